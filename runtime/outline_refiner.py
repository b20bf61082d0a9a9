"""The outline refiner at run time: the stereo outline sharpened against the left image (session 41).

The stereo outline (:func:`spacepose.silhouette.observed_mask`) covers about 1.2x the target's true area: it fills
the gaps between the dishes, the body and the boom. Against the rendered mask instead, the polish's rotation error
halves (the model card, session 40). The bundle's optional ``outline_refiner`` graph
(:class:`OutlineRefinerConfig`, trained by ``spacepose train-outline``, :mod:`spacepose.models.outline_refiner`)
sees three planes over the silhouette frame (:func:`refiner_planes`) and returns a logit per pixel that the target
covers it. The refined outline (:func:`refined_outline`) is the logit > 0 within ``grow_px`` pixels of the stereo
outline: it may cut the stereo outline's gaps and add a thin rim, nothing far from it.

The estimator polishes a decided pose (the silhouette section's ``polish``) against the stereo outline as before,
then again against the refined one, and keeps the second polish's rotation (with ``keep_centre``, the target's
centre where the first put it). Everything before the polish (the outline decision, its gates) still reads the
stereo outline.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import cv2
import numpy as np

from .errors import BundleError, check_shape

logger = logging.getLogger(__name__)

__all__ = ["OutlineRefinerConfig", "OutlineRefiner", "parse_outline_refiner", "refiner_planes", "refined_outline",
           "PLANES", "MULTIPLE"]

#: planes of the graph's input; its height and width must be multiples of MULTIPLE
PLANES, MULTIPLE = 3, 4
#: the clip of the grey plane (relative to the 90th percentile inside the outline) and of the disparity plane
GREY_MAX, DISPARITY_MAX = 2.0, 3.0


@dataclass(frozen=True)
class OutlineRefinerConfig:
    """The ``outline_refiner`` section of ``bundle.json``. file: the graph, in the bundle folder. grow_px: how far
    (silhouette-frame pixels) the refined outline may reach beyond the stereo outline. keep_centre: 1 keeps the
    target's centre where the polish against the stereo outline put it and takes only the rotation from the
    polish against the refined one; 0 takes both from the latter. On spent frames (session 41) the refined
    outline's own range came out 0.10 m too far, while the stereo polish's weighs the stereo points' range (too
    far) against the stereo outline's (too near) and is right on average."""

    file: str = "outline.onnx"
    grow_px: int = 2
    keep_centre: int = 1

    def __post_init__(self) -> None:
        if not 0 <= self.grow_px <= 8:
            raise ValueError(f"outline_refiner.grow_px must be in [0, 8], got {self.grow_px}")
        if self.keep_centre not in (0, 1):
            raise ValueError(f"outline_refiner.keep_centre must be 0 or 1, got {self.keep_centre}")


def parse_outline_refiner(section: Any) -> OutlineRefinerConfig | None:
    """The bundle's ``outline_refiner`` section (``None`` when absent); BundleError when malformed."""
    if section is None:
        return None
    if not isinstance(section, Mapping):
        raise BundleError(f"bundle.json: outline_refiner must be an object, got {type(section).__name__}")
    unknown = sorted(set(section) - {"file", "grow_px", "keep_centre"})
    if unknown:
        raise BundleError(f"bundle.json: outline_refiner has unknown keys {unknown}")
    file = section.get("file", OutlineRefinerConfig.file)
    if not isinstance(file, str) or not file:
        raise BundleError("bundle.json: outline_refiner.file must be a non-empty string")
    values = {}
    for key in ("grow_px", "keep_centre"):
        value = section.get(key, getattr(OutlineRefinerConfig, key))
        if isinstance(value, bool) or not isinstance(value, int):
            raise BundleError(f"bundle.json: outline_refiner.{key} must be an integer, got {value!r}")
        values[key] = value
    try:
        return OutlineRefinerConfig(file=file, **values)
    except ValueError as err:
        raise BundleError(f"bundle.json: {err}") from err


