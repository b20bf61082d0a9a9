"""The flip classifier's input: the left image around the target and the outlines of two poses (numpy + OpenCV).

The shipped target is nearly symmetric under a half turn about its body z axis; the stereo points
cannot tell a pose from that flip, the outline often cannot, and the hand-written image vote
(:mod:`spacepose.image_vote`) abstains when the sky around the target is lit. The flip classifier
(:mod:`spacepose.flip_classifier`) is a small CNN that looks at the same evidence as the image vote —
the left image where the two outlines differ — and learns which outline the image shows.

One *view* is three (size, size) float32 planes over the full-frame box ``(x0, y0, side)`` (the
stereo window, resampled to ``size``, upscaled when smaller):

0. the left image, grey (:func:`spacepose.image_vote.grey_unit`), divided by the 90th percentile of
   its pixels inside the two outlines and clipped to [0, 2] — a brightness relative to the target's
   own, so the exposure, the sensor's bit depth and the renderer's absolute radiance do not matter;
1. pose A's outline: the bundle's silhouette samples splatted at pose A (1 inside, 0 outside);
2. pose B's outline, the same.

The classifier's score is antisymmetric in A and B by construction (the graph scores A against B and
B against A and returns the difference), so the order of the two poses never matters.

The training side builds its views with :func:`flip_views` too, from ground-truth poses, so the
network sees at run time exactly what it was trained on.
"""

from __future__ import annotations

import numpy as np

from .errors import check_shape
from .image_vote import window_grey
from .silhouette import SilhouetteFrame, splat_mask

__all__ = ["view_frame", "flip_views", "toned_views", "CHANNELS"]

#: planes of one view: grey, outline A, outline B
CHANNELS = 3


def view_frame(K_full: np.ndarray, x0: int, y0: int, side: int, size: int) -> SilhouetteFrame:
    """The full-frame box ``(x0, y0, side)`` seen at exactly ``size`` pixels (up- or downscaled)."""
    check_shape(K_full, (3, 3), "K_full")
    side = max(1, int(side))
    s = int(size) / side
    K = np.asarray(K_full, dtype=np.float64).copy()
    K[0, 0] *= s
    K[1, 1] *= s
    K[0, 2] = (K[0, 2] - x0 + 0.5) * s - 0.5
    K[1, 2] = (K[1, 2] - y0 + 0.5) * s - 0.5
    return SilhouetteFrame(int(x0), int(y0), side, s, K)


def flip_views(image: np.ndarray, K_full: np.ndarray, window: tuple[int, int, int], silhouette_points: np.ndarray,
               pose_a: tuple[np.ndarray, np.ndarray], pose_b: tuple[np.ndarray, np.ndarray], size: int
               ) -> np.ndarray:
    """(3, size, size) float32 view (module docstring) of ``image`` (H, W[, C], rectified left, the
    intrinsics ``K_full`` (3, 3)) over ``window`` = full-frame ``(x0, y0, side)``, with the outlines of
    ``pose_a`` and ``pose_b`` ((R (3, 3), t (3,)) in the camera frame) drawn from ``silhouette_points``
    (S, 3, object frame)."""
    if size < 8:
        raise ValueError(f"flip_views: size must be >= 8, got {size}")
    check_shape(silhouette_points, (None, 3), "silhouette_points")
    x0, y0, side = (int(v) for v in window)
    frame = view_frame(K_full, x0, y0, side, size)
    n = frame.size
    grey = window_grey(image, x0, y0, side, n)
    mask_a = splat_mask(silhouette_points, pose_a[0], pose_a[1], frame)[0]
    mask_b = splat_mask(silhouette_points, pose_b[0], pose_b[1], frame)[0]
    union = (mask_a > 0) | (mask_b > 0)
    grey = np.nan_to_num(grey, nan=0.0, posinf=1.0, neginf=0.0)
    top = float(np.percentile(grey[union], 90)) if union.any() else float(np.percentile(grey, 99))
    out = np.empty((CHANNELS, n, n), np.float32)
    np.clip(grey / max(top, 1e-3), 0.0, 2.0, out=out[0])
    out[1] = mask_a
    out[2] = mask_b
    return out


def toned_views(views: np.ndarray, power: float) -> np.ndarray:
    """A copy of (N, 3, S, S) ``views`` with the grey plane raised to ``power`` and clipped to [0, 2] as
    :func:`flip_views` clips it: the views of the same images under another tone curve (the grey plane is a
    brightness relative to the target's own 90th percentile, which a power maps onto itself). The outlines
    are untouched. Used by the run-time check ``decide_tone_gamma`` and by the classifier's training."""
    if views.ndim != 4 or views.shape[1] != CHANNELS:
        raise ValueError(f"toned_views takes (N, {CHANNELS}, S, S) views, got {views.shape}")
    if not (np.isfinite(power) and power > 0.0):
        raise ValueError(f"toned_views: power must be finite and > 0, got {power}")
    out = np.array(views, dtype=np.float32, copy=True)
    np.clip(np.clip(out[:, 0], 0.0, 2.0) ** np.float32(power), 0.0, 2.0, out=out[:, 0])
    return out
