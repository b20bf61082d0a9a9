"""How far off a reported pose is likely to be: a per-frame position covariance and rotation sigma.

A navigation filter weighs each measurement by its covariance. The pose's error grows with the
distance and has a known shape (session 28, ``reports/uncertainty_s28``): most of the position error
lies along the line of sight, where the stereo depth is coarse, and grows with the registration's
depth tolerance ``tau = z^2 sigma_d / (f B)`` (:class:`spacepose.registration.RegistrationResult`);
across it the error is a fraction of a pixel at the target's range; the rotation error grows with
``z / f``, the metres a pixel spans there. The model (the ``uncertainty`` section of ``bundle.json``,
:class:`UncertaintyConfig`)::

    sigma_range   = range_k * tau
    sigma_lateral = sqrt(lateral_floor_m^2 + (lateral_px * z / f)^2)      each axis across the line of sight
    sigma_rot     = sqrt(rotation_floor_deg^2 + (rotation_k_deg * z / f)^2
                         + (rotation_chamfer_deg * chamfer_px)^2)           each axis of the rotation error

with ``z`` the distance to the target's centre, ``f`` the rectified focal length (pixels) and ``chamfer_px``
the outline stage's fit (:attr:`spacepose.estimator.PoseResult.outline_chamfer_px`, in pixels of a view of
fixed size, so scale-free): a pose whose outline fits loosely is turned further off (on the fit frames of
session 28, e_R ranked with the chamfer at 0.49 and with the distance at 0.17). The
position covariance, in the camera frame (m^2), is ``sigma_range^2 u u^T + sigma_lateral^2 (I - u u^T)``
with ``u`` the unit line of sight. Every term scales with the rig (``tau``, ``f``), so a rig the
constants were not fitted on gets sigmas in proportion.

A frame that has the target's position but no pose (``PoseResult.position_valid`` without ``valid``:
the flip undecided) gets a covariance of the same shape from its own constants (the ``position_uncertainty``
section, :class:`PositionUncertaintyConfig`, session 29). Its position comes from a loosely fitting
outline or from the registered pose moved onto it, so the outline's chamfer (at most the bundle's
``registration.position_max_chamfer_px``) widens both axes::

    sigma_range   = tau * sqrt(range_k^2 + (range_chamfer_k * chamfer_px)^2)
    sigma_lateral = sqrt(lateral_floor_m^2 + (lateral_px * z / f)^2 + (lateral_chamfer_m * chamfer_px)^2)

(on session 27's fit frames, the position-only frames' cross-range miss ranked with the chamfer at 0.58 and
not with the distance). Such a frame gets no covariance when its chamfer is not finite, or when a sigma would be
0 (the shipped constants have no cross-range term but the chamfer's).

The constants are fitted by :mod:`spacepose.tools.calibrate_uncertainty` on training frames, never
by hand. The errors have heavier tails than a normal distribution: read the measured coverage in the
model card before trusting a 3-sigma bound. ``tail_dof`` (optional) describes those tails as a
Student-t law, and :func:`spacepose.tails.nees_gate` turns it into gates for a filter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, Mapping

import numpy as np

from .errors import BundleError, check_shape

__all__ = ["UncertaintyConfig", "PositionUncertaintyConfig", "PoseUncertainty", "pose_uncertainty",
           "position_uncertainty", "parse_uncertainty", "parse_position_uncertainty"]


@dataclass(frozen=True)
class UncertaintyConfig:
    """The ``uncertainty`` section of ``bundle.json`` (module docstring for the model).

    range_k: sigma of the range error per metre of depth tolerance (> 0).
    lateral_px, lateral_floor_m: the cross-range sigma, in pixels at the target's range and a floor (m).
    rotation_k_deg, rotation_floor_deg: the per-axis rotation sigma, degrees per unit ``z / f`` and a
        floor (degrees).
    rotation_chamfer_deg: degrees of rotation sigma per pixel of the outline fit's chamfer (0: no such
        term; otherwise no rotation sigma is given without a finite chamfer).
    tail_dof: the degrees of freedom of the Student-t law the errors follow, given these sigmas (> 2), or 0
        (the default, and every bundle without the key): normal. It sets the NEES gates
        (:func:`spacepose.tails.nees_gate`), not the sigmas.
    """

    range_k: float
    lateral_px: float
    lateral_floor_m: float
    rotation_k_deg: float
    rotation_floor_deg: float
    rotation_chamfer_deg: float = 0.0
    tail_dof: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not math.isfinite(value) or value < 0.0:
                raise ValueError(f"uncertainty.{f.name} must be finite and >= 0, got {value!r}")
        if self.range_k <= 0.0:
            raise ValueError(f"uncertainty.range_k must be > 0, got {self.range_k!r}")
        if self.lateral_px == 0.0 and self.lateral_floor_m == 0.0:
            raise ValueError("uncertainty: lateral_px and lateral_floor_m cannot both be 0 (a singular covariance)")
        if self.rotation_k_deg == 0.0 and self.rotation_floor_deg == 0.0 and self.rotation_chamfer_deg == 0.0:
            raise ValueError("uncertainty: rotation_k_deg, rotation_floor_deg and rotation_chamfer_deg cannot all be 0")
        if not (self.tail_dof == 0.0 or self.tail_dof > 2.0):
            raise ValueError(f"uncertainty.tail_dof must be 0 (normal) or > 2, got {self.tail_dof!r}")


@dataclass(frozen=True)
class PositionUncertaintyConfig:
    """The ``position_uncertainty`` section of ``bundle.json``: the covariance of a position reported without a
    pose (module docstring for the model).

    range_k, range_chamfer_k: the range sigma per metre of depth tolerance, and per metre of tolerance and
        outline pixel of chamfer (added in quadrature).
    lateral_px, lateral_floor_m, lateral_chamfer_m: the cross-range sigma: pixels at the target's range, a floor
        (m) and metres per outline pixel of chamfer (added in quadrature).
    """

    range_k: float
    range_chamfer_k: float
    lateral_px: float
    lateral_floor_m: float
    lateral_chamfer_m: float

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not math.isfinite(value) or value < 0.0:
                raise ValueError(f"position_uncertainty.{f.name} must be finite and >= 0, got {value!r}")
        if self.range_k == 0.0 and self.range_chamfer_k == 0.0:
            raise ValueError("position_uncertainty: range_k and range_chamfer_k cannot both be 0")
        if self.lateral_px == 0.0 and self.lateral_floor_m == 0.0 and self.lateral_chamfer_m == 0.0:
            raise ValueError("position_uncertainty: lateral_px, lateral_floor_m and lateral_chamfer_m cannot all be 0 "
                             "(a singular covariance)")


@dataclass(frozen=True)
class PoseUncertainty:
    """``position_cov`` (3, 3): covariance of the position (m^2, camera frame); ``sigma_range_m``,
    ``sigma_lateral_m``: its standard deviations along and across the line of sight;
    ``sigma_rotation_deg``: per-axis standard deviation of the rotation error (degrees; NaN when the model
    needs the outline's chamfer and it is not finite)."""

    position_cov: np.ndarray
    sigma_range_m: float
    sigma_lateral_m: float
    sigma_rotation_deg: float


def pose_uncertainty(position: np.ndarray, tau_m: float, focal_px: float, config: UncertaintyConfig,
                     chamfer_px: float = float("nan")) -> PoseUncertainty | None:
    """The uncertainty of a pose whose target centre is at ``position`` (3,) in the camera frame,
    registered with depth tolerance ``tau_m`` (metres), seen with focal length ``focal_px``, whose outline
    fit has chamfer ``chamfer_px`` (outline px; NaN: none).

    ``None`` when an input is not finite or not positive (no uncertainty can be given).
    """
    check_shape(position, (3,), "position")
    p = np.asarray(position, dtype=np.float64)
    z = float(np.linalg.norm(p))
    if not (np.all(np.isfinite(p)) and z > 0.0 and math.isfinite(tau_m) and tau_m > 0.0
            and math.isfinite(focal_px) and focal_px > 0.0):
        return None
    u = p / z
    ratio = z / float(focal_px)
    s_range = config.range_k * float(tau_m)
    s_lat = math.hypot(config.lateral_floor_m, config.lateral_px * ratio)
    if config.rotation_chamfer_deg > 0.0 and not math.isfinite(chamfer_px):
        s_rot = float("nan")
    else:
        chamfer_term = config.rotation_chamfer_deg * float(chamfer_px) if config.rotation_chamfer_deg > 0.0 else 0.0
        s_rot = math.sqrt(config.rotation_floor_deg ** 2 + (config.rotation_k_deg * ratio) ** 2 + chamfer_term ** 2)
    return PoseUncertainty(position_cov=_line_of_sight_cov(u, s_range, s_lat), sigma_range_m=s_range,
                           sigma_lateral_m=s_lat, sigma_rotation_deg=s_rot)


def position_uncertainty(position: np.ndarray, tau_m: float, focal_px: float, config: PositionUncertaintyConfig,
                         chamfer_px: float) -> PoseUncertainty | None:
    """The uncertainty of a position reported without a pose: the target centre at ``position`` (3,) in the
    camera frame, registered with depth tolerance ``tau_m`` (m), focal length ``focal_px``, the outline's best
    fit within ``chamfer_px`` (outline px). ``sigma_rotation_deg`` is NaN (there is no attitude).

    ``None`` when an input is not finite or (but the chamfer, which may be 0) not positive, or when a sigma
    would be 0 (a singular covariance: the constants leave out a term and the chamfer is 0).
    """
    check_shape(position, (3,), "position")
    p = np.asarray(position, dtype=np.float64)
    z = float(np.linalg.norm(p))
    if not (np.all(np.isfinite(p)) and z > 0.0 and math.isfinite(tau_m) and tau_m > 0.0
            and math.isfinite(focal_px) and focal_px > 0.0 and math.isfinite(chamfer_px) and chamfer_px >= 0.0):
        return None
    chamfer = float(chamfer_px)
    s_range = float(tau_m) * math.hypot(config.range_k, config.range_chamfer_k * chamfer)
    s_lat = math.sqrt(config.lateral_floor_m ** 2 + (config.lateral_px * z / float(focal_px)) ** 2
                      + (config.lateral_chamfer_m * chamfer) ** 2)
    if s_range <= 0.0 or s_lat <= 0.0:
        return None
    return PoseUncertainty(position_cov=_line_of_sight_cov(p / z, s_range, s_lat), sigma_range_m=s_range,
                           sigma_lateral_m=s_lat, sigma_rotation_deg=float("nan"))


def _line_of_sight_cov(u: np.ndarray, sigma_range: float, sigma_lateral: float) -> np.ndarray:
    """(3, 3) ``sigma_range^2 u u^T + sigma_lateral^2 (I - u u^T)`` for the unit line of sight ``u`` (3,)."""
    along = np.outer(u, u)
    return sigma_range ** 2 * along + sigma_lateral ** 2 * (np.eye(3) - along)


def parse_uncertainty(section: Any) -> UncertaintyConfig | None:
    """The bundle's ``uncertainty`` section (``None`` when absent); BundleError when malformed."""
    return parse_number_section(section, "uncertainty", UncertaintyConfig,
                                optional=("rotation_chamfer_deg", "tail_dof"))


def parse_position_uncertainty(section: Any) -> PositionUncertaintyConfig | None:
    """The bundle's ``position_uncertainty`` section (``None`` when absent); BundleError when malformed."""
    return parse_number_section(section, "position_uncertainty", PositionUncertaintyConfig)


def parse_number_section(section: Any, name: str, cls: type, optional: tuple[str, ...] = ()) -> Any:
    """``cls(**section)`` for a bundle section ``name`` whose every field is a number (``None`` when the section is
    absent); ``BundleError`` when it is not an object, has unknown keys, lacks one not in ``optional``, holds a
    value that is not a number, or ``cls`` refuses the values."""
    if section is None:
        return None
    if not isinstance(section, Mapping):
        raise BundleError(f"bundle.json: {name} must be an object, got {type(section).__name__}")
    names = [f.name for f in fields(cls)]
    unknown = sorted(set(section) - set(names))
    missing = [n for n in names if n not in section and n not in optional]
    if unknown or missing:
        raise BundleError(f"bundle.json: {name} has unknown keys {unknown} / lacks {missing}")
    for key, value in section.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise BundleError(f"bundle.json: {name}.{key} must be a number, got {value!r}")
    try:
        return cls(**{k: float(v) for k, v in section.items()})
    except ValueError as err:
        raise BundleError(f"bundle.json: {err}") from err
