"""Stereo disparity + left image -> pose-graph inputs: the ONE preprocessing of training and flight.

:func:`prepare_pose_inputs` is called by the flight runtime (:mod:`spacepose.estimator`) and by the
training data (:mod:`spacepose.tools.pose_data`) so the pose network sees identical inputs::

    disparity (H, W) full-res  --Z = f B / d-->  depth  --depth window [z_lo, z_hi]-->  mask
        (optionally restricted to ``window_hint``, e.g. the stereo fine-pass window)
    --> back-projection X = Z K^-1 [u, v, 1]^T of every masked pixel (camera frame, metres)
    --> fewer than ``min_points`` points: status "no_target" (0 points) / "too_few_points"
    --> fixed-count seeded sample of ``spec.n_points`` (repetition when fewer are available)
    --> pose crop window: square, ``POSE_CROP_MARGIN`` x the longest side of the box of ALL valid
        pixels (not only the sampled ones, so the crop does not depend on the sampling seed),
        centred on that box, zero padded beyond the image
    --> RGB crop resized to ``spec.crop_size`` (bilinear; ``rgb_transform`` runs here in training)
    --> each point's crop pixel = rounded affine map of its full-frame pixel, clipped to the crop
    --> :func:`spacepose.pose_inputs.build_pose_inputs` (kNN / sub / up / pix2pt indices)

Point normalisation (done by ``build_pose_inputs``): the graph's ``points`` input holds
``[(xyz - xyz_mean) / spec.xyz_scale, rgb / 255 (, normals)]`` where ``xyz_mean`` is the mean of
the N sampled camera-frame points (metres) and ``rgb`` the crop colour at each point's crop pixel.
The graph outputs offsets in metres (``offset = keypoint - point``), so a vote is
``xyz_cam + offset`` with the un-normalised ``xyz_cam`` returned here; ``xyz_mean`` never needs
adding back.

numpy + OpenCV only (flight code).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from . import roi
from .errors import ShapeError, check_shape
from .geometry import backproject, disparity_to_depth, sample_indices
from .pose_inputs import PoseInputSpec, build_pose_inputs

__all__ = [
    "POSE_CROP_MARGIN",
    "PREPARE_STATUSES",
    "PreparedPose",
    "depth_window",
    "pose_crop_window",
    "to_rgb_uint8",
    "prepare_pose_inputs",
]

#: pose crop side = this margin * longest side of the target pixels' box
POSE_CROP_MARGIN = 1.1
#: statuses of :class:`PreparedPose` ("ok" = feeds are ready)
PREPARE_STATUSES = ("ok", "no_target", "too_few_points")


@dataclass(frozen=True, eq=False)
class PreparedPose:
    """Pose-graph inputs of one frame, or why there are none.

    Attributes:
        status: ``"ok"``, ``"no_target"`` (no valid stereo point) or ``"too_few_points"``.
        n_valid: stereo points inside the depth window (before sampling).
        feeds: graph inputs keyed by :func:`spacepose.pose_inputs.pose_input_names` (batch axis 1);
            empty unless ``ok``.
        xyz_cam: (N, 3) float64 sampled camera-frame points (metres), N = ``spec.n_points``.
        pixels: (N, 2) int64 full-frame pixel ``(u, v)`` each sampled point came from.
        crop_pixels: (N, 2) int64 pixel of each point in the RGB crop.
        xyz_mean: (3,) float64 mean subtracted from the points fed to the graph.
        window: the left-image square the RGB crop was cut from (``None`` unless ``ok``).
        transform: full-frame -> crop pixel map of that window (``None`` unless ``ok``).
        detail: human-readable reason when not ``ok``.
    """

    status: str
    n_valid: int
    feeds: dict[str, np.ndarray] = field(default_factory=dict)
    xyz_cam: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    pixels: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    crop_pixels: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    xyz_mean: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    window: roi.Window | None = None
    transform: roi.CropTransform | None = None
    detail: str = ""

    @property
    def ok(self) -> bool:
        return self.status == "ok"


def depth_window(distance_range_m: tuple[float, float], radius_m: float, depth_margin: float = 0.2) -> tuple[float, float]:
    """Depths (m) a target point may have: ``[near (1 - margin) - r, far (1 + margin) + r]``.

    ``distance_range_m`` is the range of the target's distance the graphs were trained for,
    ``radius_m`` its bounding radius; the low end is at least 1 mm.
    """
    near, far = float(distance_range_m[0]), float(distance_range_m[1])
    if not (0.0 < near < far) or not radius_m >= 0.0 or not depth_margin >= 0.0:
        raise ValueError(f"need 0 < near < far, radius >= 0, margin >= 0; got {distance_range_m}, {radius_m}, {depth_margin}")
    return max(near * (1.0 - depth_margin) - radius_m, 1e-3), far * (1.0 + depth_margin) + radius_m


def pose_crop_window(pixels: np.ndarray, margin: float = POSE_CROP_MARGIN, min_side: int = 16) -> roi.Window:
    """Square left-image window around target pixels (N, 2) ``(u, v)``: the pose graph's view.

    The side is ``margin`` times the longest side of the pixels' box (at least ``min_side``),
    centred on the box; it may leave the image (zero padded).
    """
    check_shape(pixels, (None, 2), "pixels")
    if len(pixels) == 0:
        raise ShapeError("pixels must hold at least one pixel")
    u0, v0 = pixels.min(axis=0).astype(np.float64)
    u1, v1 = pixels.max(axis=0).astype(np.float64) + 1.0
    side = int(math.ceil(max(u1 - u0, v1 - v0, 1.0) * margin))
    side = max(side, int(min_side))
    cx, cy = 0.5 * (u0 + u1), 0.5 * (v0 + v1)
    return roi.Window(int(round(cx - side / 2.0)), int(round(cy - side / 2.0)), side)


def to_rgb_uint8(image: np.ndarray) -> np.ndarray:
    """(H, W), (H, W, 1) or (H, W, 3) uint8/uint16/float (0-255 scale) -> contiguous (H, W, 3) uint8 RGB."""
    if not isinstance(image, np.ndarray) or image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] not in (1, 3)):
        raise ShapeError(f"image must be (H, W), (H, W, 1) or (H, W, 3), got {getattr(image, 'shape', type(image).__name__)}")
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[..., 0]
    if image.dtype == np.uint8:
        out = image
    elif image.dtype == np.uint16:
        out = (image >> 8).astype(np.uint8)
    elif np.issubdtype(image.dtype, np.floating):
        out = np.clip(np.rint(np.nan_to_num(image)), 0, 255).astype(np.uint8)
    else:
        raise ShapeError(f"image must be uint8, uint16 or float, got {image.dtype}")
    if out.ndim == 2:
        out = np.repeat(out[..., None], 3, axis=2)
    return np.ascontiguousarray(out)


def _window_box(shape: tuple[int, int], window_hint: object) -> tuple[int, int, int, int]:
    """``(x0, y0, x1, y1)`` of ``window_hint`` clipped to an image of ``shape`` (may be empty)."""
    if isinstance(window_hint, roi.Window):
        x0, y0, x1, y1 = window_hint.bbox
    else:
        try:
            x0, y0, x1, y1 = (int(v) for v in window_hint)  # type: ignore[union-attr]
        except (TypeError, ValueError) as err:
            raise ShapeError(f"window_hint must be a roi.Window or (x0, y0, x1, y1), got {window_hint!r}") from err
    h, w = shape
    return max(x0, 0), max(y0, 0), max(min(x1, w), 0), max(min(y1, h), 0)


def _support_box(disparity: np.ndarray, box: tuple[int, int, int, int]) -> tuple[int, int, int, int]:
    """The smallest sub-box of ``box`` holding every positive disparity (empty box: none).

    The flight stereo stage returns 0 outside its fine window, so depth and back-projection run on
    this box only; the points, and their row-major order, are those of the whole frame.
    """
    x0, y0, x1, y1 = box
    positive = disparity[y0:y1, x0:x1] > 0  # NaN compares False
    rows, cols = np.flatnonzero(positive.any(axis=1)), np.flatnonzero(positive.any(axis=0))
    if len(rows) == 0:
        return x0, y0, x0, y0
    return x0 + int(cols[0]), y0 + int(rows[0]), x0 + int(cols[-1]) + 1, y0 + int(rows[-1]) + 1


def prepare_pose_inputs(
    left_rect: np.ndarray,
    disparity: np.ndarray,
    K: np.ndarray,
    baseline_m: float,
    spec: PoseInputSpec,
    window_hint: roi.Window | tuple[int, int, int, int] | None = None,
    seed: int = 0,
    *,
    depth_range_m: tuple[float, float] | None = None,
    min_points: int = 64,
    rgb_transform: Callable[[np.ndarray], np.ndarray] | None = None,
) -> PreparedPose:
    """Pose-graph inputs of one rectified frame (see the module docstring for every step).

    Args:
        left_rect: left rectified image, (H, W, 3) RGB uint8 (grey / uint16 / float are converted
            by :func:`to_rgb_uint8`).
        disparity: (H, W) float32 full-resolution disparity of ``left_rect`` (pixels), 0 where unknown.
        K: (3, 3) rectified left intrinsics of ``left_rect``; ``baseline_m`` the stereo baseline.
        spec: the pose graph's input spec (point count, crop size, kNN sizes).
        window_hint: only pixels inside this left-image window / box ``(x0, y0, x1, y1)`` are used
            (e.g. the stereo fine-pass window); ``None``: the whole frame.
        seed: seed of the fixed-count point sample (training varies it, flight keeps it fixed).
        depth_range_m: ``(z_lo, z_hi)``: only points with this depth are used (see
            :func:`depth_window`); ``None``: every finite positive depth.
        min_points: fewer valid points than this gives ``too_few_points`` (0 gives ``no_target``).
        rgb_transform: optional ``f(crop uint8 (h, w, 3)) -> uint8 (h, w, 3)`` applied to the RGB
            crop before colours are read (training-time photometric augmentation; flight: None).

    Returns:
        :class:`PreparedPose` (``status != "ok"`` instead of raising when the target is missing).

    Raises:
        ShapeError: ``disparity`` is not (H, W) floating like the image, bad ``K`` or ``window_hint``.
    """
    rgb = to_rgb_uint8(left_rect)
    check_shape(disparity, rgb.shape[:2], "disparity", dtypes=(np.floating,))
    h, w = disparity.shape
    box = (0, 0, w, h) if window_hint is None else _window_box((h, w), window_hint)
    x0, y0, x1, y1 = _support_box(disparity, box)
    K_box = np.array(K, dtype=np.float64, copy=True)
    K_box[0, 2] -= x0
    K_box[1, 2] -= y0
    depth = disparity_to_depth(disparity[y0:y1, x0:x1], float(K_box[0, 0]), baseline_m)
    mask = depth > 0
    if depth_range_m is not None:
        z_lo, z_hi = float(depth_range_m[0]), float(depth_range_m[1])
        mask &= (depth >= z_lo) & (depth <= z_hi)
    cloud = backproject(depth, K_box, mask)
    cloud = type(cloud)(points=cloud.points, pixels=cloud.pixels + np.array([x0, y0], dtype=cloud.pixels.dtype),
                        colors=cloud.colors)
    n_valid = len(cloud)
    if n_valid < max(int(min_points), 1):
        status = "no_target" if n_valid == 0 else "too_few_points"
        return PreparedPose(status=status, n_valid=n_valid,
                            detail=f"{n_valid} stereo points in the depth window (need {max(int(min_points), 1)})")

    idx = sample_indices(n_valid, spec.n_points, int(seed))
    xyz = np.ascontiguousarray(cloud.points[idx], dtype=np.float32)
    pixels = cloud.pixels[idx].astype(np.int64)
    window = pose_crop_window(cloud.pixels)
    crop, transform = roi.crop_resize(rgb, window, spec.crop_size)
    if rgb_transform is not None:
        crop = np.ascontiguousarray(rgb_transform(crop))
        if crop.shape != (spec.crop_size[1], spec.crop_size[0], 3) or crop.dtype != np.uint8:
            raise ShapeError(f"rgb_transform must return a uint8 crop of the same shape, got {crop.shape} {crop.dtype}")
    cw, ch = spec.crop_size
    crop_px = np.rint(transform.to_net(pixels.astype(np.float64))).astype(np.int64)
    crop_px[:, 0] = np.clip(crop_px[:, 0], 0, cw - 1)
    crop_px[:, 1] = np.clip(crop_px[:, 1], 0, ch - 1)
    feeds, xyz_mean = build_pose_inputs(crop, xyz, crop_px, spec)
    return PreparedPose(status="ok", n_valid=n_valid, feeds=feeds, xyz_cam=xyz.astype(np.float64), pixels=pixels,
                        crop_pixels=crop_px, xyz_mean=xyz_mean, window=window, transform=transform)
