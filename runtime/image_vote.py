"""Which of two poses the left image's lit pixels support, where their outlines differ (numpy + OpenCV).

The outline stage (:mod:`spacepose.silhouette`) compares each pose's outline with the one the stereo
disparity shows. On a textureless black sky a stereo network carries the target's disparity a few
pixels into the background, and it blurs the thin parts (the dish, the boom) that tell the shipped
target from its 180° flip. The left image does neither: a lit pixel of the target is lit, a pixel of
empty space is dark.

The vote looks only where the two outlines disagree. ``A only``: pixels inside pose A's outline and
more than ``exclusion_px`` outside B's; ``B only`` the other way round (the band left out absorbs blur
and the refinements' residual misfit). A lit pixel in ``B only`` is one that pose A says is empty
space: evidence against A, and the other way round. The score is

    (lit pixels in A only - lit pixels in B only) / (pixels in A only + pixels in B only)

in [-1, 1]: positive for A. A dark pixel says nothing (the part may be in shadow), so an unlit part
abstains rather than votes.

*Lit* is relative to the sky around the target: the median and robust spread of a ring of pixels
just outside both outlines, and a floor of ``lit_fraction`` of the way from that level to the
target's own bright pixels. When more than ``max_background`` of that ring is itself lit (the Earth or
its limb behind the target, or a part of the target neither pose covers), the vote is not taken
(:attr:`ImageVote.usable` is False). So the vote depends on the image being brighter on the target than
on the sky right around it, not on any material or renderer.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np

from .errors import check_shape

__all__ = ["ImageVote", "grey_unit", "crop_to_frame", "window_grey", "image_vote"]

_KERNEL = np.ones((3, 3), np.uint8)


@dataclass(frozen=True)
class ImageVote:
    """Outcome of :func:`image_vote`.

    score: in [-1, 1], positive when the lit pixels support the first pose (module docstring); 0
        when the outlines do not differ.
    pixels: pixels where the two outlines differ (both exclusive regions).
    background_lit: share of the ring around both outlines that is lit.
    threshold: the lit threshold (image units of :func:`grey_unit`).
    usable: the ring is dark enough (``background_lit <= max_background``) and the outlines differ in
        at least ``min_pixels`` pixels.
    """

    score: float
    pixels: int
    background_lit: float
    threshold: float
    usable: bool


def grey_unit(image: np.ndarray) -> np.ndarray:
    """(H, W) float32 in [0, 1] of full scale: uint16 on 65535, uint8 and float on 255 (the estimator's
    convention); grey (H, W) or colour (H, W, C), channels averaged."""
    a = np.asarray(image)
    if a.ndim == 3:
        if a.shape[2] not in (1, 3, 4):
            raise ValueError(f"image: expected (H, W) or (H, W, 1|3|4), got {a.shape}")
        a = a[:, :, :3] if a.shape[2] == 4 else a
        if a.shape[2] == 1:
            a = a[:, :, 0]
        elif a.dtype in (np.uint8, np.uint16):   # an exact sum (< 2**24), one rounding: equal to .mean(axis=2)
            total = a[:, :, 0].astype(np.uint32)
            total += a[:, :, 1]
            total += a[:, :, 2]
            a = total.astype(np.float32) / np.float32(3)
        else:
            a = a.astype(np.float32).mean(axis=2)
    elif a.ndim != 2:
        raise ValueError(f"image: expected (H, W) or (H, W, C), got {a.shape}")
    scale = 65535.0 if np.asarray(image).dtype == np.uint16 else 255.0
    return np.ascontiguousarray(a, dtype=np.float32) / np.float32(scale)


def crop_to_frame(values: np.ndarray, x0: int, y0: int, side: int, size: int,
                  convert: Callable[[np.ndarray], np.ndarray] | None = None) -> np.ndarray:
    """(size, size) float32: the full-frame box ``(x0, y0, side)`` of ``values`` (H, W[, C]), zero
    outside the image, area-resampled to ``size``. ``convert`` maps the part of the box inside the image
    to (h, w) values first (so a threshold or a colour conversion touches the box only); without it
    ``values`` must be (H, W)."""
    a = np.asarray(values)
    if convert is None:
        check_shape(a, (None, None), "values")
    h, w = a.shape[:2]
    crop = np.zeros((side, side), np.float32)
    xa, ya, xb, yb = max(x0, 0), max(y0, 0), min(x0 + side, w), min(y0 + side, h)
    if xb > xa and yb > ya:
        box = a[ya:yb, xa:xb]
        crop[ya - y0:yb - y0, xa - x0:xb - x0] = box if convert is None else convert(box)
    if size != side:
        crop = cv2.resize(crop, (size, size), interpolation=cv2.INTER_AREA)
    return crop


def window_grey(image: np.ndarray, x0: int, y0: int, side: int, size: int) -> np.ndarray:
    """(size, size) float32 in [0, 1]: :func:`grey_unit` of the full-frame box ``(x0, y0, side)`` of
    ``image`` (H, W) or (H, W, C), converted after cropping (zero outside the image)."""
    return crop_to_frame(image, x0, y0, side, size, convert=grey_unit)


def image_vote(grey: np.ndarray, mask_a: np.ndarray, mask_b: np.ndarray, *, exclusion_px: int = 2,
               ring_px: tuple[int, int] = (3, 10), lit_sigma: float = 6.0, lit_fraction: float = 0.15,
               lit_floor: float = 0.02, max_background: float = 0.02, min_pixels: int = 0) -> ImageVote:
    """Vote between the outlines ``mask_a`` and ``mask_b`` (n, n, nonzero inside) with the lit pixels of
    ``grey`` (n, n, the same view, in [0, 1]; module docstring).

    exclusion_px: band (pixels of the view) around each outline left out of the other's exclusive
        region. ring_px: inner and outer distance of the sky ring around both outlines. lit_sigma,
        lit_fraction, lit_floor: the lit threshold is the ring's median plus the largest of
        ``lit_sigma`` robust standard deviations, ``lit_fraction`` of the way to the 90th percentile
        of the pixels inside the outlines, and ``lit_floor``. max_background: most lit share of the
        ring for a usable vote. min_pixels: fewest differing pixels for a usable vote (a far target's
        flip may move only a handful of pixels, too few to count on).
    """
    n = grey.shape[0] if grey.ndim == 2 else -1
    check_shape(grey, (n, n), "grey")
    check_shape(mask_a, (n, n), "mask_a")
    check_shape(mask_b, (n, n), "mask_b")
    if exclusion_px < 0 or not 0 <= ring_px[0] < ring_px[1]:
        raise ValueError(f"image_vote: bad exclusion_px {exclusion_px} or ring_px {ring_px}")
    a = (mask_a > 0).astype(np.uint8)
    b = (mask_b > 0).astype(np.uint8)
    union = np.maximum(a, b)
    if not union.any():
        return ImageVote(0.0, 0, 1.0, float("nan"), False)
    g = np.nan_to_num(np.asarray(grey, dtype=np.float32), nan=0.0, posinf=1.0, neginf=0.0)
    inner = cv2.dilate(union, _KERNEL, iterations=ring_px[0]) > 0 if ring_px[0] else union > 0
    ring = (cv2.dilate(union, _KERNEL, iterations=ring_px[1]) > 0) & ~inner
    sky = g[ring]
    inside = g[union > 0]
    level = float(np.median(sky)) if sky.size else 0.0
    spread = 1.4826 * float(np.median(np.abs(sky - level))) if sky.size else 0.0
    top = float(np.percentile(inside, 90))
    threshold = level + max(lit_sigma * spread, lit_fraction * (top - level), lit_floor)
    lit = g > threshold
    background_lit = float(np.mean(lit[ring])) if sky.size else 1.0
    if exclusion_px:
        only_a = (a > 0) & ~(cv2.dilate(b, _KERNEL, iterations=exclusion_px) > 0)
        only_b = (b > 0) & ~(cv2.dilate(a, _KERNEL, iterations=exclusion_px) > 0)
    else:
        only_a, only_b = (a > 0) & (b == 0), (b > 0) & (a == 0)
    pixels = int(only_a.sum() + only_b.sum())
    if pixels == 0:
        return ImageVote(0.0, 0, background_lit, threshold, False)
    score = (int(np.count_nonzero(lit & only_a)) - int(np.count_nonzero(lit & only_b))) / pixels
    usable = background_lit <= max_background and pixels >= max(min_pixels, 1)
    return ImageVote(float(score), pixels, background_lit, float(threshold), bool(usable))