def refiner_planes(grey: np.ndarray, observed: np.ndarray, disparity_ratio: np.ndarray) -> np.ndarray:
    """(3, n, n) float32 input of the refiner from the silhouette frame's (n, n) planes: ``grey`` (the left image,
    :func:`spacepose.image_vote.window_grey`) over its 90th percentile inside the ``observed`` stereo outline
    (nonzero inside; over its 99th percentile when the outline is empty), clipped to [0, 2]; the outline (0 / 1);
    and ``disparity_ratio`` (the disparity over the outline's threshold: the outline is ``> 1``), clipped to
    [0, 3] (NaN to 0)."""
    n = grey.shape[0] if isinstance(grey, np.ndarray) and grey.ndim == 2 else -1
    check_shape(grey, (n, n), "grey")
    check_shape(observed, (n, n), "observed")
    check_shape(disparity_ratio, (n, n), "disparity_ratio")
    inside = np.asarray(observed) > 0
    g = np.asarray(grey, dtype=np.float32)
    ref = float(np.percentile(g[inside], 90)) if inside.any() else float(np.percentile(g, 99))
    g = np.clip(g / max(ref, 1e-3), 0.0, GREY_MAX)
    d = np.clip(np.nan_to_num(np.asarray(disparity_ratio, dtype=np.float32), nan=0.0), 0.0, DISPARITY_MAX)
    return np.stack([g, inside.astype(np.float32), d])


def refined_outline(logit: np.ndarray, observed: np.ndarray, grow_px: int) -> np.ndarray:
    """(n, n) uint8: ``logit`` > 0 within ``grow_px`` pixels (3x3 dilations) of the ``observed`` (n, n) outline."""
    check_shape(observed, (None, None), "observed")
    check_shape(logit, np.shape(observed), "logit")
    near = np.asarray(observed) > 0
    if grow_px > 0:
        near = cv2.dilate(near.astype(np.uint8), np.ones((3, 3), np.uint8), iterations=grow_px) > 0
    return ((np.asarray(logit) > 0) & near).astype(np.uint8)


class OutlineRefiner:
    """The graph of a bundle's ``outline_refiner`` section.

    Args:
        folder: the bundle folder. config: its ``outline_refiner`` section. target: the bundle's target name (the
        graph's metadata must name it). threads: onnxruntime intra-op threads.

    Raises:
        BundleError: the graph is missing, unloadable, or its metadata disagrees with the section.
    """

    def __init__(self, folder: str | os.PathLike, config: OutlineRefinerConfig, target: str, threads: int = 1) -> None:
        from .onnx_session import checked_session

        self.config = config
        expect = {"kind": "outline", "planes": PLANES, "multiple": MULTIPLE, "target": target}
        self.session, self.metadata = checked_session(Path(folder) / config.file, expect, "outline", threads=threads)

    def logits(self, planes: np.ndarray) -> np.ndarray:
        """(n, n) float32 logits of the (3, n, n) ``planes`` (:func:`refiner_planes`; zero-padded to a multiple of
        4 for the graph, the padding cut off again)."""
        check_shape(planes, (PLANES, None, None), "planes")
        n, m = planes.shape[1], planes.shape[2]
        if n != m or n < 1:
            raise ValueError(f"refiner planes must be square, got {planes.shape}")
        side = -(-n // MULTIPLE) * MULTIPLE
        feed = np.zeros((1, PLANES, side, side), np.float32)
        feed[0, :, :n, :n] = planes
        return self.session.run(["logit"], {"planes": feed})[0][0, 0, :n, :n]

    def refine(self, grey: np.ndarray, observed: np.ndarray, disparity_ratio: np.ndarray) -> np.ndarray:
        """(n, n) uint8 refined outline of the silhouette frame's ``grey``, ``observed`` and ``disparity_ratio``
        (:func:`refiner_planes`, :func:`refined_outline`)."""
        return refined_outline(self.logits(refiner_planes(grey, observed, disparity_ratio)), observed,
                               self.config.grow_px)
