"""The flip classifier at run time: which of the outline stage's winner and its 180° flip the left image shows.

An optional graph of the bundle (``flip_classifier`` section, :class:`FlipClassifierConfig`), trained by
``spacepose train-flip`` (:mod:`spacepose.models.flip_net`). It sees one view
(:func:`spacepose.flip_views.flip_views`): the left image over the stereo window and the outlines of the
two poses, and returns the probability that the first is the right one. The estimator
(:meth:`spacepose.estimator.PoseEstimator._register`) uses it two ways:

* to **veto**: a pose the outline or the stereo points decided, which the classifier gives at most
  ``veto_prob``, is reported ``weak_votes``;
* to **decide**: a frame the outline leaves undecided, whose winner fits the outline within
  ``max_chamfer_px`` and whose stereo depth tolerance is at most ``max_depth_tolerance_m``, is decided for
  the pose the classifier gives at least ``decide_prob``.

Both thresholds are chosen on training frames (``bundle.json``), never by the exporter.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .errors import BundleError
from .flip_views import CHANNELS, flip_views, toned_views

logger = logging.getLogger(__name__)

__all__ = ["FlipClassifierConfig", "FlipClassifier", "parse_flip_classifier"]


@dataclass(frozen=True)
class FlipClassifierConfig:
    """The ``flip_classifier`` section of ``bundle.json``.

    file: the graph, in the bundle folder. size: side of a view (pixels). axis: body axis of the flip.
    decide_prob: least probability with which the classifier decides a frame the outline leaves open
        (> 1 never decides). veto_prob: a decided pose it gives at most this is refused (< 0 never
        vetoes). max_chamfer_px: the outline fit (outline px) a pose it decides must reach.
    min_margin_px: the least outline margin of a frame it decides (0: any).
    max_polish_deg: a pose it decides is refused when the silhouette stage's polish turns it by more
        than this (degrees), or when the polish does not run or is not used (the previous pose may then
        decide the frame, as without the classifier); 0: no such check. On the
        calibration frames of session 18, the classifier-decided poses that were wrong were ones the
        polish moved far (the model card, "The flip classifier").
    max_depth_tolerance_m: a frame it decides must have a registration depth tolerance (``tau``, metres:
        :class:`spacepose.registration.RegistrationResult`) of at most this; 0: no such check. Far frames
        have coarse stereo depth: on session 21's check sets the poses it added that were wrong were there.
    loose_fit_min_prob: a pose the silhouette stage decides with an outline chamfer above the silhouette's
        ``max_chamfer_px`` (the image route's looser fit) is refused unless the classifier gives it at
        least this; 0: no such check. Both image-route poses > 90° off on fresh frames of sessions 22-23
        had such fits and p 0.95-0.98 (``reports/flip_s23/gate_rule.txt``).
    registration_min_prob: a pose the stereo points decide (the registration route) is refused unless the
        classifier gives it at least this, or when it gives none (no outline frame to look at); 0: no such
        check. A pose 172° off on a fresh frame of session 27 was so decided with p 0.59
        (``reports/flip_s27/gate_rule.txt``).
    decide_tone_gamma: a frame the classifier decides must be decided, at ``decide_prob``, with the view's
        grey plane raised to the powers ``g`` and ``1 / g`` as well (other renderers' tone curves; ``g`` 2 is
        the end of the classifier's training augmentation, :func:`spacepose.tools.flip_data.augment_views`);
        1: no such check. On a restyled frame of session 37 the classifier decided a pose 178.9° off at p
        0.9998 that it gives 0.991 with its grey plane's tone curve raised to 1/2 (session 38). The shipped
        bundle sets 2 since session 39 (``reports/tone_s39/rule.txt``).
    """

    file: str = "flip.onnx"
    size: int = 128
    axis: str = "z"
    decide_prob: float = 2.0
    veto_prob: float = -1.0
    max_chamfer_px: float = 2.0
    min_margin_px: float = 0.0
    max_polish_deg: float = 0.0
    max_depth_tolerance_m: float = 0.0
    loose_fit_min_prob: float = 0.0
    registration_min_prob: float = 0.0
    decide_tone_gamma: float = 1.0

    def __post_init__(self) -> None:
        if self.size < 16:
            raise ValueError(f"flip_classifier.size must be >= 16, got {self.size}")
        if self.axis not in ("x", "y", "z"):
            raise ValueError(f"flip_classifier.axis must be x, y or z, got {self.axis!r}")
        if self.decide_prob <= 0.5 or self.veto_prob >= 0.5:
            raise ValueError(f"flip_classifier: decide_prob must be > 0.5 and veto_prob < 0.5, "
                             f"got {self.decide_prob}, {self.veto_prob}")
        if min(self.max_chamfer_px, self.min_margin_px, self.max_polish_deg, self.max_depth_tolerance_m) < 0:
            raise ValueError("flip_classifier: max_chamfer_px, min_margin_px, max_polish_deg and "
                             "max_depth_tolerance_m must be >= 0")
        for key in ("loose_fit_min_prob", "registration_min_prob"):
            if not 0.0 <= getattr(self, key) <= 1.0:
                raise ValueError(f"flip_classifier.{key} must be in [0, 1], got {getattr(self, key)}")
        if not 1.0 <= self.decide_tone_gamma <= 4.0:
            raise ValueError(f"flip_classifier.decide_tone_gamma must be in [1, 4], got {self.decide_tone_gamma}")


def parse_flip_classifier(section: Any) -> FlipClassifierConfig | None:
    """The bundle's ``flip_classifier`` section (``None`` when absent); BundleError when malformed."""
    if section is None:
        return None
    if not isinstance(section, Mapping):
        raise BundleError(f"bundle.json: flip_classifier must be an object, got {type(section).__name__}")
    fields = FlipClassifierConfig.__dataclass_fields__
    unknown = sorted(set(section) - set(fields))
    if unknown:
        raise BundleError(f"bundle.json: flip_classifier has unknown keys {unknown}")
    values = {}
    for key, value in section.items():
        kind = type(getattr(FlipClassifierConfig(), key))
        if kind is str:
            if not isinstance(value, str):
                raise BundleError(f"bundle.json: flip_classifier.{key} must be a string")
        elif isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
            raise BundleError(f"bundle.json: flip_classifier.{key} must be a finite number, got {value!r}")
        elif kind is int and int(value) != value:
            raise BundleError(f"bundle.json: flip_classifier.{key} must be an integer, got {value!r}")
        values[key] = kind(value)
    try:
        return FlipClassifierConfig(**values)
    except ValueError as err:
        raise BundleError(f"bundle.json: {err}") from err


class FlipClassifier:
    """The graph of a bundle's ``flip_classifier`` section, and its decision thresholds.

    Args:
        folder: the bundle folder. config: its ``flip_classifier`` section. target: the bundle's target
        name (the graph's metadata must name it). threads: onnxruntime intra-op threads.

    Raises:
        BundleError: the graph is missing, unloadable, or its metadata disagrees with the section.
    """

    def __init__(self, folder: str | os.PathLike, config: FlipClassifierConfig, target: str, threads: int = 1) -> None:
        from .onnx_session import checked_session

        self.config = config
        expect = {"kind": "flip", "size": config.size, "axis": config.axis, "channels": CHANNELS, "target": target}
        self.session, self.metadata = checked_session(Path(folder) / config.file, expect, "flip", threads=threads)

    def views(self, image: np.ndarray, K_full: np.ndarray, window: tuple[int, int, int],
              silhouette_points: np.ndarray, pose_a: tuple[np.ndarray, np.ndarray],
              pose_b: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
        """(1, 3, S, S) input of ``pose_a`` against ``pose_b`` seen in ``image`` (H, W[, C], rectified left)
        over the full-frame ``window`` ``(x0, y0, side)`` (:func:`spacepose.flip_views.flip_views`)."""
        return flip_views(image, K_full, window, silhouette_points, pose_a, pose_b, self.config.size)[None]

    def _probabilities(self, views: np.ndarray) -> np.ndarray:
        """(N,) float64 probabilities that the first pose of each of the (N, 3, S, S) ``views`` is the right one."""
        logit = self.session.run(["logit"], {"views": views})[0].reshape(-1).astype(np.float64)
        return 1.0 / (1.0 + np.exp(-np.clip(logit, -60.0, 60.0)))

    def probability(self, views: np.ndarray) -> float:
        """Probability that the first pose of :meth:`views` is the right one (runs the graph)."""
        return float(self._probabilities(views)[0])

    def toned_probabilities(self, views: np.ndarray, gamma: float) -> np.ndarray:
        """(2,) probabilities that the first pose of ``views`` (1, 3, S, S; :meth:`views`) is the right one with
        the grey plane raised to the powers ``gamma`` and ``1 / gamma`` (:func:`spacepose.flip_views.toned_views`;
        one run of the graph on both)."""
        if views.ndim != 4 or views.shape[0] != 1 or views.shape[1] != CHANNELS:
            raise ValueError(f"toned_probabilities takes (1, {CHANNELS}, S, S) views, got {views.shape}")
        if not (np.isfinite(gamma) and gamma > 0.0):
            raise ValueError(f"toned_probabilities: gamma must be finite and > 0, got {gamma}")
        return self._probabilities(np.concatenate([toned_views(views, gamma), toned_views(views, 1.0 / gamma)]))
