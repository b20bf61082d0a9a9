"""Left-right photometric consistency of a fitted pose: an image check the stereo graph cannot fool.

The pose stage fits a pose to the stereo points, and the surface check compares the pose with those
same points — so when the stereo graph itself is wrong (the target given the Earth's disparity, a
window that took in the Earth) a wrong pose passes both. This check goes back to the images: the
target's surface samples placed at the fitted pose are projected into the rectified left image at
``(u, v)`` and into the right one at ``(u - f·B/Z, v)``; at the right pose both see the same surface
point, so small patches around the two projections match (zero-mean normalised cross-correlation,
ZNCC, immune to gain and offset). At a pose with the wrong depth, or on the wrong object, they do not.
Patches that match themselves a few pixels along the row (smooth gradients, such as the Earth's
limb or haze) would agree at any depth and are left out.

Only surface samples visible from the left camera (nearest in a coarse z-buffer) and patches with
texture (intensity spread above ``min_std`` in both images) are scored. The score is the median ZNCC;
``None`` when fewer than ``min_patches`` patches qualify (a dark, untextured view cannot be
verified: the caller decides). A 180° flip of a nearly symmetric target puts its surface on the same
pixels at the same depth and is NOT caught here.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from spacepose.errors import check_shape

__all__ = ["PhotoConsistency", "photometric_consistency", "project_surface", "to_grey_float", "visible_mask"]


@dataclass(frozen=True)
class PhotoConsistency:
    """Result of :func:`photometric_consistency`.

    score: median ZNCC over the scored patches (``None``: too few textured visible patches).
    patches: patches scored; visible: surface samples in view and on the front in the z-buffer.
    """

    score: float | None
    patches: int
    visible: int


def to_grey_float(image: np.ndarray) -> np.ndarray:
    """(H, W) or (H, W, 3) image -> (H, W) float32 grey in [0, 1] (integers by their dtype's maximum,
    floats on the 0-255 scale as everywhere in the estimator)."""
    scale = float(np.iinfo(image.dtype).max) if np.issubdtype(image.dtype, np.integer) else 255.0
    grey = np.asarray(image, dtype=np.float32)
    if grey.ndim == 3:
        grey = cv2.cvtColor(np.ascontiguousarray(grey), cv2.COLOR_RGB2GRAY) if grey.shape[2] == 3 else grey[..., 0]
    return grey / scale


def project_surface(R: np.ndarray, t: np.ndarray, surface: np.ndarray, K: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(u, v, z)``, each (M,) float64: the object-frame samples ``surface`` (S, 3) at the pose ``(R, t)`` (object ->
    camera), those in front of the camera (z > 1e-6 m), projected with the intrinsics ``K`` (3, 3)."""
    pts = np.asarray(surface, np.float64) @ np.asarray(R, np.float64).T + np.asarray(t, np.float64)
    z = pts[:, 2]
    front = z > 1e-6
    pts, z = pts[front], z[front]
    u = float(K[0, 0]) * pts[:, 0] / z + K[0, 2]
    v = float(K[1, 1]) * pts[:, 1] / z + K[1, 2]
    return u, v, z


def visible_mask(uv: np.ndarray, z: np.ndarray, cell_px: float, depth_tol: float) -> np.ndarray:
    """(N,) boolean mask of the points ``uv`` (N, 2, pixels) at depths ``z`` (N,) within ``depth_tol`` of the
    nearest point in their ``cell_px`` cell (a coarse z-buffer)."""
    cells = np.floor(uv / cell_px).astype(np.int64)
    key = cells[:, 0] * 1_000_003 + cells[:, 1]
    order = np.lexsort((z, key))
    key_sorted = key[order]
    first = np.ones(len(order), dtype=bool)
    first[1:] = key_sorted[1:] != key_sorted[:-1]
    group = np.cumsum(first) - 1
    zmin = z[order][first][group]
    keep = np.zeros(len(z), dtype=bool)
    keep[order] = z[order] <= zmin + depth_tol
    return keep


