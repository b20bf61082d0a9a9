"""Pose graph outputs -> votes -> MeanShift -> rigid fit -> pose, validity and confidence (numpy).

The pose graph predicts, for each of its N input points (camera frame, metres),

* ``seg_logits`` (1, N, 2): background / target logits;
* ``kp_offsets`` (1, M, N, 3): offset from the point to each of the M keypoints;
* ``ctr_offsets`` (1, N, 3): offset from the point to the object centre;

with ``offset = keypoint - point`` (``spacepose.pose_inputs``), so a vote is
``point + sign * offset`` with ``sign = +1`` (``PoseGraphConfig.offset_sign``).

:func:`solve_pose` follows FFB6D: centre votes of the target points are clustered first
(:func:`spacepose.voting.centre_first_inliers`); only the inliers vote for the keypoints
(:func:`spacepose.voting.vote_keypoints`); the model keypoints and centre are fitted to the voted
ones by weighted SVD (:func:`spacepose.fit.fit_rigid`, weights = vote support).

Bandwidth (:func:`voting_bandwidth`): ``h = max(bandwidth_fraction * diameter, k_sigma * sigma_Z)``
with the stereo depth noise ``sigma_Z = Z^2 * sigma_d / (f * B)`` at the target distance ``Z``.

Validity, checked in this order (the first failure is the status):

===================  ===================================================================
``bad_input``        a point or a graph output is NaN/inf for every point
``no_target``        no point is segmented as target
``too_few_points``   fewer than ``min_points`` target points, or centre inliers
``weak_votes``       centre cluster holds < ``min_cluster_fraction`` of the target points,
                     or fewer than ``min_keypoints`` keypoints hold >= ``min_keypoint_fraction``
                     support, or (after the checks below) the confidence is < ``min_confidence``
``fit_residual``     the fit failed, or its RMS residual exceeds ``max_fit_rms_factor * h``
``out_of_range``     the fitted distance ``||t||`` lies outside the bundle's distance range
                     widened by ``depth_margin`` (relative), or the fitted centre is farther
                     than the target radius from the voted centre
===================  ===================================================================

Confidence (in [0, 1]; 0 whenever ``valid`` is False)::

    confidence = c_cluster * c_keypoints * c_fit * c_points
    c_cluster   = centre inliers / target points
    c_keypoints = mean over keypoints of (keypoint support / centre inliers), clipped to [0, 1]
    c_fit       = exp(-(rms / h)^2)
    c_points    = min(1, centre inliers / (4 * min_points))

Each factor is 1 for a perfect frame: all target points agree on one centre, every inlier agrees
on every keypoint, the keypoints fit the model exactly, and there are plenty of points.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from .bundle import VotingConfig
from .errors import ShapeError, check_shape
from .fit import fit_rigid
from .pose_inputs import knn_indices
from .voting import centre_first_inliers, vote_keypoints

__all__ = ["POSE_STATUSES", "PoseStageResult", "voting_bandwidth", "depth_sigma", "solve_pose", "surface_fitness"]

logger = logging.getLogger(__name__)

#: every status the flight path can report (``"ok"`` = valid)
POSE_STATUSES = ("ok", "no_target", "too_few_points", "weak_votes", "fit_residual", "out_of_range", "bad_input")

_FLOAT = (np.floating,)


@dataclass(frozen=True, eq=False)
class PoseStageResult:
    """Outcome of :func:`solve_pose`.

    Attributes:
        R, t: pose (``X_cam = R @ X_obj + t``), float64; all-NaN when no fit could be made.
        valid, status, confidence: see the module docstring.
        n_target: points segmented as target; ``n_inliers``: centre-cluster inliers.
        centre: (3,) voted centre (NaN if none); ``keypoints`` (M, 3) voted keypoints (NaN rows for
            keypoints without votes); ``keypoint_support`` (M,) int.
        fit_rms: RMS residual of the fit (m, NaN if none); ``bandwidth``: the MeanShift bandwidth (m).
        factors: the confidence factors (``cluster``, ``keypoints``, ``fit``, ``points``); the estimator
            adds ``flip_margin`` when its flip stage ran (:mod:`spacepose.flip`), not a factor.
        fallback: ``(R, t)`` to report instead when the estimator's checks refuse ``R, t`` (a tracked
            pose refined against the outline falls back to the registered one), else ``None``.
        decided: ``(R, t)`` as decided, before the silhouette stage's polish moved it (the pose the
            next frame's tracking compares with, as its gates were set on), else ``None`` (``R, t``).
        position_pose: ``(R, t)`` whose centre is the estimator's position without a pose (the factors
            ``position_x`` .. ``position_z``; the outline's winner or the registered pose, moved as the position
            route moves it), else ``None``; the range fit of such a position reads its rotation.
    """

    R: np.ndarray
    t: np.ndarray
    valid: bool
    status: str
    confidence: float
    n_target: int = 0
    n_inliers: int = 0
    centre: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    keypoints: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    keypoint_support: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    fit_rms: float = float("nan")
    bandwidth: float = float("nan")
    factors: dict[str, float] = field(default_factory=dict)
    fallback: tuple[np.ndarray, np.ndarray] | None = None
    decided: tuple[np.ndarray, np.ndarray] | None = None
    position_pose: tuple[np.ndarray, np.ndarray] | None = None


def depth_sigma(depth_m: float, focal_px: float, baseline_m: float, sigma_d_px: float) -> float:
    """Stereo depth noise ``sigma_Z = Z^2 * sigma_d / (f * B)`` (f and sigma_d in the same pixels)."""
    return float(depth_m) ** 2 * float(sigma_d_px) / (float(focal_px) * float(baseline_m))


def voting_bandwidth(depth_m: float, diameter_m: float, config: VotingConfig, focal_px: float,
                     baseline_m: float, sigma_d_px: float | None = None) -> float:
    """MeanShift bandwidth (m): ``max(bandwidth_fraction * diameter, k_sigma * sigma_Z)``.

    ``sigma_d_px`` is the disparity noise in the pixels of ``focal_px``; default
    ``config.sigma_d_px`` (the estimator passes the graph-pixel noise divided by the window scale).
    """
    sigma_d = config.sigma_d_px if sigma_d_px is None else sigma_d_px
    size_term = config.bandwidth_fraction * float(diameter_m)
    noise_term = config.k_sigma * depth_sigma(depth_m, focal_px, baseline_m, sigma_d)
    return float(max(size_term, noise_term))


def _invalid(status: str, **extra: object) -> PoseStageResult:
    return PoseStageResult(R=np.full((3, 3), np.nan), t=np.full(3, np.nan), valid=False, status=status,
                           confidence=0.0, **extra)  # type: ignore[arg-type]


def _squeeze_batch(array: np.ndarray, shape: tuple[int | None, ...], name: str) -> np.ndarray:
    if isinstance(array, np.ndarray) and array.ndim == len(shape) + 1 and array.shape[0] == 1:
        array = array[0]
    return check_shape(array, shape, name, dtypes=_FLOAT)


def solve_pose(
    points: np.ndarray,
    seg_logits: np.ndarray,
    kp_offsets: np.ndarray,
    ctr_offsets: np.ndarray,
    model_keypoints: np.ndarray,
    model_centre: np.ndarray,
    *,
    config: VotingConfig,
    diameter_m: float,
    distance_range_m: tuple[float, float],
    focal_px: float,
    baseline_m: float,
    sigma_d_px: float | None = None,
    offset_sign: int = 1,
    seed: int = 0,
) -> PoseStageResult:
    """Pose of the target from the pose graph's outputs for ``points``.

    Args:
        points: (N, 3) camera-frame points (m) that were fed to the pose graph.
        seg_logits: (1, N, 2) or (N, 2); ``kp_offsets`` (1, M, N, 3) or (M, N, 3);
            ``ctr_offsets`` (1, N, 3) or (N, 3) — the graph outputs (metres).
        model_keypoints: (M, 3) object-frame keypoints; ``model_centre`` (3,) object-frame centre.
        config: bandwidth rule and thresholds (``ModelBundle.voting``).
        diameter_m: target bounding-sphere diameter (m).
        distance_range_m: (near, far) distances the bundle was trained for.
        focal_px, baseline_m: rectified rig numbers for the depth-noise term.
        sigma_d_px: disparity noise in the pixels of ``focal_px`` (default ``config.sigma_d_px``).
        offset_sign: ``vote = point + offset_sign * offset``.
        seed: MeanShift seed subset (deterministic result per seed).

    Returns:
        :class:`PoseStageResult`; a content problem gives ``valid=False`` with a status.

    Raises:
        ShapeError: arrays of the wrong shape or dtype (programming errors).
    """
    check_shape(points, (None, 3), "points", dtypes=_FLOAT)
    n = points.shape[0]
    seg = _squeeze_batch(seg_logits, (n, None), "seg_logits")
    kp = _squeeze_batch(kp_offsets, (None, n, 3), "kp_offsets")
    ctr = _squeeze_batch(ctr_offsets, (n, 3), "ctr_offsets")
    check_shape(model_keypoints, (kp.shape[0], 3), "model_keypoints", dtypes=_FLOAT)
    check_shape(model_centre, (3,), "model_centre", dtypes=_FLOAT)
    if seg.shape[1] < 2:
        raise ShapeError(f"seg_logits needs >= 2 classes, got {seg.shape[1]}")
    if offset_sign not in (1, -1):
        raise ValueError(f"offset_sign must be 1 or -1, got {offset_sign!r}")

    pts = np.asarray(points, dtype=np.float64)
    finite = (np.all(np.isfinite(pts), axis=1) & np.all(np.isfinite(seg), axis=1)
              & np.all(np.isfinite(ctr), axis=1) & np.all(np.isfinite(kp), axis=(0, 2)))
    if n == 0 or not finite.any():
        return _invalid("bad_input")

    # segmentation: softmax probability of class 1 (target) above the threshold
    logits = np.asarray(seg[:, :2], dtype=np.float64)
    logit_margin = logits[:, 1] - logits[:, 0]
    threshold = math.log(config.seg_threshold / (1.0 - config.seg_threshold))
    target = finite & (logit_margin > threshold)
    n_target = int(target.sum())
    if n_target == 0:
        return _invalid("no_target")
    if n_target < config.min_points:
        return _invalid("too_few_points", n_target=n_target)

    sign = float(offset_sign)
    tgt_pts = pts[target]
    ctr_votes = tgt_pts + sign * np.asarray(ctr[target], dtype=np.float64)
    kp_votes = tgt_pts[None] + sign * np.asarray(kp[:, target], dtype=np.float64)

    depth = float(np.median(tgt_pts[:, 2]))
    h = voting_bandwidth(max(depth, 1e-6), diameter_m, config, focal_px, baseline_m, sigma_d_px)
    kw = dict(kernel=config.kernel, n_seeds=config.n_seeds, seed=seed)
    centre, inliers, n_inliers = centre_first_inliers(ctr_votes, h, **kw)
    base = dict(n_target=n_target, n_inliers=n_inliers, centre=centre, bandwidth=h)
    if n_inliers < config.min_points:
        return _invalid("too_few_points", **base)
    cluster_fraction = n_inliers / n_target
    if cluster_fraction < config.min_cluster_fraction:
        return _invalid("weak_votes", **base)

    voted = vote_keypoints(kp_votes, inliers, h, **kw)
    kp_fraction = voted.support / float(n_inliers)
    base.update(keypoints=voted.keypoints, keypoint_support=voted.support)
    strong = np.isfinite(voted.keypoints).all(axis=1) & (kp_fraction >= config.min_keypoint_fraction)
    if int(strong.sum()) < max(3, config.min_keypoints):
        return _invalid("weak_votes", **base)

    src = np.vstack([np.asarray(model_keypoints, dtype=np.float64)[strong], np.asarray(model_centre, dtype=np.float64)])
    dst = np.vstack([voted.keypoints[strong], centre])
    weights = np.append(kp_fraction[strong], cluster_fraction)
    fit = fit_rigid(src, dst, weights=weights)
    base["fit_rms"] = fit.rms
    if not fit.valid or not fit.rms <= config.max_fit_rms_factor * h:
        logger.debug("pose fit rejected: status=%s rms=%.3f bandwidth=%.3f", fit.status, fit.rms, h)
        return _invalid("fit_residual", **base)

    near, far = distance_range_m
    distance = float(np.linalg.norm(fit.t))
    fitted_centre = fit.R @ np.asarray(model_centre, dtype=np.float64) + fit.t
    if (not near * (1.0 - config.depth_margin) <= distance <= far * (1.0 + config.depth_margin)
            or np.linalg.norm(fitted_centre - centre) > 0.5 * diameter_m):
        return PoseStageResult(R=fit.R, t=fit.t, valid=False, status="out_of_range", confidence=0.0, **base)

    factors = {
        "cluster": float(np.clip(cluster_fraction, 0.0, 1.0)),
        "keypoints": float(np.clip(np.nan_to_num(kp_fraction), 0.0, 1.0).mean()),
        "fit": float(math.exp(-((fit.rms / h) ** 2))),
        "points": float(min(1.0, n_inliers / (4.0 * config.min_points))),
    }
    confidence = float(np.clip(np.prod(list(factors.values())), 0.0, 1.0))
    if confidence < config.min_confidence:
        logger.debug("pose rejected: confidence %.3f < %.3f", confidence, config.min_confidence)
        return _invalid("weak_votes", factors=factors, **base)
    return PoseStageResult(R=fit.R, t=fit.t, valid=True, status="ok", confidence=confidence,
                           factors=factors, **base)


def surface_fitness(R: np.ndarray, t: np.ndarray, points: np.ndarray, surface: np.ndarray, tolerance: float) -> float:
    """Share of ``points`` (N, 3, camera frame) within ``tolerance`` metres of the target's surface.

    ``surface`` (S, 3) are object-frame surface samples, placed by the pose ``X = R s + t``. A
    correct pose puts the observed target points on the surface (fitness near 1, less the stereo
    outliers); a wrong one leaves most of them off it. Nearest samples by :func:`knn_indices` (exact).
    """
    check_shape(points, (None, 3), "points")
    check_shape(surface, (None, 3), "surface")
    if len(points) == 0 or len(surface) == 0 or not np.all(np.isfinite(R)) or not np.all(np.isfinite(t)):
        return 0.0
    placed = np.asarray(surface, dtype=np.float64) @ np.asarray(R, dtype=np.float64).T + np.asarray(t, dtype=np.float64)
    pts = np.asarray(points, dtype=np.float64)
    nearest = knn_indices(pts, placed, 1)[:, 0]
    d2 = np.einsum("ij,ij->i", pts - placed[nearest], pts - placed[nearest])
    return float(np.count_nonzero(d2 <= float(tolerance) ** 2)) / float(len(pts))
