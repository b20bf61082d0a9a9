"""Evaluation metrics (paper §5.1, eqs. 28-33) plus ADD, ADD-S and the SPEED score. float64, numpy only.

Stereo metrics (EPE, RMSE, bad-τ, D1) are taken over a validity mask. Pixels whose ground truth
is not finite are dropped from the mask (PFM files mark unknown disparity with inf).

Empty mask: when no pixel is valid every stereo metric is ``NaN`` (``float('nan')``), never an
exception: a frame without ground truth must not stop an evaluation; aggregate with ``np.nanmean``
and count the frames separately. A non-finite *prediction* inside the mask is a bug upstream and
raises :class:`~spacepose.errors.ShapeError`.

Pose metrics follow ``spec/CONVENTIONS.md``: ``X_cam = R @ X_obj + t``, ``e_t = ||t - t_hat||`` in
metres, ``e_R`` = angle of ``R^T R_hat`` in degrees, computed as
``atan2(||vee(M - M^T)|| / 2, (tr M - 1) / 2)`` which is accurate near 0° and 180° and cannot
return NaN (also for slightly non-orthogonal inputs).
"""

from __future__ import annotations

import logging
import math
import numbers

import numpy as np

from .errors import ShapeError, check_finite, check_shape

__all__ = [
    "epe",
    "rmse",
    "bad_tau",
    "d1",
    "stereo_metrics",
    "translation_error",
    "rotation_error_deg",
    "add",
    "add_s",
    "speed_score",
    "SPEED_ROTATION_THRESHOLD_DEG",
    "SPEED_TRANSLATION_THRESHOLD",
]

logger = logging.getLogger(__name__)

#: SPNv2 zeroes the rotation term under this angle (degrees) when thresholds are applied.
SPEED_ROTATION_THRESHOLD_DEG = 0.5
#: SPNv2 zeroes the relative translation term under this value when thresholds are applied.
SPEED_TRANSLATION_THRESHOLD = 0.005

# concrete dtypes (not np.floating): check_shape names them in its message
_FLOAT_DTYPES = (np.float16, np.float32, np.float64)
_NN_CHUNK_ELEMENTS = 1 << 22  # pairwise distances held at once by add_s (32 MiB of float64)


# ----------------------------------------------------------------------------- stereo (eqs. 28-31)


