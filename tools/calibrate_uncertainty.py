"""Fit and check the per-frame uncertainty model (:mod:`spacepose.uncertainty`) on ``eval-pose`` reports.

``python -m spacepose.tools.calibrate_uncertainty REPORT [REPORT ...] [--bundle DIR] [--fit] [--positions | --confidence]
[--json OUT]``

Each REPORT is an ``eval-pose`` ``pose_eval.json`` (or ``.json.gz``) of a dataset's frames; its valid
poses give, per frame, the range error (``e_pos_los``: the reported centre's miss along the line of
sight), the cross-range error (the rest of ``e_pos``), the rotation error ``e_R``, the registration's
depth tolerance ``tau`` and the reported range ``z``; the report's ``focal_px`` (or ``--focal-px``) is the
rectified focal length.

* ``--fit``: the six constants (:func:`fit_uncertainty`) over the poses that are not wrong (off by more than
  20 degrees or 0.5 m): ``range_k`` the RMS of ``e_range / tau``; the cross-range and rotation models' shapes
  by non-negative least squares of the per-pose squared errors (on ``[1, (z/f)^2]``, and on ``[1, (z/f)^2,
  chamfer^2]`` for the rotation), each scaled so that its normalised squared errors average 1.
* Without it, the coverage of the constants in ``--bundle``'s ``uncertainty`` section (the shipped bundle
  by default): the share of poses within one and two (three for the rotation) sigma-equivalents, against
  the normal distribution's; the per-axis normalised squared errors of the poses that are not wrong (1 when
  the covariance matches their spread); the share of right and of wrong poses beyond a 3-sigma
  (chi-square 99.73 %) gate; the rank correlation of the errors with the predicted sigmas.

With ``--positions`` the same for the frames with a position but no pose (``position_valid``, not ``valid``):
the five constants of :class:`~spacepose.uncertainty.PositionUncertaintyConfig` (:func:`fit_position_uncertainty`:
the range's shape by non-negative least squares of ``(e_range / tau)^2`` on ``[1, chamfer^2]``, the cross-range's
of ``lateral^2 / 2`` on ``[1, (z/f)^2, chamfer^2]``, each scaled to a mean normalised squared error of 1, over the
positions that miss by at most 0.5 m), or the coverage of the bundle's ``position_uncertainty`` section.

With ``--confidence`` the confidence of valid poses (:mod:`spacepose.confidence`): with ``--fit``, its ``bias`` and
``slope`` (:func:`fit_confidence`, the logistic regression of "``e_t`` and ``e_R`` within ``--tolerance``" on the
logit of the normal model's probability, from the sigmas of the bundle's ``uncertainty`` section); without, how
the bundle's ``confidence`` section predicts that event (:func:`confidence_check`: mean confidence against the
share within, rank correlations with the errors, Brier score, quantile bins).

With ``--tails`` the errors' heavy tails (:mod:`spacepose.tails`): with ``--fit``, the Student-t degrees of freedom
``tail_dof`` (:func:`fit_tail_dof`, maximum likelihood over the right poses' position and rotation NEES against the
bundle's sigmas); without, how the bundle's ``tail_dof`` gates them (:func:`tail_check`: the share of right and of
wrong poses beyond the 95, 99 and 99.7 % gates, against chi-square's).

Fit only on training frames; check on frames rendered after the fit.
"""

from __future__ import annotations

import argparse
import gzip
import json
import logging
import math
from dataclasses import asdict
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np

from spacepose.confidence import P_CLIP, ConfidenceConfig, calibrated_confidence, within_probability
from spacepose.tails import nees_gate
from spacepose.uncertainty import (PositionUncertaintyConfig, UncertaintyConfig, pose_uncertainty,
                                   position_uncertainty)

logger = logging.getLogger(__name__)

__all__ = ["NOMINAL", "pose_errors", "position_errors", "wrong_poses", "fit_uncertainty", "fit_position_uncertainty",
           "coverage", "position_coverage", "format_coverage", "format_position_coverage", "normal_within",
           "model_sigmas", "within_tolerance", "fit_confidence", "confidence_check", "format_confidence_check",
           "nees_values", "right_nees", "fit_tail_dof", "tail_check", "format_tail_check", "GATE_PROBABILITIES", "main"]

# a normal distribution's share within the sigma-equivalent bounds that ``coverage`` counts
NOMINAL = {"range_1": 0.6827, "range_2": 0.9545, "lateral_1": 1.0 - math.exp(-0.5), "lateral_2": 1.0 - math.exp(-2.0),
           "rotation_median": 0.5, "rotation_3": 0.9707}
