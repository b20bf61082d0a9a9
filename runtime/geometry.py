"""Pinhole and stereo geometry: disparity <-> depth, back-projection, point sampling, intrinsics.

Conventions (``spec/CONVENTIONS.md``): OpenCV camera axes (x right, y down, z forward), metres,
pixel centres at integer coordinates, ``Z = focal_px * baseline_m / d``. Intrinsics ``K`` are
3x3 float64 ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]``. Depth and disparity maps use ``0`` for
"unknown". Pure functions; numpy only.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

from .errors import ShapeError, check_finite, check_shape

__all__ = [
    "BackProjection",
    "disparity_to_depth",
    "depth_to_disparity",
    "backproject",
    "sample_indices",
    "crop_intrinsics",
    "resize_intrinsics",
    "project",
]

# concrete dtypes (not np.floating): check_shape names them in its message
_FLOAT_DTYPES = (np.float16, np.float32, np.float64)


def _positive_scalar(value: object, name: str) -> float:
    """Return ``value`` as a float, raising ValueError unless it is finite and > 0."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be a real number, got {type(value).__name__}")
    value = float(value)
    if not math.isfinite(value) or value <= 0.0:
        raise ValueError(f"{name} must be finite and > 0, got {value}")
    return value


def _check_intrinsics(K: object) -> np.ndarray:
    """Validate a 3x3 intrinsics matrix and return it as float64."""
    check_shape(K, (3, 3), "K", dtypes=_FLOAT_DTYPES)
    check_finite(K, "K")
    K = np.asarray(K, dtype=np.float64)
    if K[0, 0] <= 0.0 or K[1, 1] <= 0.0:
        raise ValueError(f"K must have fx > 0 and fy > 0, got fx={K[0, 0]}, fy={K[1, 1]}")
    if not np.array_equal(K[2], [0.0, 0.0, 1.0]) or K[1, 0] != 0.0:
        raise ValueError(f"K must be upper triangular with last row [0, 0, 1], got {K.tolist()}")
    return K


def _reciprocal_map(values: np.ndarray, numerator: float) -> np.ndarray:
    """``numerator / values`` as float32 where ``values`` is finite and > 0, else 0."""
    values64 = values.astype(np.float64, copy=False)
    good = np.isfinite(values64) & (values64 > 0.0)
    out = np.zeros(values.shape, dtype=np.float64)
    np.divide(numerator, values64, out=out, where=good)
    return out.astype(np.float32)


def disparity_to_depth(disparity: np.ndarray, focal_px: float, baseline_m: float) -> np.ndarray:
    """Depth ``Z = focal_px * baseline_m / d`` of a disparity map.

    Args:
        disparity: (H, W) floating, pixels; ``d <= 0``, NaN and inf mean "unknown".
        focal_px: focal length in pixels of the image the disparity refers to (> 0).
        baseline_m: stereo baseline in metres (> 0).

    Returns:
        depth: (H, W) float32 metres, ``0`` where the disparity is unknown.

    Raises:
        ShapeError: ``disparity`` is not a floating (H, W) array.
        ValueError: ``focal_px`` or ``baseline_m`` is not finite and positive.
    """
    check_shape(disparity, (None, None), "disparity", dtypes=_FLOAT_DTYPES)
    f = _positive_scalar(focal_px, "focal_px")
    b = _positive_scalar(baseline_m, "baseline_m")
    return _reciprocal_map(disparity, f * b)


def depth_to_disparity(depth: np.ndarray, focal_px: float, baseline_m: float) -> np.ndarray:
    """Disparity ``d = focal_px * baseline_m / Z`` of a depth map (inverse of :func:`disparity_to_depth`).

    Args:
        depth: (H, W) floating, metres; ``Z <= 0``, NaN and inf mean "unknown".
        focal_px: focal length in pixels (> 0).
        baseline_m: stereo baseline in metres (> 0).

    Returns:
        disparity: (H, W) float32 pixels, ``0`` where the depth is unknown.

    Raises:
        ShapeError: ``depth`` is not a floating (H, W) array.
        ValueError: ``focal_px`` or ``baseline_m`` is not finite and positive.
    """
    check_shape(depth, (None, None), "depth", dtypes=_FLOAT_DTYPES)
    f = _positive_scalar(focal_px, "focal_px")
    b = _positive_scalar(baseline_m, "baseline_m")
    return _reciprocal_map(depth, f * b)