def _abs_errors(pred: np.ndarray, gt: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Validate the inputs; return ``|pred - gt|`` and ``gt`` on the effective mask, float64."""
    check_shape(pred, (None, None), "pred", dtypes=_FLOAT_DTYPES)
    check_shape(gt, pred.shape, "gt", dtypes=_FLOAT_DTYPES)
    check_shape(valid, pred.shape, "valid", dtypes=(np.bool_,))
    mask = valid & np.isfinite(gt)
    p = pred[mask].astype(np.float64)
    check_finite(p, "pred (inside the valid mask)")
    g = gt[mask].astype(np.float64)
    if p.size == 0:
        logger.debug("stereo metric over an empty mask: returning NaN")
    return np.abs(p - g), g


def _mean_or_nan(values: np.ndarray) -> float:
    return float(np.mean(values)) if values.size else math.nan


def _check_tau(tau: object) -> float:
    if isinstance(tau, bool) or not isinstance(tau, numbers.Real) or not math.isfinite(float(tau)) or tau < 0:
        raise ValueError(f"tau must be a finite number >= 0, got {tau!r}")
    return float(tau)


def epe(pred: np.ndarray, gt: np.ndarray, valid: np.ndarray) -> float:
    """End-point error (eq. 28): mean ``|pred - gt|`` over the valid pixels, in pixels.

    Args:
        pred: (H, W) floating predicted disparity.
        gt: (H, W) floating ground-truth disparity (non-finite pixels are ignored).
        valid: (H, W) bool mask of the pixels to score.

    Returns:
        EPE as a Python float; NaN when no pixel is valid.

    Raises:
        ShapeError: shapes differ, wrong dtypes, or a non-finite prediction inside the mask.
    """
    err, _ = _abs_errors(pred, gt, valid)
    return _mean_or_nan(err)


def rmse(pred: np.ndarray, gt: np.ndarray, valid: np.ndarray) -> float:
    """Root mean squared disparity error (eq. 29) over the valid pixels, in pixels.

    Shapes, empty-mask behaviour and errors as :func:`epe`.
    """
    err, _ = _abs_errors(pred, gt, valid)
    return math.sqrt(_mean_or_nan(err * err)) if err.size else math.nan


def bad_tau(pred: np.ndarray, gt: np.ndarray, valid: np.ndarray, tau: float) -> float:
    """bad-τ (eq. 30): percentage of valid pixels with ``|pred - gt| > tau`` (0-100).

    Shapes, empty-mask behaviour and errors as :func:`epe`; ``ValueError`` for a negative or
    non-finite ``tau``.
    """
    tau = _check_tau(tau)
    err, _ = _abs_errors(pred, gt, valid)
    return 100.0 * _mean_or_nan((err > tau).astype(np.float64))


def d1(pred: np.ndarray, gt: np.ndarray, valid: np.ndarray) -> float:
    """D1 (eq. 31, KITTI): percentage of valid pixels whose error is > 3 px AND > 5 % of ``gt``.

    Shapes, empty-mask behaviour and errors as :func:`epe`.
    """
    err, g = _abs_errors(pred, gt, valid)
    return 100.0 * _mean_or_nan(((err > 3.0) & (err > 0.05 * g)).astype(np.float64))


def stereo_metrics(pred: np.ndarray, gt: np.ndarray, valid: np.ndarray) -> dict[str, float]:
    """All stereo metrics of one disparity map.

    Args:
        pred: (H, W) floating predicted disparity.
        gt: (H, W) floating ground-truth disparity (non-finite pixels are ignored).
        valid: (H, W) bool mask of the pixels to score (e.g. ``target_mask & (gt > 0)``).

    Returns:
        ``{"epe", "rmse", "bad1", "bad3", "d1"}`` as Python floats (pixels; bad/d1 in percent)
        plus ``"n_valid"`` (float count of scored pixels). Every metric is NaN when ``n_valid == 0``.

    Raises:
        ShapeError: shapes differ, wrong dtypes, or a non-finite prediction inside the mask.
    """
    err, g = _abs_errors(pred, gt, valid)
    if err.size == 0:
        nan = math.nan
        return {"epe": nan, "rmse": nan, "bad1": nan, "bad3": nan, "d1": nan, "n_valid": 0.0}
    return {
        "epe": float(np.mean(err)),
        "rmse": math.sqrt(float(np.mean(err * err))),
        "bad1": 100.0 * float(np.mean(err > 1.0)),
        "bad3": 100.0 * float(np.mean(err > 3.0)),
        "d1": 100.0 * float(np.mean((err > 3.0) & (err > 0.05 * g))),
        "n_valid": float(err.size),
    }


# ----------------------------------------------------------------------------- pose (eqs. 32-33)


def _vector3(t: object, name: str) -> np.ndarray:
    check_shape(t, (3,), name, dtypes=_FLOAT_DTYPES)
    check_finite(t, name)
    return np.asarray(t, dtype=np.float64)


def _matrix3(R: object, name: str) -> np.ndarray:
    check_shape(R, (3, 3), name, dtypes=_FLOAT_DTYPES)
    check_finite(R, name)
    return np.asarray(R, dtype=np.float64)


def translation_error(t: np.ndarray, t_hat: np.ndarray) -> float:
    """Translation error ``e_t = ||t - t_hat||_2`` (eq. 32) in the units of ``t`` (metres).

    Args:
        t: (3,) floating ground-truth translation.
        t_hat: (3,) floating estimated translation.

    Raises:
        ShapeError: wrong shape or dtype, or NaN/inf.
    """
    t = _vector3(t, "t")
    t_hat = _vector3(t_hat, "t_hat")
    return float(np.linalg.norm(t - t_hat))


def _rotation_angle_rad(R: np.ndarray, R_hat: np.ndarray) -> float:
    """Angle of ``R^T R_hat`` in radians, in [0, pi], via atan2 (no NaN)."""
    M = R.T @ R_hat
    cos_part = (float(np.sum(R * R_hat)) - 1.0) / 2.0  # tr(R^T R_hat) = <R, R_hat>_F (symmetric in R, R_hat)
    axis = np.array([M[2, 1] - M[1, 2], M[0, 2] - M[2, 0], M[1, 0] - M[0, 1]])
    sin_part = float(np.linalg.norm(axis)) / 2.0
    return math.atan2(sin_part, cos_part)


def rotation_error_deg(R: np.ndarray, R_hat: np.ndarray) -> float:
    """Rotation error ``e_R`` (eq. 33): angle of ``R^T R_hat`` in degrees, in [0, 180].

    Equal to ``arccos((tr(R^T R_hat) - 1) / 2)`` for rotations but computed as
    ``atan2(||vee(M - M^T)|| / 2, (tr M - 1) / 2)``: accurate near 0° and 180°, symmetric in its
    arguments and never NaN, also for slightly non-orthogonal matrices.

    Args:
        R: (3, 3) floating ground-truth rotation.
        R_hat: (3, 3) floating estimated rotation.

    Raises:
        ShapeError: wrong shape or dtype, or NaN/inf.
    """
    R = _matrix3(R, "R")
    R_hat = _matrix3(R_hat, "R_hat")
    return math.degrees(_rotation_angle_rad(R, R_hat))


def _pose_inputs(
    R: np.ndarray, t: np.ndarray, R_hat: np.ndarray, t_hat: np.ndarray, points: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Validate; return the model points transformed by the true and by the estimated pose (float64)."""
    R = _matrix3(R, "R")
    t = _vector3(t, "t")
    R_hat = _matrix3(R_hat, "R_hat")
    t_hat = _vector3(t_hat, "t_hat")
    check_shape(points, (None, 3), "points", dtypes=_FLOAT_DTYPES)
    check_finite(points, "points")
    if points.shape[0] == 0:
        raise ShapeError("points must hold at least one point, got shape (0, 3)")
    pts = points.astype(np.float64, copy=False)
    return pts @ R.T + t, pts @ R_hat.T + t_hat


def add(
    R: np.ndarray, t: np.ndarray, R_hat: np.ndarray, t_hat: np.ndarray, points: np.ndarray
) -> float:
    """ADD: mean distance between model points under the true and the estimated pose.

    ``mean_i ||(R p_i + t) - (R_hat p_i + t_hat)||`` in the units of ``points``/``t`` (metres).

    Args:
        R, R_hat: (3, 3) floating rotations (true, estimated).
        t, t_hat: (3,) floating translations (true, estimated).
        points: (N, 3) floating model points in object coordinates, N >= 1.

    Raises:
        ShapeError: wrong shape or dtype, NaN/inf, or no points.
    """
    true_pts, est_pts = _pose_inputs(R, t, R_hat, t_hat, points)
    return float(np.mean(np.linalg.norm(true_pts - est_pts, axis=1)))


def _nearest_distances(queries: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Distance from every query to its nearest reference point (chunked brute force, float64)."""
    ref_sq = np.einsum("ij,ij->i", reference, reference)
    chunk = max(1, _NN_CHUNK_ELEMENTS // max(1, reference.shape[0]))
    out = np.empty(queries.shape[0], dtype=np.float64)
    for start in range(0, queries.shape[0], chunk):
        q = queries[start : start + chunk]
        # squared distances up to rounding; pick the nearest, then measure it exactly
        d2 = np.einsum("ij,ij->i", q, q)[:, None] + ref_sq[None, :] - 2.0 * (q @ reference.T)
        nearest = np.argmin(d2, axis=1)
        out[start : start + chunk] = np.linalg.norm(q - reference[nearest], axis=1)
    return out


def add_s(
    R: np.ndarray, t: np.ndarray, R_hat: np.ndarray, t_hat: np.ndarray, points: np.ndarray
) -> float:
    """ADD-S: mean distance from each true-pose model point to the nearest estimated-pose point.

    For symmetric objects; ``add_s <= add`` always. Nearest neighbours by chunked brute force
    (O(N^2) time, bounded memory).

    Args and errors as :func:`add`.
    """
    true_pts, est_pts = _pose_inputs(R, t, R_hat, t_hat, points)
    return float(np.mean(_nearest_distances(true_pts, est_pts)))


def speed_score(
    R: np.ndarray,
    t: np.ndarray,
    R_hat: np.ndarray,
    t_hat: np.ndarray,
    *,
    apply_thresholds: bool = False,
    rotation_threshold_deg: float = SPEED_ROTATION_THRESHOLD_DEG,
    translation_threshold: float = SPEED_TRANSLATION_THRESHOLD,
) -> float:
    """SPEED/SPEED+ score of one pose: ``||t - t_hat|| / ||t|| + angle(R^T R_hat)`` (radians).

    The dataset score is the mean over frames. With ``apply_thresholds=True`` (SPNv2 practice,
    off by default) the translation term is set to 0 when below ``translation_threshold`` and the
    rotation term to 0 when the angle is below ``rotation_threshold_deg``.

    Args:
        R, R_hat: (3, 3) floating rotations (true, estimated).
        t, t_hat: (3,) floating translations (true, estimated); ``||t|| > 0``.

    Raises:
        ShapeError: wrong shape or dtype, or NaN/inf.
        ValueError: ``t`` is the zero vector.
    """
    R = _matrix3(R, "R")
    R_hat = _matrix3(R_hat, "R_hat")
    t = _vector3(t, "t")
    t_hat = _vector3(t_hat, "t_hat")
    distance = float(np.linalg.norm(t))
    if distance == 0.0:
        raise ValueError("speed_score needs a non-zero ground-truth translation t")
    score_t = float(np.linalg.norm(t - t_hat)) / distance
    score_r = _rotation_angle_rad(R, R_hat)
    if apply_thresholds:
        if score_t < translation_threshold:
            score_t = 0.0
        if score_r < math.radians(rotation_threshold_deg):
            score_r = 0.0
    return score_t + score_r
