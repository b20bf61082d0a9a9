"""Image degradations of paper Fig. 10: speckle noise, Gaussian blur, motion blur.

Every frame gets one or more of the three (each drawn with probability 1/2; if none was drawn,
one is picked uniformly). The blurs are the same for both views of a frame (the rig moves as one
body and both lenses are alike); the speckle noise fields are independent per view. Blur sizes
are drawn in pixels at 640 px width and scaled with the image width, so the look does not depend
on the resolution. The parameters are recorded in the labels exactly as applied.

Order: optics and motion blur the image first, then the sensor adds noise; all in display space
(values in [0, 1]), quantised to uint8 by :func:`to_uint8`.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from spacepose.errors import check_shape

__all__ = ["DEGRADATIONS", "sample_degradations", "apply_degradations", "motion_kernel", "to_uint8"]

DEGRADATIONS = ("speckle", "gaussian_blur", "motion_blur")


def sample_degradations(rng: np.random.Generator, width: int) -> dict:
    """Draw a non-empty set of degradations and their parameters for an image ``width`` px wide."""
    chosen = [name for name in DEGRADATIONS if rng.random() < 0.5]
    if not chosen:
        chosen = [DEGRADATIONS[int(rng.integers(0, len(DEGRADATIONS)))]]
    scale = width / 640.0
    params: dict = {}
    if "speckle" in chosen:
        params["speckle"] = {"sigma": round(float(rng.uniform(0.03, 0.2)), 4), "read_sigma": round(float(rng.uniform(0.0, 0.012)), 4)}
    if "gaussian_blur" in chosen:
        params["gaussian_blur"] = {"sigma_px": round(float(rng.uniform(0.4, 1.6) * scale), 3)}
    if "motion_blur" in chosen:
        params["motion_blur"] = {
            "length_px": round(float(rng.uniform(3.0, 13.0) * scale), 2),
            "angle_deg": round(float(rng.uniform(0.0, 180.0)), 2),
        }
    return params


def motion_kernel(length_px: float, angle_deg: float) -> np.ndarray:
    """Normalised linear motion-blur kernel (odd square, anti-aliased line of ``length_px``)."""
    if not (math.isfinite(length_px) and length_px > 0):
        raise ValueError(f"motion blur length must be > 0, got {length_px}")
    size = int(math.ceil(length_px)) | 1
    size = max(size, 3)
    c = (size - 1) / 2.0
    # supersample the segment for a smooth, sub-pixel accurate kernel
    steps = max(16, int(length_px * 8))
    s = np.linspace(-length_px / 2, length_px / 2, steps)
    a = math.radians(angle_deg)
    xs, ys = c + s * math.cos(a), c - s * math.sin(a)
    kernel = np.zeros((size, size), dtype=np.float64)
    x0, y0 = np.floor(xs).astype(int), np.floor(ys).astype(int)
    fx, fy = xs - x0, ys - y0
    for dx, dy, wgt in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)), (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
        xi, yi = np.clip(x0 + dx, 0, size - 1), np.clip(y0 + dy, 0, size - 1)
        np.add.at(kernel, (yi, xi), wgt)
    return (kernel / kernel.sum()).astype(np.float32)


def apply_degradations(image: np.ndarray, params: dict, rng: np.random.Generator) -> np.ndarray:
    """Apply ``params`` (from :func:`sample_degradations`) to a float image in [0, 1].

    Args:
        image: (H, W, 3) or (H, W) float32 display values.
        params: degradation parameters; missing keys are not applied.
        rng: generator for the noise field (use a different stream per view).

    Returns:
        float32 image of the same shape, clipped to [0, 1].
    """
    if not isinstance(image, np.ndarray) or image.ndim not in (2, 3):
        check_shape(image, (None, None, 3), "image")
    out = np.ascontiguousarray(image, dtype=np.float32)
    if "gaussian_blur" in params:
        sigma = float(params["gaussian_blur"]["sigma_px"])
        out = cv2.GaussianBlur(out, (0, 0), sigmaX=sigma, sigmaY=sigma, borderType=cv2.BORDER_REFLECT)
    if "motion_blur" in params:
        mb = params["motion_blur"]
        out = cv2.filter2D(out, -1, motion_kernel(float(mb["length_px"]), float(mb["angle_deg"])), borderType=cv2.BORDER_REFLECT)
    if "speckle" in params:
        sp = params["speckle"]
        shape = out.shape[:2]
        # speckle is a per-pixel gain (shared by the colour channels, like a sensor's PRNU/shot mix)
        gain = 1.0 + float(sp["sigma"]) * rng.standard_normal(shape, dtype=np.float32)
        read = float(sp.get("read_sigma", 0.0)) * rng.standard_normal(shape, dtype=np.float32)
        if out.ndim == 3:
            gain, read = gain[:, :, None], read[:, :, None]
        out = out * gain + read
    return np.clip(out, 0.0, 1.0)


def to_uint8(image: np.ndarray) -> np.ndarray:
    """Quantise [0, 1] float values to uint8 (round half up)."""
    return np.clip(np.asarray(image, dtype=np.float32) * 255.0 + 0.5, 0, 255).astype(np.uint8)