def photometric_consistency(R: np.ndarray, t: np.ndarray, surface: np.ndarray, left: np.ndarray, right: np.ndarray,
                            K: np.ndarray, baseline_m: float, *, radius: int = 2, min_std: float = 0.008,
                            min_patches: int = 20, depth_tol_m: float | None = None, shift_px: float = 2.0,
                            max_self_zncc: float = 0.7) -> PhotoConsistency:
    """Median left-right patch ZNCC of the target's visible surface at the pose ``(R, t)``.

    Args:
        R: (3, 3), t: (3,) object -> rectified left camera.
        surface: (S, 3) object-frame surface samples.
        left, right: rectified images, (H, W) or (H, W, 3), same size, any dtype.
        K: (3, 3) rectified intrinsics (zero-disparity rectification: ``u_right = u_left - f·B/Z``).
        baseline_m: rectified baseline in metres.
        radius: patch half-size in pixels ((2r+1)² samples per patch).
        min_std: least intensity standard deviation of a patch in both images (grey in [0, 1] for integer
            images, i.e. about 2 grey levels of 8 bits).
        min_patches: least scored patches for a score.
        depth_tol_m: z-buffer tolerance (default: 5 % of the surface's extent).
        shift_px, max_self_zncc: a patch whose ZNCC with the left image shifted by ``±shift_px`` along
            the row exceeds ``max_self_zncc`` is not distinctive and is not scored.
    """
    check_shape(R, (3, 3), "R")
    check_shape(t, (3,), "t")
    check_shape(surface, (None, 3), "surface")
    check_shape(K, (3, 3), "K")
    if left.shape[:2] != right.shape[:2]:
        raise ValueError(f"left {left.shape[:2]} and right {right.shape[:2]} differ in size")
    h, w = left.shape[:2]
    if len(surface) == 0 or not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
        return PhotoConsistency(None, 0, 0)
    u, v, z = project_surface(R, t, surface, K)
    if len(z) == 0:
        return PhotoConsistency(None, 0, 0)
    f = float(K[0, 0])
    d = f * float(baseline_m) / z
    margin = radius + 1
    inside = (u - d >= margin) & (u < w - margin) & (v >= margin) & (v < h - margin)
    u, v, d, z = u[inside], v[inside], d[inside], z[inside]
    if len(z) == 0:
        return PhotoConsistency(None, 0, 0)
    extent = float(np.ptp(np.asarray(surface, np.float64), axis=0).max())
    tol = 0.05 * extent if depth_tol_m is None else float(depth_tol_m)
    cell = max(2.0 * radius + 1.0, 1.0)
    vis = visible_mask(np.stack([u, v], axis=1), z, cell, tol)
    u, v, d = u[vis], v[vis], d[vis]
    offsets = np.arange(-radius, radius + 1, dtype=np.float32)
    dx, dy = np.meshgrid(offsets, offsets)
    map_x = (u[:, None] + dx.ravel()[None, :]).astype(np.float32)
    map_y = (v[:, None] + dy.ravel()[None, :]).astype(np.float32)
    shift = d[:, None].astype(np.float32)
    # only the box the patches sample from is converted to grey (same values: remap reads at most one
    # pixel beyond a sample, and the box is clipped to the image, where the border rule is the same)
    x0 = max(int(np.floor(map_x.min() - float(shift_px) - float(shift.max()))) - 1, 0)
    x1 = min(int(np.ceil(map_x.max() + float(shift_px))) + 2, w)
    y0 = max(int(np.floor(map_y.min())) - 1, 0)
    y1 = min(int(np.ceil(map_y.max())) + 2, h)
    grey_l, grey_r = to_grey_float(left[y0:y1, x0:x1]), to_grey_float(right[y0:y1, x0:x1])
    map_x -= np.float32(x0)
    map_y -= np.float32(y0)

    def patches(grey: np.ndarray, dx_px: np.ndarray | float) -> np.ndarray:
        p = cv2.remap(grey, map_x + dx_px, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        return p - p.mean(axis=1, keepdims=True)

    def zncc(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return (a * b).mean(axis=1) / np.maximum(np.sqrt((a ** 2).mean(axis=1) * (b ** 2).mean(axis=1)), 1e-12)

    pl, pr = patches(grey_l, 0.0), patches(grey_r, -shift)
    sl, sr = np.sqrt((pl ** 2).mean(axis=1)), np.sqrt((pr ** 2).mean(axis=1))
    # a patch is only evidence if it would NOT match itself shifted along the epipolar line (smooth
    # gradients, e.g. the Earth's limb, correlate at any disparity)
    self_match = np.maximum(zncc(pl, patches(grey_l, float(shift_px))), zncc(pl, patches(grey_l, -float(shift_px))))
    usable = (sl >= min_std) & (sr >= min_std) & (self_match <= max_self_zncc)
    n = int(usable.sum())
    if n < min_patches:
        return PhotoConsistency(None, n, int(vis.sum()))
    return PhotoConsistency(float(np.median(zncc(pl[usable], pr[usable]))), n, int(vis.sum()))