MAXWELL_MEDIAN = 1.5382  # median of the length of a 3-D standard normal vector
WRONG_DEG, WRONG_M = 20.0, 0.5   # a "wrong" valid pose, as the project counts them
CHI2_3DOF_997 = 14.156   # 99.73 % quantile of a chi-square with 3 degrees of freedom (a "3-sigma" gate)
GATE_PROBABILITIES = (0.95, 0.99, 0.997)   # the gates tail_check counts


def _read(path: Path) -> dict[str, Any]:
    opener = gzip.open if path.suffix == ".gz" else open
    with opener(path, "rt") as fh:
        return json.load(fh)


def pose_errors(rows: Iterable[dict[str, Any]], focal_px: float | None = None) -> dict[str, np.ndarray]:
    """Per valid pose with a depth tolerance: ``range`` (signed, m), ``lateral`` (m), ``e_R`` (deg), ``e_t``
    (the translation's error, m; NaN where the row has none), ``tau`` (m), ``z`` (m), ``ratio`` (z / f; NaN without ``focal_px``), ``chamfer`` (the outline fit, outline
    px) and, where the row has them, the predicted ``sigma_*`` (NaN otherwise)."""
    return _errors(rows, focal_px, positions_only=False)


def position_errors(rows: Iterable[dict[str, Any]], focal_px: float | None = None) -> dict[str, np.ndarray]:
    """:func:`pose_errors`' columns for the frames with a position but no pose (``position_valid`` and not
    ``valid``; ``e_R`` NaN)."""
    return _errors(rows, focal_px, positions_only=True)


def _errors(rows: Iterable[dict[str, Any]], focal_px: float | None, positions_only: bool) -> dict[str, np.ndarray]:
    keys = ("range", "lateral", "e_R", "e_t", "tau", "ratio", "z", "chamfer", "sigma_range_m", "sigma_lateral_m",
            "sigma_rotation_deg")
    out: dict[str, list[float]] = {k: [] for k in keys}
    for r in rows:
        tau = float(r.get("depth_tolerance_m", float("nan")))
        pos = np.asarray(r.get("position", [float("nan")] * 3), dtype=np.float64)
        wanted = (r.get("position_valid") and not r.get("valid")) if positions_only else r.get("valid")
        if not (wanted and math.isfinite(tau) and tau > 0 and np.all(np.isfinite(pos))):
            continue
        z = float(np.linalg.norm(pos))
        los, e_pos = float(r["e_pos_los"]), float(r["e_pos"])
        out["range"].append(los)
        out["lateral"].append(math.sqrt(max(e_pos ** 2 - los ** 2, 0.0)))
        out["e_R"].append(float("nan") if positions_only else float(r["e_R"]))
        out["e_t"].append(float("nan") if positions_only else float(r.get("e_t", float("nan"))))
        out["tau"].append(tau)
        out["ratio"].append(z / float(focal_px) if focal_px else float("nan"))
        out["z"].append(z)
        chamfer = r.get("outline_chamfer_px")
        out["chamfer"].append(float("nan") if chamfer is None else float(chamfer))
        for k in keys[-3:]:
            out[k].append(float(r.get(k, float("nan"))))
    return {k: np.asarray(v, dtype=np.float64) for k, v in out.items()}


def wrong_poses(err: dict[str, np.ndarray]) -> np.ndarray:
    """(n,) bool: the poses off by more than :data:`WRONG_DEG` or :data:`WRONG_M` (the centre's miss), the
    project's "wrong pose" (failures the gates try to stop, not the noise a covariance describes). For
    :func:`position_errors` rows (``e_R`` NaN): the positions that miss by more than :data:`WRONG_M`."""
    return (err["e_R"] > WRONG_DEG) | (np.hypot(err["range"], err["lateral"]) > WRONG_M)


def _scaled_nnls(features: np.ndarray, variance: np.ndarray) -> np.ndarray:
    """Non-negative ``c`` with ``variance ~ features @ c`` (least squares over the poses), then scaled so
    that the mean of ``variance / (features @ c)`` is 1: the squared coefficients of a consistent model."""
    from scipy.optimize import nnls

    coef, _ = nnls(features, variance)
    predicted = features @ coef
    if not np.all(predicted > 0):
        raise ValueError("the fitted variance is not positive on every pose (too few or degenerate poses)")
    return coef * float(np.mean(variance / predicted))


