"""Region-of-interest geometry shared by stereo training and flight (numpy + OpenCV only).

The stereo graph has one fixed input size (default 256x256). Two kinds of input are made from a
rectified frame, and training crops them with exactly these functions so that train and flight
agree to the pixel:

* the *letterbox* view: the whole frame, aspect kept, resized and zero padded (coarse pass);
* the *ROI window*: one square pixel window, the same in left and right, zero padded beyond the
  image, that holds the target in the left image and its copy shifted by ``-d`` in the right image
  (fine pass).

Both are an axis-aligned affine map of full-frame pixel centres to net pixel centres::

    u' = sx * u + tx,   v' = sy * v + ty

with pixel centres at integer coordinates (``cx' = (cx + 0.5) * s - 0.5`` for a resize, as in
``spacepose.geometry.resize_intrinsics``). Disparity measured in net pixels is full-frame disparity
times ``sx``; :meth:`CropTransform.intrinsics` moves a pinhole matrix along.

Boxes are ``(x0, y0, x1, y1)`` integer pixel bounds with ``x1``/``y1`` exclusive.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from .errors import ShapeError

__all__ = [
    "Window",
    "CropTransform",
    "square_window",
    "window_transform",
    "letterbox_transform",
    "crop_resize",
    "letterbox",
    "warp_to_net",
    "warp_to_full",
    "bbox_from_mask",
    "bbox_from_disparity",
    "disparity_range",
    "WINDOW_DISPARITY_FILL",
    "COARSE_TILE_OVERLAP_PX",
]

BBox = tuple[int, int, int, int]

#: a fine-pass window is at least wide enough that the target's largest disparity maps to this share
#: of the graph's ``max_disp`` (:func:`square_window`); so a rig with a long baseline still gives the
#: graph disparities it can output, at a coarser window
WINDOW_DISPARITY_FILL = 0.9
#: overlap (graph px) of neighbouring tiles of a tiled coarse pass (:class:`spacepose.stereo_stage.StereoMatcher`)
COARSE_TILE_OVERLAP_PX = 32


@dataclass(frozen=True)
class Window:
    """A square pixel window of a full frame: columns ``x0 .. x0+side-1``, rows ``y0 .. y0+side-1``.

    It may extend beyond the image (those pixels read as zero).
    """

    x0: int
    y0: int
    side: int

    def __post_init__(self) -> None:
        if self.side < 1:
            raise ValueError(f"window side must be >= 1, got {self.side}")

    @property
    def bbox(self) -> BBox:
        return (self.x0, self.y0, self.x0 + self.side, self.y0 + self.side)


@dataclass(frozen=True)
class CropTransform:
    """Full-frame pixel -> net pixel: ``u' = sx*u + tx``, ``v' = sy*v + ty`` (pixel centres integer).

    ``out_size`` is the net input size (width, height).
    """

    sx: float
    sy: float
    tx: float
    ty: float
    out_size: tuple[int, int]

    @property
    def scale(self) -> float:
        """Horizontal scale: disparity in net pixels = full-frame disparity * ``scale``."""
        return self.sx

    @property
    def matrix(self) -> np.ndarray:
        """The 2x3 affine (float64) that maps full-frame pixels to net pixels."""
        return np.array([[self.sx, 0.0, self.tx], [0.0, self.sy, self.ty]], dtype=np.float64)

    def to_net(self, points: np.ndarray) -> np.ndarray:
        """Map (N, 2) full-frame pixel coordinates to net pixel coordinates."""
        p = np.asarray(points, dtype=np.float64)
        return np.stack([p[..., 0] * self.sx + self.tx, p[..., 1] * self.sy + self.ty], axis=-1)

    def to_full(self, points: np.ndarray) -> np.ndarray:
        """Map (N, 2) net pixel coordinates back to full-frame pixel coordinates."""
        p = np.asarray(points, dtype=np.float64)
        return np.stack([(p[..., 0] - self.tx) / self.sx, (p[..., 1] - self.ty) / self.sy], axis=-1)

    def intrinsics(self, K: np.ndarray) -> np.ndarray:
        """The pinhole matrix of the net view, given the full-frame one (3x3 float64)."""
        K = np.asarray(K, dtype=np.float64)
        A = np.array([[self.sx, 0.0, self.tx], [0.0, self.sy, self.ty], [0.0, 0.0, 1.0]])
        return A @ K

    def net_bbox_to_full(self, bbox: BBox, size: tuple[int, int] | None = None) -> BBox:
        """Map a net-pixel box to the enclosing full-frame box (clipped to ``size`` if given)."""
        x0, y0, x1, y1 = bbox
        (u0, v0), (u1, v1) = self.to_full(np.array([[x0 - 0.5, y0 - 0.5], [x1 - 0.5, y1 - 0.5]]))
        out = [math.floor(u0 + 0.5), math.floor(v0 + 0.5), math.ceil(u1 + 0.5), math.ceil(v1 + 0.5)]
        if size is not None:
            w, h = size
            out = [min(max(out[0], 0), w), min(max(out[1], 0), h), min(max(out[2], 0), w), min(max(out[3], 0), h)]
        return (out[0], out[1], out[2], out[3])


def _check_size(size: tuple[int, int], name: str = "size") -> tuple[int, int]:
    if len(size) != 2 or int(size[0]) < 1 or int(size[1]) < 1:
        raise ValueError(f"{name} must be (width, height) with positive entries, got {size!r}")
    return int(size[0]), int(size[1])


def square_window(
    bbox: BBox,
    d_min: float,
    d_max: float,
    margin: float = 1.25,
    *,
    center_jitter: tuple[float, float] = (0.0, 0.0),
    min_side: int = 32,
    out_side: int | None = None,
    max_disp: float | None = None,
) -> Window:
    """The square window that holds the target in the left image and its shifted copy in the right.

    Args:
        bbox: target box in the left rectified image, full-frame pixels ``(x0, y0, x1, y1)``.
        d_min, d_max: disparity range of the target (full-frame pixels, ``0 <= d_min <= d_max``).
            The right-image copy occupies columns ``x0 - d_max .. x1 - d_min``.
        margin: side = margin * longest side of the union box (>= 1).
        center_jitter: shift of the window centre, in units of the side (training only).
        min_side: smallest side in pixels (limits the upsampling of far, small targets).
        out_side, max_disp: when both are given the side is enlarged so that ``d_max`` maps below
            ``WINDOW_DISPARITY_FILL * max_disp`` net pixels (the graph cannot output more than ``max_disp``).
    """
    x0, y0, x1, y1 = (float(b) for b in bbox)
    if not (x1 > x0 and y1 > y0):
        raise ValueError(f"empty bbox {bbox!r}")
    if not (math.isfinite(d_min) and math.isfinite(d_max)) or d_min < 0 or d_max < d_min:
        raise ValueError(f"need 0 <= d_min <= d_max, got {d_min}, {d_max}")
    if margin < 1.0:
        raise ValueError(f"margin must be >= 1, got {margin}")
    ux0, ux1 = x0 - d_max, x1  # union of the left box and its right-image copy
    uy0, uy1 = y0, y1
    side = max(ux1 - ux0, uy1 - uy0) * margin
    side = max(side, float(min_side))
    if out_side is not None and max_disp is not None and d_max > 0:
        side = max(side, d_max * out_side / (WINDOW_DISPARITY_FILL * max_disp))
    side_i = int(math.ceil(side))
    cx = 0.5 * (ux0 + ux1) + center_jitter[0] * side_i
    cy = 0.5 * (uy0 + uy1) + center_jitter[1] * side_i
    return Window(int(round(cx - side_i / 2.0)), int(round(cy - side_i / 2.0)), side_i)


def window_transform(window: Window, size: tuple[int, int]) -> CropTransform:
    """Transform of a square window resized to ``size`` (its side maps onto the net width)."""
    w, h = _check_size(size)
    sx = w / window.side
    sy = h / window.side
    return CropTransform(sx, sy, (0.5 - window.x0) * sx - 0.5, (0.5 - window.y0) * sy - 0.5, (w, h))


def letterbox_transform(image_size: tuple[int, int], size: tuple[int, int]) -> CropTransform:
    """Transform of the whole ``image_size`` frame letterboxed (aspect kept, centred) into ``size``."""
    iw, ih = _check_size(image_size, "image_size")
    w, h = _check_size(size)
    s = min(w / iw, h / ih)
    nw, nh = max(1, int(round(iw * s))), max(1, int(round(ih * s)))
    sx, sy = nw / iw, nh / ih
    ox, oy = (w - nw) // 2, (h - nh) // 2
    return CropTransform(sx, sy, 0.5 * sx - 0.5 + ox, 0.5 * sy - 0.5 + oy, (w, h))


def _is_integer(x: float) -> bool:
    return abs(x - round(x)) < 1e-9


def warp_to_net(image: np.ndarray, transform: CropTransform, *, nearest: bool = False) -> np.ndarray:
    """Resample a full-frame ``image`` (H, W[, C]) into the net view; zero beyond the image.

    Downscaling uses area averaging (anti-aliased) when the view is an integer-offset crop+resize;
    ``nearest=True`` is for label maps (disparity, masks).
    """
    if not isinstance(image, np.ndarray) or image.ndim not in (2, 3):
        raise ShapeError(f"image must be an (H, W) or (H, W, C) array, got {getattr(image, 'shape', type(image))}")
    w, h = transform.out_size
    src = image if image.dtype != np.bool_ else image.astype(np.uint8)
    interp = cv2.INTER_NEAREST_EXACT if nearest else cv2.INTER_LINEAR
    # crop+resize path: integer source window, then cv2.resize (area when shrinking)
    cx0 = (-0.5 - transform.tx) / transform.sx + 0.5  # full-frame column of the net's left edge
    cy0 = (-0.5 - transform.ty) / transform.sy + 0.5
    cw = w / transform.sx
    ch = h / transform.sy
    if all(_is_integer(v) for v in (cx0, cy0, cw, ch)):
        out = _crop_padded(src, int(round(cx0)), int(round(cy0)), int(round(cw)), int(round(ch)))
        if out.shape[1] != w or out.shape[0] != h:
            if not nearest and (w < out.shape[1] or h < out.shape[0]):
                interp = cv2.INTER_AREA
            out = cv2.resize(out, (w, h), interpolation=interp)
    else:
        # letterbox path (offset not an integer number of source pixels): resize then pad
        out = _letterbox_by_resize(src, transform, interp, nearest)
    if out.ndim == 2 and image.ndim == 3:
        out = out[..., None]
    return out.astype(image.dtype, copy=False)


def _letterbox_by_resize(src: np.ndarray, t: CropTransform, interp: int, nearest: bool) -> np.ndarray:
    w, h = t.out_size
    ih, iw = src.shape[:2]
    nw, nh = int(round(iw * t.sx)), int(round(ih * t.sy))
    ox = t.tx - 0.5 * t.sx + 0.5
    oy = t.ty - 0.5 * t.sy + 0.5
    if not (_is_integer(ox) and _is_integer(oy)):
        M = t.matrix
        return cv2.warpAffine(src, M, (w, h), flags=interp, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    if not nearest and (nw < iw or nh < ih):
        interp = cv2.INTER_AREA
    small = cv2.resize(src, (nw, nh), interpolation=interp)
    out = np.zeros((h, w) + src.shape[2:], dtype=src.dtype)
    ox, oy = int(round(ox)), int(round(oy))
    xs0, ys0 = max(0, -ox), max(0, -oy)
    xd0, yd0 = max(0, ox), max(0, oy)
    cw = min(nw - xs0, w - xd0)
    ch = min(nh - ys0, h - yd0)
    if cw > 0 and ch > 0:
        out[yd0:yd0 + ch, xd0:xd0 + cw] = small[ys0:ys0 + ch, xs0:xs0 + cw]
    return out


def _crop_padded(image: np.ndarray, x0: int, y0: int, cw: int, ch: int) -> np.ndarray:
    """``image[y0:y0+ch, x0:x0+cw]`` with zeros where the window leaves the image."""
    ih, iw = image.shape[:2]
    out = np.zeros((ch, cw) + image.shape[2:], dtype=image.dtype)
    sx0, sy0 = max(x0, 0), max(y0, 0)
    sx1, sy1 = min(x0 + cw, iw), min(y0 + ch, ih)
    if sx1 > sx0 and sy1 > sy0:
        out[sy0 - y0:sy1 - y0, sx0 - x0:sx1 - x0] = image[sy0:sy1, sx0:sx1]
    return out


def crop_resize(image: np.ndarray, window: Window, size: tuple[int, int], *, nearest: bool = False) -> tuple[np.ndarray, CropTransform]:
    """Cut ``window`` out of ``image`` (zero padded) and resize it to ``size`` -> (view, transform)."""
    t = window_transform(window, size)
    return warp_to_net(image, t, nearest=nearest), t


def letterbox(image: np.ndarray, size: tuple[int, int], *, nearest: bool = False) -> tuple[np.ndarray, CropTransform]:
    """Letterbox the whole ``image`` into ``size`` (aspect kept, centred, zero padded)."""
    if not isinstance(image, np.ndarray) or image.ndim not in (2, 3):
        raise ShapeError(f"image must be an (H, W) or (H, W, C) array, got {getattr(image, 'shape', type(image))}")
    t = letterbox_transform((image.shape[1], image.shape[0]), size)
    return warp_to_net(image, t, nearest=nearest), t


def warp_to_full(net_map: np.ndarray, transform: CropTransform, image_size: tuple[int, int], *, nearest: bool = False) -> np.ndarray:
    """Resample a net-view map (h, w) back onto the full frame ``image_size``; 0 outside the view.

    Values are not rescaled: divide a disparity by ``transform.scale`` yourself.
    """
    iw, ih = _check_size(image_size, "image_size")
    w, h = transform.out_size
    check = np.asarray(net_map)
    if check.ndim != 2 or check.shape != (h, w):
        raise ShapeError(f"net_map must have shape ({h}, {w}), got {check.shape}")
    flags = (cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR) | cv2.WARP_INVERSE_MAP
    src = check.astype(np.float32, copy=False)
    # pixels whose centre maps outside the net view get exactly 0 (no half-blended border values),
    # so only the full-frame box of the pixels inside it is resampled
    u = np.arange(iw) * transform.sx + transform.tx
    v = np.arange(ih) * transform.sy + transform.ty
    cols = np.flatnonzero((u >= -0.5) & (u <= w - 0.5))
    rows = np.flatnonzero((v >= -0.5) & (v <= h - 0.5))
    out = np.zeros((ih, iw), dtype=np.float32)
    if len(cols) == 0 or len(rows) == 0:
        return out
    x0, x1, y0, y1 = int(cols[0]), int(cols[-1]) + 1, int(rows[0]), int(rows[-1]) + 1
    M = np.array(transform.matrix, dtype=np.float64, copy=True)
    M[:, 2] += M[:, :2] @ np.array([x0, y0], dtype=np.float64)  # box pixel (x, y) is frame (x0 + x, y0 + y)
    out[y0:y1, x0:x1] = cv2.warpAffine(src, M, (x1 - x0, y1 - y0), flags=flags, borderMode=cv2.BORDER_CONSTANT,
                                       borderValue=0)
    return out


def bbox_from_mask(mask: np.ndarray) -> BBox | None:
    """Tight box of the non-zero pixels of a 2-D mask, or ``None`` when it is empty."""
    m = np.asarray(mask)
    if m.ndim != 2:
        raise ShapeError(f"mask must be 2-D, got shape {m.shape}")
    ys, xs = np.nonzero(m)
    if xs.size == 0:
        return None
    return (int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1)


def bbox_from_disparity(disparity: np.ndarray, threshold: float, *, min_pixels: int = 16, keep_fraction: float = 0.1) -> BBox | None:
    """Box of the target in a (coarse) disparity map: pixels with ``d > threshold``.

    Earth and stars sit at ~0 disparity. Connected components smaller than ``keep_fraction`` of the
    largest one are dropped as speckle; ``None`` when fewer than ``min_pixels`` pixels remain.
    """
    d = np.asarray(disparity, dtype=np.float32)
    if d.ndim != 2:
        raise ShapeError(f"disparity must be 2-D, got shape {d.shape}")
    fg = (np.nan_to_num(d, nan=0.0, posinf=0.0, neginf=0.0) > threshold).astype(np.uint8)
    if int(fg.sum()) < min_pixels:
        return None
    n, labels, stats, _ = cv2.connectedComponentsWithStats(fg, connectivity=8)
    if n <= 1:
        return None
    areas = stats[1:, cv2.CC_STAT_AREA]
    keep = np.flatnonzero(areas >= max(keep_fraction * areas.max(), 1)) + 1
    if int(stats[keep, cv2.CC_STAT_AREA].sum()) < min_pixels:
        return None
    x0 = int(stats[keep, cv2.CC_STAT_LEFT].min())
    y0 = int(stats[keep, cv2.CC_STAT_TOP].min())
    x1 = int((stats[keep, cv2.CC_STAT_LEFT] + stats[keep, cv2.CC_STAT_WIDTH]).max())
    y1 = int((stats[keep, cv2.CC_STAT_TOP] + stats[keep, cv2.CC_STAT_HEIGHT]).max())
    return (x0, y0, x1, y1)


def disparity_range(disparity: np.ndarray, region: np.ndarray | None = None, threshold: float = 0.0,
                    percentiles: tuple[float, float] = (2.0, 98.0)) -> tuple[float, float] | None:
    """Robust (low, high) disparity of the pixels above ``threshold`` (inside ``region`` if given)."""
    d = np.asarray(disparity, dtype=np.float32)
    sel = np.isfinite(d) & (d > threshold)
    if region is not None:
        sel &= np.asarray(region, dtype=bool)
    vals = d[sel]
    if vals.size == 0:
        return None
    lo, hi = np.percentile(vals, percentiles)
    return float(lo), float(hi)
