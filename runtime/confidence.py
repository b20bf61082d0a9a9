"""A pose's confidence: the probability that it is within a tolerance, from its predicted uncertainty.

DESIGN.md asks that errors grow as confidence falls. The confidence each decision route computes (the
inlier share times a margin term, :meth:`spacepose.estimator.PoseEstimator._register`) says how sure the
flip decision is, not how accurate the pose is; on fresh frames it ranked the errors the wrong way round
(Spearman(e_t, confidence) +0.16, session 28). With the bundle's ``confidence`` section (session 30,
:class:`ConfidenceConfig`) the reported confidence of a valid pose is instead::

    p_pos = P(|x| <= position_m),   x ~ N(0, Sigma)            Sigma: the pose's position covariance
    p_rot = P(|w| <= rotation_deg), w ~ N(0, s_rot^2 I_3)      s_rot: its per-axis rotation sigma
    p     = clip(p_pos * p_rot, 1e-6, 1 - 1e-6)
    confidence = 1 / (1 + exp(-(bias + slope * logit(p))))

``Sigma`` and ``s_rot`` come from :mod:`spacepose.uncertainty`. Its errors have heavier tails than a
normal distribution with the same second moment, so the normal ``p`` is too low near zero error;
``bias`` and ``slope`` recalibrate it (logistic regression of "within the tolerance" on ``logit(p)``,
fitted on training frames by :func:`spacepose.tools.calibrate_uncertainty.fit_confidence`). The
shipped tolerance is the pose bar of the project's issue 6: 0.10 m and 2 degrees.

``Sigma`` has the shape :func:`spacepose.uncertainty.pose_uncertainty` gives it: one sigma along the
line of sight and one, the same, on both axes across it. ``p_pos`` integrates the range axis by
Gauss-Legendre quadrature; the two cross-range axes in closed form (a 2-D normal's radius).

The section's optional ``min_valid`` is a floor: the estimator reports a pose under it as ``weak_votes`` (the
default bundle's 0.08 since session 34; the model card, "A floor on the confidence").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from functools import lru_cache
from typing import Any

import numpy as np

from .uncertainty import parse_number_section

__all__ = ["ConfidenceConfig", "within_probability", "position_within_probability", "rotation_within_probability",
           "calibrated_confidence", "parse_confidence", "P_CLIP"]

#: ``p`` is clipped to ``[P_CLIP, 1 - P_CLIP]`` before its logit
P_CLIP = 1e-6
_NODES = 64
_RANGE_SPAN = 8.0   # the range axis is integrated over +-8 sigma (or the tolerance, if less)


@dataclass(frozen=True)
class ConfidenceConfig:
    """The ``confidence`` section of ``bundle.json`` (module docstring for the model).

    position_m: radius of the position tolerance (m, > 0); the event is the position error within it.
    rotation_deg: the rotation tolerance (degrees, > 0).
    bias, slope: the logistic recalibration of the normal model's probability (``slope`` > 0, so that the
        confidence grows with that probability).
    min_valid: the floor, in [0, 1): a pose whose confidence is under it is reported invalid (``weak_votes``,
        :class:`spacepose.estimator.PoseResult`). Optional in ``bundle.json``; 0, the default, reports every pose
        the decision routes pass.
    """

    position_m: float
    rotation_deg: float
    bias: float
    slope: float
    min_valid: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"confidence.{f.name} must be a finite number, got {value!r}")
        for name in ("position_m", "rotation_deg", "slope"):
            if getattr(self, name) <= 0.0:
                raise ValueError(f"confidence.{name} must be > 0, got {getattr(self, name)!r}")
        if not 0.0 <= self.min_valid < 1.0:
            raise ValueError(f"confidence.min_valid must be in [0, 1), got {self.min_valid!r}")


@lru_cache(maxsize=1)
def _gauss_legendre() -> tuple[np.ndarray, np.ndarray]:
    return np.polynomial.legendre.leggauss(_NODES)


def position_within_probability(sigma_range_m: float, sigma_lateral_m: float, radius_m: float) -> float:
    """``P(|x| <= radius_m)`` for ``x`` normal with mean 0, standard deviation ``sigma_range_m`` on one axis
    and ``sigma_lateral_m`` on each of the two others (all > 0, finite)."""
    sr, sl, r = float(sigma_range_m), float(sigma_lateral_m), float(radius_m)
    if not (sr > 0.0 and sl > 0.0 and r > 0.0 and math.isfinite(sr) and math.isfinite(sl) and math.isfinite(r)):
        raise ValueError(f"sigmas and radius must be finite and > 0, got {sr!r}, {sl!r}, {r!r}")
    nodes, weights = _gauss_legendre()
    half = min(r, _RANGE_SPAN * sr)                 # the integrand is even in a: integrate 0..half, twice
    a = 0.5 * half * (nodes + 1.0)
    w = 0.5 * half * weights
    density = np.exp(-0.5 * (a / sr) ** 2) / (sr * math.sqrt(2.0 * math.pi))
    lateral = -np.expm1(-(r * r - a * a) / (2.0 * sl * sl))   # P(cross-range radius^2 <= r^2 - a^2)
    return float(min(max(2.0 * np.sum(w * density * lateral), 0.0), 1.0))


def rotation_within_probability(sigma_deg: float, tolerance_deg: float) -> float:
    """``P(|w| <= tolerance_deg)`` for ``w`` a 3-vector of independent normals with standard deviation
    ``sigma_deg`` (the chi distribution with 3 degrees of freedom)."""
    s, tol = float(sigma_deg), float(tolerance_deg)
    if not (s > 0.0 and tol > 0.0 and math.isfinite(s) and math.isfinite(tol)):
        raise ValueError(f"sigma and tolerance must be finite and > 0, got {s!r}, {tol!r}")
    x = tol / s
    return float(min(max(math.erf(x / math.sqrt(2.0)) - math.sqrt(2.0 / math.pi) * x * math.exp(-0.5 * x * x),
                         0.0), 1.0))


def within_probability(sigma_range_m: float, sigma_lateral_m: float, sigma_rotation_deg: float,
                       config: ConfidenceConfig) -> float:
    """The normal model's ``p = p_pos * p_rot`` (module docstring), not yet recalibrated."""
    return (position_within_probability(sigma_range_m, sigma_lateral_m, config.position_m)
            * rotation_within_probability(sigma_rotation_deg, config.rotation_deg))


def calibrated_confidence(p: float, config: ConfidenceConfig) -> float:
    """``sigmoid(bias + slope * logit(clip(p)))``: the reported confidence for the normal model's ``p``."""
    if not math.isfinite(p):
        raise ValueError(f"p must be finite, got {p!r}")
    q = min(max(float(p), P_CLIP), 1.0 - P_CLIP)
    s = config.bias + config.slope * math.log(q / (1.0 - q))
    return 1.0 / (1.0 + math.exp(-s)) if s >= 0.0 else math.exp(s) / (1.0 + math.exp(s))


def parse_confidence(section: Any) -> ConfidenceConfig | None:
    """The bundle's ``confidence`` section (``None`` when absent); ``BundleError`` when malformed."""
    return parse_number_section(section, "confidence", ConfidenceConfig, optional=("min_valid",))