def fit_uncertainty(err: dict[str, np.ndarray]) -> UncertaintyConfig:
    """The constants of :class:`~spacepose.uncertainty.UncertaintyConfig` from :func:`pose_errors` rows, over
    the poses that are not wrong (:func:`wrong_poses`) and have an outline chamfer: ``range_k`` the RMS of
    ``e_range / tau``; the cross-range model's shape by non-negative least squares of ``lateral^2 / 2`` on
    ``[1, (z/f)^2]``, the rotation's of ``e_R^2 / 3`` on ``[1, (z/f)^2, chamfer^2]`` (per-axis variances of
    2-D and 3-D normals), each then scaled so that its mean normalised squared error is 1. The covariance
    then matches the errors' spread (a navigation filter's normalised errors average one per axis), and
    wrong poses stand out of it."""
    keep = ~wrong_poses(err) & np.isfinite(err["chamfer"]) & np.isfinite(err["ratio"])
    if keep.sum() < 25:
        raise ValueError(f"{int(keep.sum())} valid poses (not wrong, with a chamfer) are too few to fit (need 25)")
    e = {k: v[keep] for k, v in err.items()}
    range_k = float(np.sqrt(np.mean((e["range"] / e["tau"]) ** 2)))
    ones, ratio2 = np.ones(len(e["ratio"])), e["ratio"] ** 2
    lat = _scaled_nnls(np.stack([ones, ratio2], axis=1), e["lateral"] ** 2 / 2.0)
    rot = _scaled_nnls(np.stack([ones, ratio2, e["chamfer"] ** 2], axis=1), e["e_R"] ** 2 / 3.0)
    return UncertaintyConfig(range_k=range_k, lateral_px=float(np.sqrt(lat[1])), lateral_floor_m=float(np.sqrt(lat[0])),
                             rotation_k_deg=float(np.sqrt(rot[1])), rotation_floor_deg=float(np.sqrt(rot[0])),
                             rotation_chamfer_deg=float(np.sqrt(rot[2])))


def fit_position_uncertainty(err: dict[str, np.ndarray]) -> PositionUncertaintyConfig:
    """The constants of :class:`~spacepose.uncertainty.PositionUncertaintyConfig` from :func:`position_errors`
    rows, over the positions that miss by at most :data:`WRONG_M` and have a chamfer: the range's shape by
    non-negative least squares of ``(e_range / tau)^2`` on ``[1, chamfer^2]``, the cross-range's of
    ``lateral^2 / 2`` on ``[1, (z/f)^2, chamfer^2]``, each scaled so that its mean normalised squared error is 1."""
    keep = ~wrong_poses(err) & np.isfinite(err["chamfer"]) & np.isfinite(err["ratio"])
    if keep.sum() < 25:
        raise ValueError(f"{int(keep.sum())} positions (not wrong, with a chamfer) are too few to fit (need 25)")
    e = {k: v[keep] for k, v in err.items()}
    ones, chamfer2 = np.ones(len(e["ratio"])), e["chamfer"] ** 2
    rng = _scaled_nnls(np.stack([ones, chamfer2], axis=1), (e["range"] / e["tau"]) ** 2)
    lat = _scaled_nnls(np.stack([ones, e["ratio"] ** 2, chamfer2], axis=1), e["lateral"] ** 2 / 2.0)
    return PositionUncertaintyConfig(range_k=float(np.sqrt(rng[0])), range_chamfer_k=float(np.sqrt(rng[1])),
                                     lateral_px=float(np.sqrt(lat[1])), lateral_floor_m=float(np.sqrt(lat[0])),
                                     lateral_chamfer_m=float(np.sqrt(lat[2])))


def model_sigmas(err: dict[str, np.ndarray], config: UncertaintyConfig, focal_px: float | None) -> np.ndarray:
    """(n, 3) the sigmas ``config`` gives each :func:`pose_errors` pose (range m, lateral m, rotation deg),
    recomputed from its ``tau``, ``z`` and chamfer with ``focal_px``; NaN where it gives none."""
    sig = np.full((len(err["range"]), 3), np.nan)
    for i in range(len(sig)):
        spread = pose_uncertainty(np.array([0.0, 0.0, err["z"][i]]), float(err["tau"][i]), float(focal_px), config,
                                  float(err["chamfer"][i]))
        if spread is not None:
            sig[i] = spread.sigma_range_m, spread.sigma_lateral_m, spread.sigma_rotation_deg
    return sig


