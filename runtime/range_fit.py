"""The range of a decided pose from the stereo pair at full resolution, given its rotation (session 42).

The stereo graph runs on a 256x256 crop, and its disparity over the target carries a per-frame bias: on spent
frames (``reports/range_s42``) its mean error on the target's pixels had a spread of 0.23 px at 640x480, which
is 0.1 m of range at 30 m. The range of a valid pose followed it: the polish weighs the stereo points' range
against the outline's, and neither removes that bias. Step 2 below alone, on the rendered disparity, leaves 0.03 m.

This module measures the range again from the images. With the bundle's optional ``range_fit`` section
(:class:`RangeFitConfig`), the estimator does, after every check of a valid pose:

1. the disparity refined at full resolution over the box the target's surface samples cover at the pose
   (:func:`refine_disparity`): per pixel where the stereo disparity is positive, the offset in
   ``[-span_px, span_px]`` (step ``step_px``) that minimises the mean absolute difference, over a
   ``window_px`` x ``window_px`` window, between the left image and the right image sampled at ``x - d - offset``
   (bilinear), with a parabola through the best offset and its two neighbours;
2. the pose moved along the line of sight of the target's centre until the median, over the surface samples
   visible at the pose (a coarse z-buffer, :func:`visible_samples`), of the refined disparity minus the sample's
   own disparity ``f·B/Z`` is zero (``steps`` fixed-point steps; samples whose residual exceeds ``max_residual_px``,
   the background and the outline's edge among them, are left out).

The rotation and the centre's pixel do not change, and neither does anything decided before (the route, the
gates, the polish caps). With ``positions`` 1, a frame that reports the target's position without a pose (the flip
undecided) has that position fitted the same way, read with the rotation of the pose it came from. A fit on fewer
than ``min_samples`` samples, or one that would move the centre more than ``max_move_m``, is not applied: the pose
or position is reported as before (:class:`RangeFit` says why).

Measured (session 42, rules written before their fresh frames): valid poses' mean range error 0.121 -> 0.076 m
(``reports/range_s42/plan.txt``); positions without a pose 0.200 -> 0.163 m (``plan3.txt``, part B).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Mapping

import cv2
import numpy as np

from .errors import BundleError, check_shape
from .photometric import project_surface, to_grey_float, visible_mask

__all__ = ["RangeFitConfig", "RangeFit", "parse_range_fit", "refine_disparity", "visible_samples", "fit_range"]


@dataclass(frozen=True)
class RangeFitConfig:
    """The ``range_fit`` section of ``bundle.json`` (module docstring).

    window_px: odd side of the matching window (pixels of the rectified image). span_px, step_px: the disparity
    offsets searched around the stereo disparity. cell_px, depth_tol_m: the z-buffer's cell and depth tolerance
    for the visible surface samples. max_residual_px: samples farther than this from the model's disparity are left
    out. min_samples: least samples for a fit. steps: fixed-point steps of the range. max_move_m: a fit that moves
    the target's centre farther than this is not applied. positions: 1 fits the range of a position reported
    without a pose too (``PoseResult.position_valid`` without ``valid``), read with the rotation of the pose the
    position came from (the outline's winner or the registered pose; its flip puts the centre at the same place);
    0 (the default) leaves those positions as the position route makes them.
    """

    window_px: int = 7
    span_px: float = 1.0
    step_px: float = 0.1
    cell_px: float = 3.0
    depth_tol_m: float = 0.25
    max_residual_px: float = 3.0
    min_samples: int = 30
    steps: int = 2
    max_move_m: float = 1.0
    positions: int = 0

    def __post_init__(self) -> None:
        if not (isinstance(self.window_px, int) and self.window_px >= 1 and self.window_px % 2 == 1
                and self.window_px <= 31):
            raise ValueError(f"range_fit.window_px must be an odd integer in [1, 31], got {self.window_px!r}")
        if not (0.0 < self.step_px <= self.span_px <= 4.0):
            raise ValueError(f"range_fit needs 0 < step_px <= span_px <= 4, got {self.step_px!r}, {self.span_px!r}")
        if self.span_px / self.step_px > 200:
            raise ValueError("range_fit: more than 400 offsets (span_px / step_px > 200)")
        if not (self.cell_px > 0.0 and self.depth_tol_m > 0.0 and self.max_residual_px > 0.0 and self.max_move_m > 0.0):
            raise ValueError("range_fit: cell_px, depth_tol_m, max_residual_px and max_move_m must be positive")
        if not (isinstance(self.min_samples, int) and self.min_samples >= 3):
            raise ValueError(f"range_fit.min_samples must be an integer >= 3, got {self.min_samples!r}")
        if self.positions not in (0, 1) or isinstance(self.positions, bool):
            raise ValueError(f"range_fit.positions must be 0 or 1, got {self.positions!r}")
        if not (isinstance(self.steps, int) and 1 <= self.steps <= 10):
            raise ValueError(f"range_fit.steps must be an integer in [1, 10], got {self.steps!r}")

    @property
    def offsets(self) -> np.ndarray:
        """(K,) the disparity offsets searched, symmetric about 0."""
        n = int(math.floor(self.span_px / self.step_px + 1e-9))
        return np.arange(-n, n + 1, dtype=np.float64) * self.step_px


def parse_range_fit(section: Any) -> RangeFitConfig | None:
    """The bundle's ``range_fit`` section (``None`` when absent); BundleError when malformed."""
    if section is None:
        return None
    if not isinstance(section, Mapping):
        raise BundleError(f"bundle.json: range_fit must be an object, got {type(section).__name__}")
    fields = {f.name: f for f in dataclasses.fields(RangeFitConfig)}
    unknown = sorted(set(section) - set(fields))
    if unknown:
        raise BundleError(f"bundle.json: range_fit has unknown keys {unknown}")
    values: dict[str, Any] = {}
    for name, value in section.items():
        integer = fields[name].type in ("int", int)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or (integer and not isinstance(value, int)):
            kind = "an integer" if integer else "a number"
            raise BundleError(f"bundle.json: range_fit.{name} must be {kind}, got {value!r}")
        if not math.isfinite(value):
            raise BundleError(f"bundle.json: range_fit.{name} must be finite, got {value!r}")
        values[name] = value if integer else float(value)
    try:
        return RangeFitConfig(**values)
    except ValueError as err:
        raise BundleError(f"bundle.json: {err}") from err


@dataclass(frozen=True)
class RangeFit:
    """Result of :func:`fit_range`.

    t: (3,) the moved translation, ``None`` when the fit was not applied (``why`` says why). move_m: how far the
    target's centre moved along its line of sight (positive: farther; NaN without a fit). samples: visible surface
    samples the last step rested on. residual_px: their median disparity residual before the first step (refined
    minus model; NaN when there were too few).
    """

    t: np.ndarray | None
    move_m: float
    samples: int
    residual_px: float
    why: str = ""


def visible_samples(R: np.ndarray, t: np.ndarray, surface: np.ndarray, K: np.ndarray, image_size: tuple[int, int],
                    cell_px: float, depth_tol_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(u, v, z)``, each (M,): the surface samples (S, 3, object frame) at the pose ``(R, t)`` that fall inside the
    image ``image_size`` = (W, H) in front of the camera and are nearest in their ``cell_px`` z-buffer cell (within
    ``depth_tol_m``)."""
    u, v, z = project_surface(R, t, surface, K)
    w, h = image_size
    inside = (u >= 0.0) & (u <= w - 1.0) & (v >= 0.0) & (v <= h - 1.0)
    u, v, z = u[inside], v[inside], z[inside]
    if len(z) == 0:
        return u, v, z
    keep = visible_mask(np.stack([u, v], 1), z, cell_px, depth_tol_m)
    return u[keep], v[keep], z[keep]


def refine_disparity(left_grey: np.ndarray, right_grey: np.ndarray, disparity: np.ndarray,
                     box: tuple[int, int, int, int], config: RangeFitConfig) -> np.ndarray:
    """The disparity over ``box`` = (x0, y0, x1, y1) (pixel bounds, end exclusive) refined by matching (module
    docstring, step 1): (y1 - y0, x1 - x0) float32, 0 where ``disparity`` is not positive.

    left_grey, right_grey: (H, W) float32 rectified images; disparity: (H, W) of the left image.
    """
    check_shape(left_grey, (None, None), "left_grey")
    check_shape(right_grey, tuple(left_grey.shape), "right_grey")
    check_shape(disparity, tuple(left_grey.shape), "disparity")
    x0, y0, x1, y1 = box
    sub = (slice(y0, y1), slice(x0, x1))
    d = np.asarray(disparity[sub], dtype=np.float32)
    yy, xx = np.mgrid[y0:y1, x0:x1].astype(np.float32)
    base = xx - d
    left = np.ascontiguousarray(left_grey[sub], dtype=np.float32)
    right = np.ascontiguousarray(right_grey, dtype=np.float32)
    offsets = config.offsets.astype(np.float32)
    k = config.window_px
    # a running minimum over the offsets, keeping the costs at the best one's two neighbours for the parabola
    best = np.full(d.shape, np.inf, dtype=np.float32)
    index = np.zeros(d.shape, dtype=np.int32)
    before = np.full(d.shape, np.inf, dtype=np.float32)   # the cost one offset below the best
    after = np.full(d.shape, np.inf, dtype=np.float32)    # ... and one above
    previous = None
    for i, off in enumerate(offsets):
        warped = cv2.remap(right, base - off, yy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
        cost = cv2.blur(cv2.absdiff(left, warped), (k, k))
        if previous is not None:
            np.copyto(after, cost, where=index == i - 1)
        better = cost < best
        np.copyto(best, cost, where=better)
        np.copyto(index, np.int32(i), where=better)
        if previous is not None:
            np.copyto(before, previous, where=better)
        np.copyto(after, np.float32(np.inf), where=better)
        previous = cost
    den = before - 2.0 * best + after
    inner = np.isfinite(den) & (den > 1e-12)    # the best offset is not at the ends of the search
    frac = np.zeros(d.shape, dtype=np.float32)
    np.divide(0.5 * (before - after), den, out=frac, where=inner)
    shift = offsets[index] + np.clip(frac, -1.0, 1.0) * np.float32(config.step_px)
    return np.where(d > 0.0, d + shift, 0.0).astype(np.float32)


def _sample(values: np.ndarray, u: np.ndarray, v: np.ndarray, x0: int, y0: int) -> np.ndarray:
    """Bilinear samples at the image pixels (u, v) of (h, w) ``values`` whose first pixel is the image's (x0, y0); 0
    beyond its bounds. The pixels go to float32 before the shift, which is then exact."""
    mx = u.astype(np.float32) - np.float32(x0)
    my = v.astype(np.float32) - np.float32(y0)
    return cv2.remap(values, mx[None], my[None], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                     borderValue=0.0)[0].astype(np.float64)


def fit_range(R: np.ndarray, t: np.ndarray, centre: np.ndarray, surface: np.ndarray, left: np.ndarray,
              right: np.ndarray, disparity: np.ndarray, K: np.ndarray, baseline_m: float,
              config: RangeFitConfig) -> RangeFit:
    """The pose ``(R, t)`` moved along its centre's line of sight to the range the images show (module docstring).

    Args:
        R: (3, 3), t: (3,) object -> rectified left camera. centre: (3,) the target's centre (object frame).
        surface: (S, 3) object-frame surface samples.
        left, right: rectified images, (H, W) or (H, W, C), any dtype (:func:`spacepose.photometric.to_grey_float`).
        disparity: (H, W) the stereo disparity of the left image (0 where unknown).
        K: (3, 3) rectified intrinsics; baseline_m: the rectified baseline.
    """
    check_shape(R, (3, 3), "R")
    check_shape(t, (3,), "t")
    check_shape(centre, (3,), "centre")
    check_shape(surface, (None, 3), "surface")
    check_shape(K, (3, 3), "K")
    h, w = np.asarray(disparity).shape[:2]
    check_shape(disparity, (h, w), "disparity")
    if left.shape[:2] != (h, w) or right.shape[:2] != (h, w):
        raise ValueError(f"left {left.shape[:2]}, right {right.shape[:2]} and disparity {(h, w)} differ in size")
    R = np.asarray(R, np.float64)
    t = np.asarray(t, np.float64)
    centre = np.asarray(centre, np.float64)
    fB = float(K[0, 0]) * float(baseline_m)
    if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t)) and fB > 0.0):
        return RangeFit(None, math.nan, 0, math.nan, "the pose is not finite")
    u, v, _ = visible_samples(R, t, surface, K, (w, h), config.cell_px, config.depth_tol_m)
    if len(u) < config.min_samples:
        return RangeFit(None, math.nan, len(u), math.nan, f"{len(u)} visible surface samples (< {config.min_samples})")
    pad = config.window_px // 2 + 2
    x0, y0 = max(int(math.floor(u.min())) - pad, 0), max(int(math.floor(v.min())) - pad, 0)
    x1, y1 = min(int(math.ceil(u.max())) + pad + 1, w), min(int(math.ceil(v.max())) + pad + 1, h)
    # the matching reads the box's rows only (the right image's whole width): grey images and disparity of those
    # rows, the refined disparity of the box alone, sampled in box coordinates with 0 outside it
    band = slice(y0, y1)
    refined = refine_disparity(to_grey_float(np.asarray(left)[band]), to_grey_float(np.asarray(right)[band]),
                               np.asarray(disparity, np.float32)[band], (x0, 0, x1, y1 - y0), config)
    c = R @ centre + t
    c0 = c.copy()
    first = math.nan
    n = 0
    for step in range(config.steps):
        t_now = c - R @ centre
        u, v, z = visible_samples(R, t_now, surface, K, (w, h), config.cell_px, config.depth_tol_m)
        observed = _sample(refined, u, v, x0, y0)
        residual = observed - fB / z
        ok = (observed > 0.0) & (np.abs(residual) < config.max_residual_px)
        n = int(ok.sum())
        if n < config.min_samples:
            return RangeFit(None, math.nan, n, first, f"{n} surface samples match the disparity (< {config.min_samples})")
        delta = float(np.median(residual[ok]))
        if step == 0:
            first = delta
        d_centre = fB / c[2]
        if not (c[2] > 0.0 and d_centre + delta > 0.0):
            return RangeFit(None, math.nan, n, first, "the refined disparity puts the target behind the camera")
        c = c * (d_centre / (d_centre + delta))
    move = float(np.linalg.norm(c) - np.linalg.norm(c0))
    if not (abs(move) <= config.max_move_m):
        return RangeFit(None, move, n, first, f"the fit would move the target {move:+.2f} m (beyond "
                                              f"{config.max_move_m:g} m)")
    return RangeFit(c - R @ centre, move, n, first)
