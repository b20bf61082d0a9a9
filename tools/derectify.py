"""Raw camera frames of a non-ideal stereo rig, made from a rendered (ideal, rectified) dataset.

The renderer draws ideal rigs only: parallel pinhole cameras, no distortion, raw = rectified. A
calibration from a real rig has lens distortion and cameras that are a little turned against each
other, and the runtime then rectifies every frame itself before the stereo graph sees it. This tool
checks that path end to end: it draws one such rig around the dataset's ideal one and resamples
every frame into what that rig's cameras would have seen.

The raw rig (seeded, one per dataset): each camera is turned from the ideal one by a rotation of up
to ``rot_deg`` about a random axis (``X_raw_left = Rl X_ideal``, ``X_raw_right = Rr (X_ideal - b e_x)``,
so ``R = Rr Rl^T``, ``T = -Rr b e_x``); focal lengths scaled by up to ``focal_pct`` percent; principal
points moved by up to ``centre_pct`` percent of the width; radial ``k1`` in [-0.15, 0.05], ``k2`` in
[-0.05, 0.10] and tangential ``p1, p2`` within 1e-3. A raw pixel samples the ideal image where its
undistorted ray, turned back into the ideal camera, lands (``cv2.undistortPoints``, iterated, then
``cv2.remap``, bilinear; the mask nearest); pixels whose ray leaves the ideal image are black.

Poses: the runtime reports them in the *left rectified* camera of the raw rig (CONVENTIONS.md), the
frame ``cv2.stereoRectify`` gives (``X_rect = R1 X_raw_left``), which is the ideal frame turned by
``R1 Rl``. The labels are rewritten in it: ``R' = R1 Rl R``, ``t' = R1 Rl t``, ``sun_dir' = R1 Rl sun_dir``.
Disparity and depth maps are not written (they belong to the ideal images); the output serves
``spacepose eval-pose`` and ``spacepose estimate``, not ``eval-stereo``.

``python -m spacepose.tools.derectify SRC DST --seed S [--split train] [--limit N] [--rot-deg 2]
[--focal-pct 3] [--centre-pct 2] [--force]``

Nothing in ``SRC`` is touched; ``DST`` must not exist unless ``--force``.
"""

from __future__ import annotations

import argparse
import json
import logging
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Sequence

import cv2
import numpy as np

from spacepose.calibration.rectify import rectify
from spacepose.calibration.rig import StereoRig, load_rig, save_rig
from spacepose.errors import DatasetError
from spacepose.estimator import rotation_to_quaternion
from spacepose.imageio import read_image, write_image
from spacepose.tools.restyle import select_copy_labels

log = logging.getLogger(__name__)

__all__ = ["RawRigConfig", "RawRig", "sample_raw_rig", "raw_maps", "derectify_dataset", "main"]


@dataclass(frozen=True)
class RawRigConfig:
    """How far the drawn raw rig strays from the ideal one (module docstring)."""

    rot_deg: float = 2.0
    focal_pct: float = 3.0
    centre_pct: float = 2.0

    def __post_init__(self) -> None:
        for name in ("rot_deg", "focal_pct", "centre_pct"):
            value = getattr(self, name)
            if not (np.isfinite(value) and 0.0 <= value <= 45.0):
                raise ValueError(f"{name} must be in [0, 45], got {value}")


@dataclass(frozen=True)
class RawRig:
    """A raw rig drawn around an ideal one: ``rig`` (what a calibration file holds), the camera turns
    ``Rl``, ``Rr`` (3, 3) from the ideal cameras, and ``to_rect`` (3, 3) = ``R1 Rl``, the turn from the
    ideal left camera to the raw rig's left rectified camera (``cv2.stereoRectify``)."""

    rig: StereoRig
    ideal: StereoRig
    Rl: np.ndarray
    Rr: np.ndarray
    to_rect: np.ndarray


def _turn(rng: np.random.Generator, max_deg: float) -> np.ndarray:
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    angle = np.deg2rad(rng.uniform(0.0, max_deg))
    R, _ = cv2.Rodrigues(axis * angle)
    return R


def _camera(rng: np.random.Generator, K: np.ndarray, width: int, config: RawRigConfig) -> tuple[np.ndarray, np.ndarray]:
    M = K.copy()
    f = K[0, 0] * (1.0 + rng.uniform(-1.0, 1.0) * config.focal_pct / 100.0)
    M[0, 0], M[1, 1] = f, f * (1.0 + rng.uniform(-0.002, 0.002))
    M[0, 2] += rng.uniform(-1.0, 1.0) * config.centre_pct / 100.0 * width
    M[1, 2] += rng.uniform(-1.0, 1.0) * config.centre_pct / 100.0 * width
    D = np.array([rng.uniform(-0.15, 0.05), rng.uniform(-0.05, 0.10), rng.uniform(-1e-3, 1e-3),
                  rng.uniform(-1e-3, 1e-3), 0.0])
    return M, D


def sample_raw_rig(ideal: StereoRig, seed: int, config: RawRigConfig = RawRigConfig()) -> RawRig:
    """Draw a raw rig around ``ideal`` (an ideal parallel rig: R = I, T along -x, no distortion)."""
    if not (np.allclose(ideal.R, np.eye(3)) and np.allclose(ideal.T[1:], 0.0) and ideal.T[0] < 0
            and not np.any(ideal.D1) and not np.any(ideal.D2) and np.allclose(ideal.M1, ideal.M2)):
        raise DatasetError("derectify needs a dataset rendered with an ideal parallel rig")
    rng = np.random.default_rng(seed)
    width = ideal.image_size[0]
    Rl, Rr = _turn(rng, config.rot_deg), _turn(rng, config.rot_deg)
    M1, D1 = _camera(rng, np.asarray(ideal.M1), width, config)
    M2, D2 = _camera(rng, np.asarray(ideal.M2), width, config)
    b = float(-ideal.T[0])
    rig = StereoRig(M1, D1, M2, D2, Rr @ Rl.T, -Rr @ np.array([b, 0.0, 0.0]), ideal.image_size)
    R1 = rectify(rig).R1
    return RawRig(rig, ideal, Rl, Rr, np.asarray(R1) @ Rl)


