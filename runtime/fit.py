"""Weighted least-squares rigid fit (Kabsch / Umeyama without scale), numpy only.

Paper Eq. (27): find (R, t) minimising sum_j w_j ||dst_j - (R src_j + t)||^2. Both point sets are
centred on their weighted centroids, R comes from the SVD of the weighted 3x3 cross-covariance with
the reflection fix (the last singular direction is flipped when det < 0, so det(R) = +1 always), and
t = c_dst - R c_src. Everything is computed in float64.

Bad *content* (too few points, NaN/inf, degenerate geometry, bad weights) is a normal outcome in the
flight path and gives a :class:`RigidFit` with ``valid=False`` and a status string; a wrong *shape*
is a programming error and raises :class:`~spacepose.errors.ShapeError`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spacepose._checks import check_real

__all__ = ["RigidFit", "fit_rigid", "STATUSES"]

#: Every status string :func:`fit_rigid` can return.
STATUSES = ("ok", "too_few_points", "non_finite", "bad_weights", "degenerate")

@dataclass(frozen=True)
class RigidFit:
    """A rigid transform with ``dst ≈ R @ src + t``.

    Attributes:
        R: (3, 3) float64 proper rotation (det = +1).
        t: (3,) float64 translation.
        valid: False when no fit could be made; then ``R`` and ``t`` are all-NaN arrays (so that
            nobody can use them by accident: any pose computed from them is NaN) and ``rms`` is NaN.
        status: ``"ok"`` or why the fit is invalid, one of :data:`STATUSES`:
            ``"too_few_points"`` (fewer than 3 points, or fewer than 3 with positive weight),
            ``"non_finite"`` (NaN/inf in src, dst or weights), ``"bad_weights"`` (a negative weight or
            a total weight <= 0), ``"degenerate"`` (src points coincident or (near-)collinear).
        rms: weighted RMS residual sqrt(sum w ||R src + t - dst||^2 / sum w), in the units of dst.
    """

    R: np.ndarray
    t: np.ndarray
    valid: bool
    status: str
    rms: float


def _invalid(status: str) -> RigidFit:
    return RigidFit(R=np.full((3, 3), np.nan), t=np.full(3, np.nan), valid=False, status=status,
                    rms=float("nan"))


def fit_rigid(
    src: np.ndarray,
    dst: np.ndarray,
    weights: np.ndarray | None = None,
    rel_tol: float = 1e-6,
) -> RigidFit:
    """Weighted least-squares rigid transform mapping ``src`` onto ``dst``.

    Args:
        src: (N, 3) points in the source frame (e.g. object-frame keypoints).
        dst: (N, 3) corresponding points in the destination frame (e.g. voted camera-frame keypoints).
        weights: optional (N,) non-negative weights (e.g. keypoint vote support); ``None`` = all 1.
            Points with weight 0 are ignored.
        rel_tol: the fit is ``"degenerate"`` when the second singular value of the weighted,
            centred ``src`` is <= ``rel_tol`` times the first (collinear), or the first is ~0
            relative to the coordinates' magnitude (coincident). Planar ``src`` is fine.

    Returns:
        :class:`RigidFit`; check ``valid`` (or ``status``) before using ``R`` and ``t``.

    Raises:
        ShapeError: ``src``/``dst`` not (N, 3) numeric, different N, or ``weights`` not (N,) numeric.
        ValueError: ``rel_tol`` not in [0, 1).
    """
    check_real(src, (None, 3), "src")
    check_real(dst, (src.shape[0], 3), "dst")
    if weights is not None:
        check_real(weights, (src.shape[0],), "weights")
    if not (0.0 <= rel_tol < 1.0):
        raise ValueError(f"rel_tol must be in [0, 1), got {rel_tol!r}")

    a = np.asarray(src, dtype=np.float64)
    b = np.asarray(dst, dtype=np.float64)
    w = np.ones(a.shape[0]) if weights is None else np.asarray(weights, dtype=np.float64)

    if a.shape[0] < 3:
        return _invalid("too_few_points")
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b)) and np.all(np.isfinite(w))):
        return _invalid("non_finite")
    if np.any(w < 0.0) or w.sum() <= 0.0:
        return _invalid("bad_weights")
    if np.count_nonzero(w) < 3:
        return _invalid("too_few_points")

    w = w / w.sum()
    c_a = w @ a
    c_b = w @ b
    a_c = a - c_a
    b_c = b - c_b

    sw = np.sqrt(w)[:, None]
    sv = np.linalg.svd(sw * a_c, compute_uv=False)
    scale = float(np.sqrt(w @ np.einsum("ij,ij->i", a, a)))  # weighted RMS norm of src
    if sv[0] <= 1e-12 * max(scale, np.finfo(np.float64).tiny) or sv[1] <= rel_tol * sv[0]:
        return _invalid("degenerate")

    h = (w[:, None] * a_c).T @ b_c  # 3x3 cross-covariance, src -> dst
    u, _, vt = np.linalg.svd(h)
    d = 1.0 if np.linalg.det(vt.T @ u.T) >= 0.0 else -1.0
    rot = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    trans = c_b - rot @ c_a
    resid = a @ rot.T + trans - b
    rms = float(np.sqrt(w @ np.einsum("ij,ij->i", resid, resid)))
    return RigidFit(R=rot, t=trans, valid=True, status="ok", rms=rms)
