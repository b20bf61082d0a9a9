"""Pixels that the images place at infinity, whatever disparity a network gave them.

The Earth, its limb and clouds are, at orbital ranges, at zero disparity. A stereo network that
hallucinates a few pixels of disparity there makes the coarse pass take the Earth for the target.
The images themselves settle it: around such a pixel the left image matches the right one
*unshifted* better than shifted by the predicted disparity. :func:`infinity_mask` compares the local
zero-mean normalised cross-correlation (ZNCC, box windows) of the two hypotheses on textured pixels.
The real target, tens of pixels of disparity away, does not match at zero shift, so it is kept.
:func:`infinity_regions` decides per connected region of candidate pixels (a region mostly at
infinity goes as a whole: the pixels along a limb or a shadow edge, which match at any shift, go
with it).
"""

from __future__ import annotations

import cv2
import numpy as np

from .errors import check_shape

__all__ = ["local_zncc", "infinity_mask", "infinity_regions"]


def _grey(image: np.ndarray) -> np.ndarray:
    """(H, W) / (H, W, 3) / (1, 3, H, W) -> (H, W) float32 (scale does not matter to ZNCC)."""
    a = np.asarray(image, dtype=np.float32)
    if a.ndim == 4:
        return a[0].mean(axis=0)  # planes are contiguous: averaging them is 5x faster than channels-last
    if a.ndim == 3 and a.shape[2] <= 4:  # channel mean as one OpenCV pass (numpy's is 50x slower)
        a = cv2.transform(np.ascontiguousarray(a), np.full((1, a.shape[2]), 1.0 / a.shape[2], dtype=np.float32))
    elif a.ndim == 3:
        a = a.mean(axis=2)
    return np.ascontiguousarray(a)


def local_zncc(a: np.ndarray, b: np.ndarray, window: int = 7) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel ZNCC of ``a`` and ``b`` (H, W) over ``window``² boxes, and the local std of ``a``."""
    ksize = (window, window)
    ma, mb = cv2.blur(a, ksize), cv2.blur(b, ksize)
    va = np.maximum(cv2.blur(a * a, ksize) - ma * ma, 0.0)
    vb = np.maximum(cv2.blur(b * b, ksize) - mb * mb, 0.0)
    cov = cv2.blur(a * b, ksize) - ma * mb
    return cov / np.sqrt(np.maximum(va * vb, 1e-12)), np.sqrt(va)


def infinity_mask(left: np.ndarray, right: np.ndarray, disparity: np.ndarray, *, min_disparity: float = 1.0,
                  window: int = 7, margin: float = 0.1, min_zncc: float = 0.6, min_std: float = 2.0) -> np.ndarray:
    """Boolean (H, W): pixels with ``disparity > min_disparity`` that match better at zero disparity.

    Args:
        left, right: rectified views of the same size ((H, W), (H, W, 3) or (1, 3, H, W); values on
            the 0-255 scale for ``min_std``).
        disparity: (H, W) disparity of ``left`` in the same pixels.
        window: ZNCC box side in pixels.
        margin: the zero-shift ZNCC must beat the predicted-shift ZNCC by this much...
        min_zncc: ...and be at least this (a real match, not two kinds of noise).
        min_std: least local intensity std of ``left`` (untextured pixels are never flagged).
    """
    gl, gr = _grey(left), _grey(right)
    h, w = gl.shape
    check_shape(gr, (h, w), "right")
    check_shape(disparity, (h, w), "disparity")
    d = np.nan_to_num(np.asarray(disparity, dtype=np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    cand = d > min_disparity
    if not cand.any():
        return cand
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    warped = cv2.remap(gr, xs - d, ys, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    z_pred, std = local_zncc(gl, warped, window)
    z_zero, _ = local_zncc(gl, gr, window)
    return cand & (std >= min_std) & (z_zero >= min_zncc) & (z_zero >= z_pred + margin)


def infinity_regions(left: np.ndarray, right: np.ndarray, disparity: np.ndarray, *, min_disparity: float = 1.0,
                     share: float = 0.5, **kwargs) -> np.ndarray:
    """Boolean (H, W): connected regions of ``disparity > min_disparity`` in which more than ``share``
    of the pixels are flagged by :func:`infinity_mask` (``kwargs`` go to it)."""
    flagged = infinity_mask(left, right, disparity, min_disparity=min_disparity, **kwargs)
    if not flagged.any():
        return flagged
    cand = np.nan_to_num(np.asarray(disparity, dtype=np.float32), nan=0.0, posinf=0.0, neginf=0.0) > min_disparity
    n, labels = cv2.connectedComponents(cand.astype(np.uint8), connectivity=8)
    total = np.bincount(labels.ravel(), minlength=n)
    hits = np.bincount(labels[flagged], minlength=n)
    drop = hits > share * np.maximum(total, 1)
    drop[0] = False  # label 0: not a candidate
    return drop[labels]