@dataclass(frozen=True)
class BackProjection:
    """Camera-frame points of a depth map, with the pixel and colour each came from.

    Attributes:
        points: (N, 3) float32 camera-frame coordinates in metres (OpenCV axes).
        pixels: (N, 2) int32 pixel coordinates ``(u, v)`` = ``(x, y)`` = (column, row).
        colors: (N, C) float32 image values at those pixels (C = 1 for grey), or ``None``.
    """

    points: np.ndarray
    pixels: np.ndarray
    colors: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.points.shape[0])


def backproject(
    depth: np.ndarray,
    K: np.ndarray,
    mask: np.ndarray | None = None,
    image: np.ndarray | None = None,
) -> BackProjection:
    """Back-project the valid pixels of a depth map to camera-frame points.

    A pixel ``(u, v)`` with depth ``Z`` becomes ``Z * K^-1 [u, v, 1]^T``. A pixel is used when
    its depth is finite and > 0 and (if given) ``mask`` is True there. Points come in row-major
    pixel order (as ``np.nonzero``).

    Args:
        depth: (H, W) floating, metres, 0 (or NaN/inf) where invalid.
        K: (3, 3) floating intrinsics of the depth map's image.
        mask: (H, W) bool or ``None`` (all pixels).
        image: (H, W) or (H, W, C) image aligned with ``depth`` (any real dtype) or ``None``.

    Returns:
        :class:`BackProjection` with ``points`` (N, 3) float32, ``pixels`` (N, 2) int32 ``(u, v)``
        and ``colors`` (N, C) float32 (``None`` without ``image``).

    Raises:
        ShapeError: wrong shape or dtype of any input, or non-finite ``K``.
        ValueError: ``K`` has a non-positive focal length or is not upper triangular.
    """
    check_shape(depth, (None, None), "depth", dtypes=_FLOAT_DTYPES)
    K = _check_intrinsics(K)
    height, width = depth.shape
    valid = np.isfinite(depth) & (depth > 0)
    if mask is not None:
        check_shape(mask, (height, width), "mask", dtypes=(np.bool_,))
        valid &= mask
    if image is not None:
        if not isinstance(image, np.ndarray) or image.ndim not in (2, 3):
            raise ShapeError(f"image must be a numpy array of shape (H, W) or (H, W, C), got {getattr(image, 'shape', type(image).__name__)}")
        if image.shape[:2] != (height, width):
            raise ShapeError(f"image must have shape ({height}, {width}[, C]) like depth, got {image.shape}")
        if not (np.issubdtype(image.dtype, np.integer) or np.issubdtype(image.dtype, np.floating)):
            raise ShapeError(f"image must have an integer or floating dtype, got {image.dtype}")

    rows, cols = np.nonzero(valid)
    z = depth[rows, cols].astype(np.float64)
    K_inv = np.linalg.inv(K)
    pix_h = np.stack([cols.astype(np.float64), rows.astype(np.float64), np.ones_like(z)], axis=1)
    rays = pix_h @ K_inv.T  # (N, 3), z component is exactly 1 for an upper-triangular K
    points = (rays * z[:, None]).astype(np.float32)
    pixels = np.stack([cols, rows], axis=1).astype(np.int32)

    colors = None
    if image is not None:
        values = image[rows, cols]
        colors = values.reshape(values.shape[0], -1).astype(np.float32)
    return BackProjection(points=points, pixels=pixels, colors=colors)