def raw_maps(M: np.ndarray, D: np.ndarray, turn: np.ndarray, K_ideal: np.ndarray,
             size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) float32 maps: for each raw pixel of a camera (``M``, ``D``) turned by ``turn`` from
    the ideal one (``X_raw = turn X_ideal``), where its ray lands in the ideal image ``K_ideal``."""
    w, h = size
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    pix = np.stack([u.ravel(), v.ravel()], axis=1)[:, None, :]
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-9)
    if hasattr(cv2, "undistortPointsIter"):   # OpenCV 4; OpenCV 5 folded it into undistortPoints
        ideal = cv2.undistortPointsIter(pix, M, D, turn.T, K_ideal, criteria)[:, 0, :]
    else:
        ideal = cv2.undistortPoints(pix, M, D, R=turn.T, P=K_ideal, criteria=criteria)[:, 0, :]
    return (ideal[:, 0].reshape(h, w).astype(np.float32), ideal[:, 1].reshape(h, w).astype(np.float32))


def _rewrite_label(label: dict[str, Any], to_rect: np.ndarray) -> dict[str, Any]:
    out = dict(label)
    R = to_rect @ np.asarray(label["R"], dtype=np.float64)
    out["R"] = R.tolist()
    out["t"] = (to_rect @ np.asarray(label["t"], dtype=np.float64)).tolist()
    out["q_wxyz"] = [float(x) for x in rotation_to_quaternion(R)]
    if label.get("sun_dir") is not None:
        out["sun_dir"] = (to_rect @ np.asarray(label["sun_dir"], dtype=np.float64)).tolist()
    return out


def derectify_dataset(src: str | Path, dst: str | Path, seed: int, *, config: RawRigConfig = RawRigConfig(),
                      split: str | None = None, limit: int | None = None, force: bool = False) -> RawRig:
    """Write ``dst``: ``src``'s frames (of ``split``, the first ``limit``) as the raw rig's cameras
    see them, its calibration as ``rig.yaml`` and the labels in its left rectified frame."""
    src, dst = Path(src), Path(dst)
    labels = select_copy_labels(src, dst, "derectify", split=split, limit=limit, force=force)
    raw = sample_raw_rig(load_rig(src / "rig.yaml"), seed, config)
    size = raw.rig.image_size
    K_ideal = np.asarray(raw.ideal.M1)
    maps = {"left": raw_maps(raw.rig.M1, raw.rig.D1, raw.Rl, K_ideal, size),
            "right": raw_maps(raw.rig.M2, raw.rig.D2, raw.Rr, K_ideal, size)}
    for sub in ("left", "right", "mask"):
        (dst / sub).mkdir(parents=True, exist_ok=True)
    for i, label in enumerate(labels):
        name = label["frame"]
        for view in ("left", "right"):
            image = read_image(src / view / f"{name}.png")
            out = cv2.remap(image, *maps[view], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
            write_image(dst / view / f"{name}.png", out)
        mask_path = src / "mask" / f"{name}.png"
        if mask_path.is_file():
            mask = cv2.remap(read_image(mask_path), *maps["left"], cv2.INTER_NEAREST,
                             borderMode=cv2.BORDER_CONSTANT, borderValue=0)
            write_image(dst / "mask" / f"{name}.png", mask)
        if (i + 1) % 50 == 0:
            log.info("derectified %d of %d frames", i + 1, len(labels))
    save_rig(raw.rig, dst / "rig.yaml")
    with open(dst / "labels.jsonl", "w") as fh:
        for label in labels:
            fh.write(json.dumps(_rewrite_label(label, raw.to_rect)) + "\n")
    meta = {"derectified_from": str(src), "seed": int(seed), "config": asdict(config), "Rl": raw.Rl.tolist(),
            "Rr": raw.Rr.tolist(), "to_rect": raw.to_rect.tolist(),
            "frames": len(labels)}
    (dst / "derectify.json").write_text(json.dumps(meta, indent=1) + "\n")
    return raw


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m spacepose.tools.derectify", description=__doc__.split("\n")[0])
    parser.add_argument("src")
    parser.add_argument("dst")
    parser.add_argument("--seed", type=int, required=True)
    parser.add_argument("--split", default=None)
    parser.add_argument("--limit", type=int, default=None)
    parser.add_argument("--rot-deg", type=float, default=RawRigConfig.rot_deg)
    parser.add_argument("--focal-pct", type=float, default=RawRigConfig.focal_pct)
    parser.add_argument("--centre-pct", type=float, default=RawRigConfig.centre_pct)
    parser.add_argument("--force", action="store_true")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    config = RawRigConfig(rot_deg=args.rot_deg, focal_pct=args.focal_pct, centre_pct=args.centre_pct)
    try:
        raw = derectify_dataset(args.src, args.dst, args.seed, config=config, split=args.split, limit=args.limit,
                                force=args.force)
    except DatasetError as err:
        log.error("%s", err)
        return 2
    log.info("wrote %s: R deviates %.2f deg from identity, D1 %s", args.dst,
             float(np.rad2deg(np.linalg.norm(cv2.Rodrigues(raw.rig.R)[0]))), np.round(raw.rig.D1, 4).tolist())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