def normal_within(err: dict[str, np.ndarray], config: UncertaintyConfig, focal_px: float,
                  tolerance: ConfidenceConfig) -> np.ndarray:
    """(n,) the normal model's probability ``p`` (:func:`spacepose.confidence.within_probability`) that each
    :func:`pose_errors` pose is within ``tolerance``'s ``position_m`` and ``rotation_deg``, from the sigmas of
    ``config`` (recomputed from ``tau``, ``z`` and the chamfer with ``focal_px``); NaN where it has none."""
    return np.array([within_probability(*sig, tolerance) if np.all(np.isfinite(sig)) else np.nan
                     for sig in model_sigmas(err, config, focal_px)])


def within_tolerance(err: dict[str, np.ndarray], tolerance: ConfidenceConfig) -> np.ndarray:
    """(n,) bool: ``e_t <= position_m`` and ``e_R <= rotation_deg`` (the event the confidence predicts)."""
    return (err["e_t"] <= tolerance.position_m) & (err["e_R"] <= tolerance.rotation_deg)


def fit_confidence(p: np.ndarray, within: np.ndarray, position_m: float = 0.10,
                   rotation_deg: float = 2.0) -> ConfidenceConfig:
    """``bias`` and ``slope`` of :class:`~spacepose.confidence.ConfidenceConfig` by maximum likelihood: the
    logistic regression of ``within`` (n,) bool on ``logit(p)`` (n,), ``p`` clipped as the runtime clips it
    (Newton's method; poses with ``p`` NaN left out)."""
    keep = np.isfinite(p)
    y = np.asarray(within, dtype=np.float64)[keep]
    if len(y) < 25 or y.min() == y.max():
        raise ValueError(f"{len(y)} poses, {int(y.sum())} within the tolerance: too few, or all on one side, to fit")
    q = np.clip(p[keep], P_CLIP, 1.0 - P_CLIP)
    x = np.stack([np.ones(len(q)), np.log(q / (1.0 - q))], axis=1)
    w = np.zeros(2)
    for _ in range(100):
        m = 0.5 * (1.0 + np.tanh(0.5 * (x @ w)))     # the logistic function, without overflow
        hessian = (x * (m * (1.0 - m))[:, None]).T @ x
        try:
            step = np.linalg.solve(hessian, x.T @ (y - m))
        except np.linalg.LinAlgError:
            step = np.full(2, np.inf)
        if not np.all(np.isfinite(step)) or np.max(np.abs(w + step)) > 1e3:
            break
        w += step
        if np.max(np.abs(step)) < 1e-10:
            break
    else:
        step = np.full(2, np.inf)
    if not np.max(np.abs(step)) < 1e-10:
        raise ValueError("the logistic fit did not converge (the poses within and without may be separable)")
    return ConfidenceConfig(position_m=float(position_m), rotation_deg=float(rotation_deg), bias=float(w[0]),
                            slope=float(w[1]))


def confidence_check(confidence: np.ndarray, within: np.ndarray, e_t: np.ndarray, e_R: np.ndarray,
                     n_bins: int = 4) -> dict[str, Any]:
    """How a confidence (n,) predicts ``within`` (n,) bool, over the poses with a finite confidence: ``poses``,
    ``mean_confidence``, ``share_within``, ``spearman_t`` / ``spearman_R`` (of ``e_t`` / ``e_R`` with the
    confidence: negative when the errors grow as it falls), ``brier`` and ``brier_base`` (the Brier score of
    the confidence, and of the set's own share within as a constant), and ``bins``: ``n_bins`` quantile bins
    of confidence, lowest first, each ``{"poses", "mean_confidence", "share_within"}``."""
    keep = np.isfinite(confidence)
    c, y = np.asarray(confidence)[keep], np.asarray(within, dtype=np.float64)[keep]
    if not len(c):
        return {"poses": 0}
    order = np.argsort(c, kind="stable")
    bins = [{"poses": int(len(b)), "mean_confidence": float(c[b].mean()), "share_within": float(y[b].mean())}
            for b in np.array_split(order, min(n_bins, len(c)))]
    return {"poses": int(len(c)), "mean_confidence": float(c.mean()), "share_within": float(y.mean()),
            "spearman_t": _spearman(np.asarray(e_t)[keep], c), "spearman_R": _spearman(np.asarray(e_R)[keep], c),
            "brier": float(np.mean((c - y) ** 2)), "brier_base": float(np.mean((y.mean() - y) ** 2)), "bins": bins}


def format_confidence_check(name: str, check: dict[str, Any]) -> str:
    if not check.get("poses"):
        return f"{name}: no valid pose with a confidence"
    bins = " ".join(f"{b['mean_confidence']:.2f}/{b['share_within']:.2f}" for b in check["bins"])
    return (f"{name}: {check['poses']} poses | mean confidence {check['mean_confidence']:.3f}, within "
            f"{check['share_within']:.3f} | spearman e_t {check['spearman_t']:+.2f}, e_R {check['spearman_R']:+.2f} | "
            f"brier {check['brier']:.3f} (constant {check['brier_base']:.3f}) | bins low to high, confidence/within: "
            f"{bins}")