def _count(value: object, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ShapeError(f"{name} must be an integer, got {type(value).__name__}")
    value = int(value)
    if value < 0:
        raise ShapeError(f"{name} must be >= 0, got {value}")
    return value


def sample_indices(n_available: int, n_out: int, seed: int) -> np.ndarray:
    """Deterministic fixed-count sample of ``range(n_available)``.

    With ``n_available >= n_out`` the indices are drawn without replacement. With fewer points
    every index appears ``n_out // n_available`` or one more times: a random permutation of all
    indices is repeated (tiled) until ``n_out`` are filled. The same arguments always give the
    same result (``numpy.random.default_rng(seed)``).

    Args:
        n_available: number of points to draw from (>= 1).
        n_out: number of indices wanted (>= 0).
        seed: integer seed.

    Returns:
        (n_out,) int64 indices in ``[0, n_available)``.

    Raises:
        ShapeError: ``n_available`` is 0 (nothing to sample), a count is negative or not an integer.
    """
    n_available = _count(n_available, "n_available")
    n_out = _count(n_out, "n_out")
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral):
        raise ShapeError(f"seed must be an integer, got {type(seed).__name__}")
    if n_available == 0:
        raise ShapeError("n_available must be >= 1: cannot sample from an empty point set")
    rng = np.random.default_rng(int(seed))
    if n_available >= n_out:
        return rng.choice(n_available, size=n_out, replace=False).astype(np.int64)
    order = rng.permutation(n_available).astype(np.int64)
    return np.resize(order, n_out)


def crop_intrinsics(K: np.ndarray, x0: float, y0: float) -> np.ndarray:
    """Intrinsics of the crop whose top-left pixel is ``(x0, y0)`` of the original image.

    ``cx' = cx - x0``, ``cy' = cy - y0``; focal lengths and skew unchanged. Negative offsets
    describe a zero-padded window that starts outside the image.

    Args:
        K: (3, 3) floating intrinsics.
        x0, y0: column and row of the crop's top-left pixel in the original image.

    Returns:
        (3, 3) float64 intrinsics of the crop (a new array).

    Raises:
        ShapeError: ``K`` is not a finite floating (3, 3) array.
        ValueError: non-finite offsets, or an invalid ``K``.
    """
    K = _check_intrinsics(K).copy()
    for name, value in (("x0", x0), ("y0", y0)):
        if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(float(value)):
            raise ValueError(f"{name} must be a finite number, got {value!r}")
    K[0, 2] -= float(x0)
    K[1, 2] -= float(y0)
    return K


def resize_intrinsics(K: np.ndarray, sx: float, sy: float) -> np.ndarray:
    """Intrinsics after resizing the image by ``sx`` horizontally and ``sy`` vertically.

    Pixel centres stay at integer coordinates (``cv2.resize`` convention):
    ``fx' = fx*sx``, ``s' = s*sx``, ``cx' = (cx + 0.5)*sx - 0.5``; likewise ``fy``, ``cy`` with ``sy``.

    Args:
        K: (3, 3) floating intrinsics.
        sx, sy: scale factors (new size / old size), > 0.

    Returns:
        (3, 3) float64 intrinsics of the resized image (a new array).

    Raises:
        ShapeError: ``K`` is not a finite floating (3, 3) array.
        ValueError: a scale is not finite and positive, or an invalid ``K``.
    """
    K = _check_intrinsics(K).copy()
    sx = _positive_scalar(sx, "sx")
    sy = _positive_scalar(sy, "sy")
    K[0, 0] *= sx
    K[0, 1] *= sx
    K[0, 2] = (K[0, 2] + 0.5) * sx - 0.5
    K[1, 1] *= sy
    K[1, 2] = (K[1, 2] + 0.5) * sy - 0.5
    return K


def project(points: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Pinhole projection of camera-frame points to pixel coordinates ``(u, v)``.

    Points with ``z <= 0`` (on or behind the camera plane) have no image: their row is NaN.

    Args:
        points: (N, 3) floating camera-frame points in metres, finite.
        K: (3, 3) floating intrinsics.

    Returns:
        (N, 2) float64 pixel coordinates ``(u, v)`` (NaN where ``z <= 0``).

    Raises:
        ShapeError: wrong shape or dtype, or NaN/inf in ``points`` or ``K``.
        ValueError: an invalid ``K``.
    """
    check_shape(points, (None, 3), "points", dtypes=_FLOAT_DTYPES)
    check_finite(points, "points")
    K = _check_intrinsics(K)
    pts = points.astype(np.float64, copy=False)
    z = pts[:, 2]
    in_front = z > 0.0
    uvw = pts @ K.T
    out = np.full((pts.shape[0], 2), np.nan, dtype=np.float64)
    out[in_front] = uvw[in_front, :2] / z[in_front, None]
    return out
