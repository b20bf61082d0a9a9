"""Training samples of the outline refiner (:mod:`spacepose.outline_refiner`) from a rendered dataset.

``python -m spacepose.tools.outline_data DATASET --split train --skip S --limit N --out OUT.npz [--bundle B]`` runs
the bundle's pipeline (no prior, as ``eval-pose``) on frames ``S .. S + N`` of the split and, on every frame that
reaches the outline decision (:func:`spacepose.silhouette.decide_outline`), keeps in the decision's silhouette frame
(n <= 192 pixels a side, zero-padded to ``PAD``):

* ``grey``: the left image (:func:`spacepose.image_vote.window_grey`), float16;
* ``disp``: the disparity over the outline's threshold (the stereo outline is ``disp > 1``), float16;
* ``observed``: the stereo outline the decision used, uint8;
* ``truth``: the rendered mask (``mask/``) resampled the same way (> 0.5), uint8;
* ``size`` (n), ``frame``, ``regime``, ``distance``, ``valid`` (the frame's reported pose).

Two processes over halves of the frames make the samples twice as fast (about 0.6 s a frame each at 640x480).
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from typing import Any

import numpy as np

log = logging.getLogger(__name__)

#: side the (n, n) planes are zero-padded to (silhouette.max_side_px of the shipped bundle)
PAD = 192
KEYS = ("grey", "disp", "observed", "truth", "size", "frame", "regime", "distance", "valid")


def make_outline_samples(dataset: str | Path, split: str, skip: int, limit: int,
                         bundle_path: str | Path | None = None) -> dict[str, np.ndarray]:
    """The samples (module docstring) of frames ``skip .. skip + limit`` of ``dataset``'s ``split``."""
    from spacepose import estimator as est_mod
    from spacepose.bundle import load_bundle
    from spacepose.calibration.rig import load_rig
    from spacepose.errors import SpaceposeError
    from spacepose.image_vote import crop_to_frame, window_grey
    from spacepose.imageio import read_image
    from spacepose.tools.pose_data import read_pose_labels

    root = Path(dataset)
    if not (root / "mask").is_dir():
        raise SpaceposeError(f"{root} has no mask/ folder (the rendered target masks are needed)")
    bundle = load_bundle(bundle_path)
    if bundle.silhouette is None or bundle.silhouette.max_side_px > PAD:
        raise SpaceposeError(f"the bundle needs a silhouette stage with max_side_px <= {PAD}")
    records = read_pose_labels(root, split)[skip: skip + limit]
    estimator = est_mod.PoseEstimator(load_rig(root / "rig.yaml"), bundle=bundle, threads=1, use_prior=False)
    seen: list[Any] = []
    original = est_mod.decide_outline

    def recording(*args: Any, **kwargs: Any) -> Any:
        decision = original(*args, **kwargs)
        seen.append((decision, args[2]))          # the decision and the full-frame disparity
        return decision

    keep: dict[str, list] = {k: [] for k in KEYS}
    est_mod.decide_outline = recording
    try:
        for i, rec in enumerate(records):
            seen.clear()
            left = read_image(root / "left" / f"{rec.frame}.png")
            res = estimator.estimate(left, read_image(root / "right" / f"{rec.frame}.png"))
            if seen and seen[-1][0].frame is not None and seen[-1][0].min_disparity > 0.0:
                decision, disparity = seen[-1]
                fr, n = decision.frame, decision.frame.size
                disp = crop_to_frame(np.asarray(disparity, np.float32), fr.x0, fr.y0, fr.side, n) \
                    / decision.min_disparity
                truth = crop_to_frame(read_image(root / "mask" / f"{rec.frame}.png"), fr.x0, fr.y0, fr.side, n,
                                      convert=lambda box: (box > 127).astype(np.float32)) > 0.5
                for name, a, dtype in (("grey", window_grey(left, fr.x0, fr.y0, fr.side, n), np.float16),
                                       ("disp", np.clip(disp, 0.0, 60000.0), np.float16),
                                       ("observed", decision.observed, np.uint8), ("truth", truth, np.uint8)):
                    pad = np.zeros((PAD, PAD), dtype)
                    pad[:n, :n] = a
                    keep[name].append(pad)
                keep["size"].append(n)
                keep["frame"].append(rec.frame)
                keep["regime"].append(rec.regime)
                keep["distance"].append(rec.distance_m)
                keep["valid"].append(bool(res.valid))
            if (i + 1) % 100 == 0:
                log.info("%d/%d frames, %d samples", i + 1, len(records), len(keep["size"]))
    finally:
        est_mod.decide_outline = original
    if not keep["size"]:
        raise SpaceposeError(f"no frame of {root} ({split}, {skip}..{skip + limit}) reached the outline decision")
    return {k: np.asarray(v) for k, v in keep.items()}


def load_outline_samples(paths: list[str | Path]) -> dict[str, np.ndarray]:
    """The samples of one or more ``.npz`` files (:func:`make_outline_samples`), concatenated."""
    from spacepose.errors import SpaceposeError

    parts = []
    for p in paths:
        try:
            with np.load(p) as z:
                parts.append({k: z[k] for k in KEYS})
        except (OSError, KeyError, ValueError) as err:
            raise SpaceposeError(f"{p} is not an outline sample file: {err}") from err
    return {k: np.concatenate([part[k] for part in parts]) for k in KEYS}


def main(argv: list[str] | None = None) -> int:
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("dataset", type=Path)
    p.add_argument("--split", default="train", choices=("train", "test"))
    p.add_argument("--skip", type=int, default=0)
    p.add_argument("--limit", type=int, default=1000)
    p.add_argument("--bundle", type=Path, default=None)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--force", action="store_true", help="overwrite an existing --out")
    a = p.parse_args(argv)
    from spacepose.errors import SpaceposeError

    if a.out.exists() and not a.force:
        raise SpaceposeError(f"{a.out} exists; pass --force to overwrite")
    samples = make_outline_samples(a.dataset, a.split, a.skip, a.limit, a.bundle)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(a.out, **samples)
    log.info("wrote %s: %d samples", a.out, len(samples["size"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