def _spearman(a: np.ndarray, b: np.ndarray) -> float:
    if len(a) < 3:
        return float("nan")
    ra, rb = np.argsort(np.argsort(a)), np.argsort(np.argsort(b))
    return float(np.corrcoef(ra, rb)[0, 1])


def coverage(err: dict[str, np.ndarray], config: UncertaintyConfig | None = None,
             focal_px: float | None = None) -> dict[str, float]:
    """Shares of the poses within the predicted sigma-equivalents (keys of :data:`NOMINAL`) and rank
    correlations of the errors with the sigmas: those of ``config`` (recomputed from ``tau`` and ``z``
    with ``focal_px``), or without it the ones the rows recorded (``sigma_*``; poses without any are left
    out)."""
    if config is not None:
        sig = model_sigmas(err, config, focal_px)
        keep = np.all(np.isfinite(sig), axis=1)
    else:
        sig = np.stack([err["sigma_range_m"], err["sigma_lateral_m"], err["sigma_rotation_deg"]], axis=1)
        keep = np.all(np.isfinite(sig), axis=1)
    if not keep.any():
        return {"poses": 0}
    s_r, s_l, s_R = sig[keep].T
    e_R = err["e_R"][keep]
    right = ~wrong_poses({k: v[keep] for k, v in err.items()})
    out = _position_coverage(err["range"][keep], err["lateral"][keep], s_r, s_l, right, (e_R / s_R) ** 2)
    return {"poses": out.pop("positions"), **out,
            "nees_rotation": float(np.mean((e_R[right] / s_R[right]) ** 2) / 3.0) if right.any() else float("nan"),
            "rotation_median": float(np.mean(e_R <= MAXWELL_MEDIAN * s_R)),
            "rotation_3": float(np.mean(e_R <= 3 * s_R)),
            "spearman_rotation": _spearman(e_R, s_R),
            "sigma_rotation_median_deg": float(np.median(s_R))}


def position_coverage(err: dict[str, np.ndarray], config: PositionUncertaintyConfig | None = None,
                      focal_px: float | None = None) -> dict[str, float]:
    """:func:`coverage`'s position columns for :func:`position_errors` rows: with ``config`` its sigmas
    (recomputed from ``tau``, ``z`` and the chamfer with ``focal_px``), else the recorded ones. Keys:
    ``positions``, ``wrong``, the gate shares, ``nees_range``, ``nees_lateral``, ``range_1/2``,
    ``lateral_1/2``, ``spearman_position`` and the median sigmas."""
    n = len(err["range"])
    if config is not None:
        sig = np.full((n, 2), np.nan)
        for i in range(n):
            spread = position_uncertainty(np.array([0.0, 0.0, err["z"][i]]), float(err["tau"][i]), float(focal_px),
                                          config, float(err["chamfer"][i]))
            if spread is not None:
                sig[i] = spread.sigma_range_m, spread.sigma_lateral_m
    else:
        sig = np.stack([err["sigma_range_m"], err["sigma_lateral_m"]], axis=1)
    keep = np.all(np.isfinite(sig), axis=1)
    if not keep.any():
        return {"positions": 0}
    right = ~wrong_poses({k: v[keep] for k, v in err.items()})
    s_r, s_l = sig[keep].T
    return _position_coverage(err["range"][keep], err["lateral"][keep], s_r, s_l, right, np.zeros(int(keep.sum())))


def _position_coverage(e_r: np.ndarray, e_l: np.ndarray, s_r: np.ndarray, s_l: np.ndarray, right: np.ndarray,
                       d2_other: np.ndarray) -> dict[str, float]:
    """Shares, normalised squared errors (over ``right``) and the 3-sigma gate for range and cross-range errors
    ``e_r`` (signed), ``e_l`` (>= 0) with sigmas ``s_r``, ``s_l``; ``d2_other`` another term the gate also tests."""
    wrong = ~right
    flagged = ((e_r / s_r) ** 2 + (e_l / s_l) ** 2 > CHI2_3DOF_997) | (d2_other > CHI2_3DOF_997)
    return {"positions": int(len(e_r)), "wrong": int(wrong.sum()),
            "wrong_flagged": float(np.mean(flagged[wrong])) if wrong.any() else float("nan"),
            "right_flagged": float(np.mean(flagged[right])) if right.any() else float("nan"),
            "nees_range": float(np.mean((e_r[right] / s_r[right]) ** 2)) if right.any() else float("nan"),
            "nees_lateral": float(np.mean((e_l[right] / s_l[right]) ** 2) / 2.0) if right.any() else float("nan"),
            "range_1": float(np.mean(np.abs(e_r) <= s_r)),
            "range_2": float(np.mean(np.abs(e_r) <= 2 * s_r)),
            "lateral_1": float(np.mean(e_l <= s_l)),
            "lateral_2": float(np.mean(e_l <= 2 * s_l)),
            "spearman_position": _spearman(np.hypot(e_r, e_l), np.sqrt(s_r ** 2 + 2 * s_l ** 2)),
            "sigma_range_median_m": float(np.median(s_r)), "sigma_lateral_median_m": float(np.median(s_l))}


