"""Training samples of the pose network from a rendered dataset (layout of CONVENTIONS.md).

Per frame:

1. depth source (``PoseDataConfig.depth_source``):

   * ``"stereo"`` — the paper's §4 protocol: the disparity the *runtime stereo stage* predicted for
     this frame, cached as ``DATASET/pred_disparity/<name>.pfm`` by
     :mod:`spacepose.tools.predict_disparity` (``spacepose train-pose ... --stereo-graph`` makes
     the cache first). Noise, outliers and holes are the stereo network's own.
   * ``"gt_noisy"`` — bootstrap / fallback when no stereo graph is trained yet: the renderer's exact
     disparity through :func:`stereo_like_noise` (per-pixel Gaussian sigma_d ~ 0.3 px, flying
     pixels on the inner edge, foreground fattening on the outer edge, missing pixels and blobs).
     It only imitates a stereo network; the shipped model should be trained on ``"stereo"``.

2. :func:`spacepose.pose_preprocess.prepare_pose_inputs` — the *same* function the flight runtime
   calls — with the depth window of the bundle (dataset depth range, target radius, margin 0.2),
   a sampling seed that changes every epoch, and photometric augmentation of the RGB crop.

3. per-point labels: a point is *target* (label 1) when its pixel is on the GT mask AND its depth
   lies within ``max(seg_depth_tol_m, seg_depth_tol_sigma * sigma_Z)`` of the GT depth at that
   pixel (``sigma_Z = Z^2 sigma_d / (f B)``: the expected stereo depth noise, which exceeds 0.3 m
   beyond ~25 m at 640x480); keypoint offsets ``R kp + t - xyz_cam`` (M, N, 3) and centre offsets
   ``R c + t - xyz_cam`` (N, 3), metres, for every point (the loss masks background points).

A frame whose depth holds too few points is replaced by the next usable frame (logged).
Randomness is a pure function of (seed, epoch, index).
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from spacepose.errors import DatasetError
from spacepose.geometry import disparity_to_depth
from spacepose.imageio import read_image, read_pfm
from spacepose.pose_inputs import PoseInputSpec, pose_input_names
from spacepose.pose_preprocess import PreparedPose, depth_window, prepare_pose_inputs
from spacepose.tools.labels import FrameLabel, read_labels

log = logging.getLogger(__name__)

__all__ = ["DEPTH_SOURCES", "PRED_DISPARITY_DIR", "NoiseModel", "PoseDataConfig", "PoseFrame", "read_pose_labels",
           "dataset_info", "load_dataset_keypoints", "stereo_like_noise", "point_labels", "PoseDataset"]

DEPTH_SOURCES = ("stereo", "gt_noisy")
PRED_DISPARITY_DIR = "pred_disparity"


@dataclass(frozen=True)
class NoiseModel:
    """Stereo-like corruption of an exact disparity map (pixels of the dataset images)."""

    sigma_d_px: float = 0.3          # per-pixel Gaussian disparity noise
    edge_width: int = 2              # width (px) of the inner / outer edge bands
    p_edge_outlier: float = 0.3      # inner-band pixel becomes a flying pixel (d * U(0.3, 1))
    p_fatten: float = 0.3            # outer-band pixel takes the foreground disparity (fattening)
    p_missing: float = 0.03          # i.i.d. missing target pixels
    p_blob: float = 0.03             # missing 8x8 blobs (per low-res cell)


@dataclass(frozen=True)
class PoseDataConfig:
    """How pose samples are made (serialised into the training config)."""

    depth_source: str = "gt_noisy"
    augment: bool = True
    noise: NoiseModel = NoiseModel()
    depth_margin: float = 0.2
    min_points: int = 64
    seg_depth_tol_m: float = 0.3
    seg_depth_tol_sigma: float = 3.0
    sigma_d_px: float = 0.3          # disparity noise used for the label tolerance (frame pixels)
    grey_prob: float = 0.1
    noise_sigma_max: float = 4.0

    def __post_init__(self) -> None:
        if self.depth_source not in DEPTH_SOURCES:
            raise ValueError(f"depth_source must be one of {DEPTH_SOURCES}, got {self.depth_source!r}")


#: the pose samples' name of the shared label record (``R`` and ``t`` always set)
PoseFrame = FrameLabel


def read_pose_labels(root: str | Path, split: str | None = None) -> list[PoseFrame]:
    """Frames of ``labels.jsonl`` with their pose (optionally of one split), in file order."""
    return read_labels(root, split, require=("R", "t"))


def dataset_info(root: str | Path) -> dict[str, Any]:
    """``dataset.json`` of a rendered dataset (target, seed, count, size, depth_range), ``{}`` if absent."""
    path = Path(root) / "dataset.json"
    if not path.is_file():
        return {}
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as err:
        raise DatasetError(f"{path}: unreadable: {err}") from err


def load_dataset_keypoints(target: str) -> tuple[np.ndarray, np.ndarray]:
    """(keypoints (M, 3), centre (3,)) of a shipped target from ``tools/meshes/<target>/keypoints.json``."""
    from spacepose.tools.keypoints import load_keypoints

    path = Path(__file__).resolve().parent / "meshes" / target / "keypoints.json"
    if not path.is_file():
        raise DatasetError(f"no keypoints for target {target!r} ({path}); run `spacepose keypoints {target}`")
    kps = load_keypoints(path)
    return np.asarray(kps.keypoints, dtype=np.float64), np.asarray(kps.centre, dtype=np.float64)


def stereo_like_noise(disparity: np.ndarray, rng: np.random.Generator, model: NoiseModel = NoiseModel()) -> np.ndarray:
    """A copy of an exact disparity map (0 = no target) corrupted like a stereo network's output.

    Gaussian noise on every target pixel; on the band ``edge_width`` px inside the silhouette a
    fraction of pixels become flying pixels (disparity scaled by U(0.3, 1): points pulled towards
    the background); on the band outside, a fraction take the nearest foreground disparity
    (foreground fattening); finally i.i.d. and blob-shaped holes (0).
    """
    d = np.asarray(disparity, dtype=np.float32)
    h, w = d.shape
    valid = d > 0
    out = np.where(valid, d + rng.normal(0.0, model.sigma_d_px, size=d.shape).astype(np.float32), 0.0)
    if model.edge_width > 0 and valid.any():
        kernel = np.ones((2 * model.edge_width + 1,) * 2, np.uint8)
        v8 = valid.astype(np.uint8)
        inner = valid & (cv2.erode(v8, kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0) == 0)
        grown = cv2.dilate(d, kernel)  # nearest-ish foreground disparity (max over the window)
        outer = ~valid & (grown > 0)
        fly = inner & (rng.random(d.shape) < model.p_edge_outlier)
        out[fly] *= rng.uniform(0.3, 1.0, size=int(fly.sum())).astype(np.float32)
        fat = outer & (rng.random(d.shape) < model.p_fatten)
        out[fat] = grown[fat] + rng.normal(0.0, model.sigma_d_px, size=int(fat.sum())).astype(np.float32)
    missing = rng.random(d.shape) < model.p_missing
    if model.p_blob > 0:
        cells = rng.random((h // 8 + 1, w // 8 + 1)) < model.p_blob
        missing |= np.kron(cells, np.ones((8, 8), bool))[:h, :w]
    out[missing] = 0.0
    return np.maximum(out, 0.0).astype(np.float32)


def point_labels(prep: PreparedPose, gt_disparity: np.ndarray, mask: np.ndarray, focal_px: float, baseline_m: float,
                 R: np.ndarray, t: np.ndarray, keypoints: np.ndarray, centre: np.ndarray,
                 config: PoseDataConfig = PoseDataConfig()) -> dict[str, np.ndarray]:
    """Per-point supervision of a prepared frame (see the module docstring, step 3).

    Returns ``labels`` (N,) int64 (1 = target), ``kp_targets`` (M, N, 3) float32 and
    ``ctr_targets`` (N, 3) float32 (``keypoint - point``, camera frame, metres).
    """
    u, v = prep.pixels[:, 0], prep.pixels[:, 1]
    z_gt = disparity_to_depth(gt_disparity, focal_px, baseline_m)[v, u].astype(np.float64)
    z = prep.xyz_cam[:, 2]
    sigma_z = z_gt ** 2 * config.sigma_d_px / (focal_px * baseline_m)
    tol = np.maximum(config.seg_depth_tol_m, config.seg_depth_tol_sigma * sigma_z)
    labels = mask[v, u] & (z_gt > 0) & (np.abs(z - z_gt) <= tol)
    kp_cam = keypoints @ R.T + t                     # (M, 3)
    ctr_cam = R @ centre + t                         # (3,)
    kp_targets = kp_cam[:, None, :] - prep.xyz_cam[None, :, :]
    ctr_targets = ctr_cam[None, :] - prep.xyz_cam
    return {"labels": labels.astype(np.int64), "kp_targets": kp_targets.astype(np.float32),
            "ctr_targets": ctr_targets.astype(np.float32)}


def _augment_crop(crop: np.ndarray, rng: np.random.Generator, config: PoseDataConfig) -> np.ndarray:
    from spacepose.tools.stereo_data import photometric_augment

    x = photometric_augment(crop.astype(np.float32), rng, config.noise_sigma_max)
    if rng.random() < config.grey_prob:
        x = np.repeat(x.mean(axis=2, keepdims=True), 3, axis=2)
    return np.clip(np.rint(x), 0, 255).astype(np.uint8)


class PoseDataset:
    """A ``torch.utils.data.Dataset`` of pose-net samples (see the module docstring).

    Items: every graph input of :func:`~spacepose.pose_inputs.pose_input_names` without the batch
    axis (torch tensors), plus ``xyz`` (N, 3) float32 camera-frame points, ``labels`` (N,) int64,
    ``kp_targets`` (M, N, 3), ``ctr_targets`` (N, 3), ``R`` (3, 3) / ``t`` (3,) float64, ``index``
    (the frame actually used) and ``distance`` (m).

    Args:
        root: dataset folder. split: "train" / "test" / None (all).
        spec: the pose graph's input spec.
        config: depth source, augmentation, label tolerances.
        keypoints, centre: object-frame keypoints (M, 3) and centre (3,); default: the shipped
            keypoints of the dataset's target.
        radius_m: target bounding radius for the depth window; default from the target mesh.
        seed: randomness seed; limit: use only the first ``limit`` frames; deterministic: the same
            sample for an index every epoch and no augmentation (validation).
    """

    def __init__(self, root: str | Path, split: str | None = "train", spec: PoseInputSpec = PoseInputSpec(),
                 config: PoseDataConfig = PoseDataConfig(), *, keypoints: np.ndarray | None = None,
                 centre: np.ndarray | None = None, radius_m: float | None = None, seed: int = 0,
                 limit: int | None = None, deterministic: bool = False) -> None:
        from spacepose.calibration.rectify import rectify
        from spacepose.calibration.rig import load_rig

        self.root = Path(root)
        self.spec = spec
        self.config = config
        self.seed = int(seed)
        self.epoch = 0
        self.deterministic = bool(deterministic)
        self.records = read_pose_labels(self.root, split)
        if limit is not None:
            self.records = self.records[: int(limit)]
        if not self.records:
            raise DatasetError(f"{self.root}: no frames in split {split!r}")
        self.info = dataset_info(self.root)
        self.target = str(self.info.get("target", "tdrs"))
        if keypoints is None or centre is None:
            keypoints, centre = load_dataset_keypoints(self.target)
        self.keypoints = np.asarray(keypoints, dtype=np.float64).reshape(-1, 3)
        self.centre = np.asarray(centre, dtype=np.float64).reshape(3)
        if radius_m is None:
            from spacepose.tools.targets import load_target

            radius_m = float(load_target(self.target).bounding_radius)
        self.radius_m = float(radius_m)
        rig_path = self.root / "rig.yaml"
        if not rig_path.is_file():
            raise DatasetError(f"{self.root}: no rig.yaml")
        rect = rectify(load_rig(rig_path))
        if not rect.is_identity:
            raise DatasetError(f"{self.root}: the rig is not an ideal parallel rig; labels assume raw = rectified")
        self.K = np.asarray(rect.K, dtype=np.float64)
        self.focal_px = float(rect.focal_px)
        self.baseline_m = float(rect.baseline_m)
        self.distance_range_m = tuple(float(v) for v in self.info.get("depth_range", (10.0, 50.0)))
        self.depth_range_m = depth_window(self.distance_range_m, self.radius_m, config.depth_margin)
        if config.depth_source == "stereo":
            missing = [r.frame for r in self.records if not (self.root / PRED_DISPARITY_DIR / f"{r.frame}.pfm").is_file()]
            if missing:
                raise DatasetError(
                    f"{self.root}/{PRED_DISPARITY_DIR} lacks {len(missing)} of {len(self.records)} predicted disparities "
                    f"(first: {missing[0]}); run `python -m spacepose.tools.predict_disparity {self.root} --graph "
                    f"STEREO.onnx` or pass --stereo-graph to train-pose, or use --depth-source gt_noisy")

    def __len__(self) -> int:
        return len(self.records)

    def set_epoch(self, epoch: int) -> None:
        self.epoch = int(epoch)

    def _rng(self, index: int) -> np.random.Generator:
        epoch = 0 if self.deterministic else self.epoch
        return np.random.default_rng([self.seed, epoch, int(index)])

    def load_frame(self, rec: PoseFrame, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(left RGB, input disparity, GT disparity, mask bool) of one frame."""
        left = read_image(self.root / "left" / f"{rec.frame}.png")
        gt = np.nan_to_num(read_pfm(self.root / "disparity" / f"{rec.frame}.pfm").astype(np.float32),
                           nan=0.0, posinf=0.0, neginf=0.0)
        mask = read_image(self.root / "mask" / f"{rec.frame}.png")
        if mask.ndim == 3:
            mask = mask[..., 0]
        if self.config.depth_source == "stereo":
            disp = np.nan_to_num(read_pfm(self.root / PRED_DISPARITY_DIR / f"{rec.frame}.pfm").astype(np.float32),
                                 nan=0.0, posinf=0.0, neginf=0.0)
        else:
            disp = stereo_like_noise(gt, rng, self.config.noise)
        if left.shape[:2] != gt.shape or disp.shape != gt.shape or mask.shape != gt.shape:
            raise DatasetError(f"{rec.frame}: left/disparity/mask sizes differ")
        return left, disp, gt, mask > 0

    def sample(self, index: int) -> dict[str, Any] | None:
        """numpy sample of frame ``index`` or None when its depth holds too few points."""
        rec = self.records[index]
        rng = self._rng(index)
        left, disp, gt, mask = self.load_frame(rec, rng)
        augment = self.config.augment and not self.deterministic
        transform = (lambda crop: _augment_crop(crop, rng, self.config)) if augment else None
        point_seed = int(rng.integers(0, 2**31 - 1)) if not self.deterministic else self.spec.seed
        prep = prepare_pose_inputs(left, disp, self.K, self.baseline_m, self.spec, seed=point_seed,
                                   depth_range_m=self.depth_range_m, min_points=self.config.min_points,
                                   rgb_transform=transform)
        if not prep.ok:
            return None
        labels = point_labels(prep, gt, mask, self.focal_px, self.baseline_m, rec.R, rec.t, self.keypoints,
                              self.centre, self.config)
        out: dict[str, Any] = {name: prep.feeds[name][0] for name in pose_input_names(self.spec.n_levels)}
        out.update(labels)
        out.update({"xyz": prep.xyz_cam.astype(np.float32), "R": rec.R, "t": rec.t, "index": int(index),
                    "distance": rec.distance_m, "n_valid": prep.n_valid})
        return out

    def __getitem__(self, index: int) -> dict[str, Any]:
        import torch

        n = len(self.records)
        for attempt in range(min(n, 20)):
            i = (int(index) + attempt) % n
            item = self.sample(i)
            if item is not None:
                if attempt:
                    log.debug("frame %s has too few stereo points; used %s", self.records[index].frame, self.records[i].frame)
                return {k: torch.from_numpy(np.ascontiguousarray(v)) if isinstance(v, np.ndarray) else v
                        for k, v in item.items()}
        raise DatasetError(f"{self.root}: no usable frame near index {index} (too few stereo points)")