def format_coverage(name: str, cov: dict[str, float]) -> str:
    if not cov.get("poses"):
        return f"{name}: no valid pose with a depth tolerance"
    cells = " ".join(f"{k} {100 * cov[k]:5.1f}% ({100 * NOMINAL[k]:.1f})" for k in NOMINAL)
    return (f"{name}: {cov['poses']} poses | {cells} | per-axis normalised squared error of the {cov['poses'] - cov['wrong']}"
            f" not wrong (1 if consistent): range {cov['nees_range']:.2f}, lateral {cov['nees_lateral']:.2f}, rotation "
            f"{cov['nees_rotation']:.2f} | beyond a 3-sigma gate: {100 * cov['right_flagged']:.1f}% of those, "
            f"{100 * cov['wrong_flagged']:.0f}% of the {cov['wrong']} wrong | spearman e_t "
            f"{cov['spearman_position']:.2f}, e_R {cov['spearman_rotation']:.2f}")


def format_position_coverage(name: str, cov: dict[str, float]) -> str:
    if not cov.get("positions"):
        return f"{name}: no position without a pose that has a covariance"
    cells = " ".join(f"{k} {100 * cov[k]:5.1f}% ({100 * NOMINAL[k]:.1f})"
                     for k in ("range_1", "range_2", "lateral_1", "lateral_2"))
    return (f"{name}: {cov['positions']} positions without a pose | {cells} | per-axis normalised squared error of "
            f"the {cov['positions'] - cov['wrong']} within {WRONG_M} m: range {cov['nees_range']:.2f}, lateral "
            f"{cov['nees_lateral']:.2f} | beyond a 3-sigma gate: {100 * cov['right_flagged']:.1f}% of those, "
            f"{100 * cov['wrong_flagged']:.0f}% of the {cov['wrong']} others | spearman e_pos "
            f"{cov['spearman_position']:.2f}")


def nees_values(err: dict[str, np.ndarray], config: UncertaintyConfig, focal_px: float | None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(d2_position, d2_rotation, right)`` over the poses with finite sigmas of ``config``: the position's NEES
    against its covariance (range and cross-range, 3 axes), the rotation's against ``sigma_rot`` per axis (3
    axes), and which poses are not wrong (:func:`wrong_poses`)."""
    sig = model_sigmas(err, config, focal_px)
    keep = np.all(np.isfinite(sig), axis=1)
    s_r, s_l, s_R = sig[keep].T
    d2_position = (err["range"][keep] / s_r) ** 2 + (err["lateral"][keep] / s_l) ** 2
    d2_rotation = (err["e_R"][keep] / s_R) ** 2
    right = ~wrong_poses({k: v[keep] for k, v in err.items()})
    return d2_position, d2_rotation, right


def fit_tail_dof(d2: np.ndarray, bounds: tuple[float, float] = (2.05, 200.0)) -> float:
    """The Student-t degrees of freedom (:mod:`spacepose.tails`) that maximise the likelihood of the 3-axis NEES
    values ``d2`` (the right poses' position and rotation NEES of :func:`nees_values`, pooled), within ``bounds``.
    ValueError with fewer than 20 finite values."""
    from scipy import optimize, stats

    d2 = np.asarray(d2, dtype=np.float64)
    d2 = d2[np.isfinite(d2)]
    if len(d2) < 20:
        raise ValueError(f"need at least 20 NEES values to fit the tails, got {len(d2)}")
    d2 = np.maximum(d2, 1e-12)

    def nll(nu: float) -> float:
        c = nu / ((nu - 2.0) * 3.0)   # d2 * c ~ F(3, nu)
        return -float(np.sum(stats.f.logpdf(d2 * c, 3, nu) + math.log(c)))

    res = optimize.minimize_scalar(nll, bounds=bounds, method="bounded", options={"xatol": 1e-4})
    return float(res.x)


def right_nees(per_report: Iterable[tuple[dict[str, np.ndarray], float]], config: UncertaintyConfig) -> np.ndarray:
    """The right poses' position and rotation NEES (:func:`nees_values`) of every ``(err, focal_px)``, pooled."""
    parts = []
    for err, focal in per_report:
        d2_position, d2_rotation, right = nees_values(err, config, focal)
        parts += [d2_position[right], d2_rotation[right]]
    return np.concatenate(parts) if parts else np.zeros(0)


def tail_check(err: dict[str, np.ndarray], config: UncertaintyConfig, focal_px: float | None,
               tail_dof: float) -> dict[str, Any]:
    """The gates of ``tail_dof`` (and chi-square's, ``tail_dof`` 0) at :data:`GATE_PROBABILITIES`: per gate the
    share of right poses whose position / rotation NEES is beyond it and the share of wrong poses beyond either."""
    d2_position, d2_rotation, right = nees_values(err, config, focal_px)
    out: dict[str, Any] = {"poses": int(len(right)), "right": int(right.sum()), "wrong": int((~right).sum()),
                           "tail_dof": float(tail_dof), "gates": {}}
    for model, nu in (("t", tail_dof), ("chi2", 0.0)):
        for p in GATE_PROBABILITIES:
            gate = nees_gate(p, 3, nu)
            pos, rot = d2_position > gate, d2_rotation > gate
            out["gates"][f"{model}_{p}"] = {
                "gate": gate,
                "right_position": float(np.mean(pos[right])) if right.any() else float("nan"),
                "right_rotation": float(np.mean(rot[right])) if right.any() else float("nan"),
                "wrong_either": float(np.mean((pos | rot)[~right])) if (~right).any() else float("nan")}
    return out


def format_tail_check(name: str, check: dict[str, Any]) -> str:
    """One line per gate model: the gates and the shares beyond them (right position / right rotation / wrong)."""
    lines = [f"{name}: {check['right']} right and {check['wrong']} wrong poses; beyond the gate, right position / "
             f"right rotation / wrong (either):"]
    for model, label in (("t", f"t, dof {check['tail_dof']:.2f}"), ("chi2", "chi-square")):
        cells = []
        for p in GATE_PROBABILITIES:
            g = check["gates"][f"{model}_{p}"]
            cells.append(f"{100 * p:g}% gate {g['gate']:.1f}: {100 * g['right_position']:.1f}% / "
                         f"{100 * g['right_rotation']:.1f}% / {100 * g['wrong_either']:.0f}%")
        lines.append(f"  {label:<14}" + " | ".join(cells))
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m spacepose.tools.calibrate_uncertainty", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("reports", type=Path, nargs="+", help="eval-pose pose_eval.json[.gz] files")
    parser.add_argument("--fit", action="store_true", help="fit the constants on these reports")
    what = parser.add_mutually_exclusive_group()
    what.add_argument("--positions", action="store_true",
                      help="the frames with a position but no pose (the position_uncertainty section)")
    what.add_argument("--tails", action="store_true",
                      help="the errors' heavy tails: the uncertainty section's tail_dof (fit with --fit) and its gates")
    what.add_argument("--confidence", action="store_true",
                      help="the confidence of valid poses from their uncertainty (the confidence section; the "
                           "bundle's uncertainty section gives the sigmas)")
    parser.add_argument("--tolerance", type=float, nargs=2, default=(0.10, 2.0), metavar=("M", "DEG"),
                        help="with --confidence --fit: the tolerance the confidence predicts (default 0.10 m, 2 deg)")
    parser.add_argument("--bundle", type=Path, default=None, help="bundle whose uncertainty section is checked")
    parser.add_argument("--focal-px", type=float, default=None,
                        help="rectified focal length (default: each report's focal_px)")
    parser.add_argument("--json", type=Path, default=None, help="write the fit / coverage here")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    per_report = []
    for path in args.reports:
        report = _read(path)
        focal = args.focal_px or report.get("focal_px")
        if focal is None:
            parser.error(f"{path} records no focal_px: pass --focal-px")
        errors = position_errors if args.positions else pose_errors
        per_report.append((str(path), errors(report["frames"], float(focal)), float(focal)))
    out: dict[str, Any] = {"reports": [p for p, _, _ in per_report]}
    if args.confidence:
        return _confidence_main(parser, args, per_report, out)
    if args.tails:
        return _tails_main(parser, args, per_report, out)
    section = "position_uncertainty" if args.positions else "uncertainty"
    config: UncertaintyConfig | PositionUncertaintyConfig | None
    if args.fit:
        pooled = {k: np.concatenate([e[k] for _, e, _ in per_report]) for k in per_report[0][1]}
        config = fit_position_uncertainty(pooled) if args.positions else fit_uncertainty(pooled)
        out["fit"] = {k: v for k, v in asdict(config).items() if k != "tail_dof"}   # --tails fits it
        print(json.dumps({section: out["fit"]}, indent=1))
    else:
        config = getattr(_load(args.bundle), section)
        if config is None:
            parser.error(f"the bundle has no {section} section: pass --fit, or a bundle with one")
    out["coverage"] = {}
    for path, err, focal in per_report:
        if args.positions:
            cov = position_coverage(err, config, focal)   # type: ignore[arg-type]
            line = format_position_coverage(path, cov)
        else:
            cov = coverage(err, config, focal)            # type: ignore[arg-type]
            line = format_coverage(path, cov)
        out["coverage"][path] = cov
        print(line)
    _write(args.json, out)
    return 0


def _load(bundle: Path | None) -> Any:
    from spacepose.bundle import load_bundle

    return load_bundle(bundle, verify_graphs=False)


def _write(path: Path | None, out: dict[str, Any]) -> None:
    if path is not None:
        path.write_text(json.dumps(out, indent=1))


def _confidence_main(parser: argparse.ArgumentParser, args: argparse.Namespace,
                     per_report: list[tuple[str, dict[str, np.ndarray], float]], out: dict[str, Any]) -> int:
    """``--confidence``: fit ``bias`` and ``slope`` on the reports (``--fit``), or check the bundle's section."""
    model = _load(args.bundle)
    if model.uncertainty is None:
        parser.error("the bundle has no uncertainty section: the confidence needs its sigmas")
    if args.fit:
        try:
            tolerance = ConfidenceConfig(position_m=args.tolerance[0], rotation_deg=args.tolerance[1], bias=0.0,
                                         slope=1.0)
        except ValueError as err:
            parser.error(f"--tolerance: {err}")
    elif model.confidence is None:
        parser.error("the bundle has no confidence section: pass --fit, or a bundle with one")
    else:
        tolerance = model.confidence
    p = [normal_within(err, model.uncertainty, focal, tolerance) for _, err, focal in per_report]
    within = [within_tolerance(err, tolerance) for _, err, _ in per_report]
    config = tolerance
    if args.fit:
        try:
            config = fit_confidence(np.concatenate(p), np.concatenate(within), tolerance.position_m,
                                    tolerance.rotation_deg)
        except ValueError as err:
            parser.error(f"cannot fit the confidence on these reports: {err}")
        out["fit"] = {k: v for k, v in asdict(config).items() if k != "min_valid"}   # a floor is chosen, not fitted
        print(json.dumps({"confidence": out["fit"]}, indent=1))
    out["check"] = {}
    for (path, err, _), p_i, w_i in zip(per_report, p, within):
        conf = np.array([calibrated_confidence(v, config) if math.isfinite(v) else np.nan for v in p_i])
        out["check"][path] = confidence_check(conf, w_i, err["e_t"], err["e_R"])
        print(format_confidence_check(path, out["check"][path]))
    _write(args.json, out)
    return 0


def _tails_main(parser: argparse.ArgumentParser, args: argparse.Namespace,
                per_report: list[tuple[str, dict[str, np.ndarray], float]], out: dict[str, Any]) -> int:
    """``--tails``: fit ``tail_dof`` on the reports (``--fit``) against the bundle's sigmas, or check its gates."""
    model = _load(args.bundle)
    if model.uncertainty is None:
        parser.error("the bundle has no uncertainty section: the tails are those of its sigmas")
    tail_dof = model.uncertainty.tail_dof
    if args.fit:
        try:
            tail_dof = fit_tail_dof(right_nees([(e, f) for _, e, f in per_report], model.uncertainty))
        except ValueError as err:
            parser.error(f"cannot fit the tails on these reports: {err}")
        out["fit"] = {"tail_dof": round(tail_dof, 4)}
        print(json.dumps({"uncertainty": out["fit"]}, indent=1))
    elif tail_dof == 0.0:
        logger.info("the bundle's uncertainty section has no tail_dof: its gates are chi-square's")
    out["check"] = {}
    for path, err, focal in per_report:
        out["check"][path] = tail_check(err, model.uncertainty, focal, tail_dof)
        print(format_tail_check(path, out["check"][path]))
    _write(args.json, out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
