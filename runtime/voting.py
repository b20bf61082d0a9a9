"""Seeded non-blurring mean shift and FFB6D's centre-first keypoint voting (numpy only).

FFB6D (and PVN3D) turn per-point offset predictions into votes (vote = point - offset) and cluster
them with mean shift: first the votes for the object centre, whose winning cluster decides which
points are inliers, then, using only those inliers, the votes for each keypoint.

FFB6D's released ``MeanShiftTorch`` is a *blurring* N x N variant (every point moves, every
iteration costs N^2). Here the points stay fixed and only a few seeds move (non-blurring mean
shift, as in scikit-learn): each iteration costs one (seeds x points) distance matrix, and seeds
that have converged are masked out of later iterations.

Kernels (``bandwidth`` is ``h``):

* ``"flat"``: a seed moves to the mean of the points within distance ``h`` (scikit-learn's kernel).
* ``"gaussian"``: a seed moves to the mean of all points weighted by ``exp(-d^2 / (2 h^2))``.

For both kernels a mode's *support* is the number of points within distance ``h`` of it, modes
closer than ``h`` to a mode with more support are merged into it, and a point's *label* is the
index of its nearest mode within ``h`` (``-1`` if none).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from spacepose._checks import check_real
from spacepose.errors import ShapeError, check_shape

__all__ = [
    "KERNELS",
    "MeanShiftResult",
    "CentreInliers",
    "KeypointVotes",
    "mean_shift",
    "centre_first_inliers",
    "vote_keypoints",
]

logger = logging.getLogger(__name__)

KERNELS = ("flat", "gaussian")

@dataclass(frozen=True)
class MeanShiftResult:
    """Modes found by :func:`mean_shift`.

    Attributes:
        modes: (K, D) float64, sorted by ``support`` descending (K >= 1).
        support: (K,) int64, number of finite points within ``bandwidth`` of each mode.
        labels: (N,) int64, per input point the index of its nearest mode within ``bandwidth``,
            ``-1`` when no mode is that close or the point had a NaN/inf coordinate.
        n_iter: number of mean-shift iterations run (until all seeds converged or ``max_iter``).
        converged: whether every seed converged before ``max_iter``.
    """

    modes: np.ndarray
    support: np.ndarray
    labels: np.ndarray
    n_iter: int
    converged: bool


class CentreInliers(NamedTuple):
    """Result of :func:`centre_first_inliers`.

    Attributes:
        centre: (3,) float64, the winning (most supported) mode of the centre votes.
        inliers: (N,) bool, points whose centre vote lies within ``bandwidth`` of ``centre``.
        support: number of inliers (``inliers.sum()``).
    """

    centre: np.ndarray
    inliers: np.ndarray
    support: int


class KeypointVotes(NamedTuple):
    """Result of :func:`vote_keypoints`.

    Attributes:
        keypoints: (M, 3) float64, the winning mode of each keypoint's votes; a row is NaN when
            every inlier vote for that keypoint was NaN/inf.
        support: (M,) int64, inlier votes within ``bandwidth`` of each keypoint (0 for a NaN row).
    """

    keypoints: np.ndarray
    support: np.ndarray


def _check_bandwidth(bandwidth: float) -> float:
    try:
        h = float(bandwidth)
    except (TypeError, ValueError) as err:
        raise ValueError(f"bandwidth must be a positive number, got {bandwidth!r}") from err
    if not np.isfinite(h) or h <= 0.0:
        raise ValueError(f"bandwidth must be a positive finite number, got {bandwidth!r}")
    return h


def _squared_distances(a: np.ndarray, b: np.ndarray, b_sq: np.ndarray) -> np.ndarray:
    """(len(a), len(b)) squared Euclidean distances; ``b_sq`` = row-wise squared norms of ``b``."""
    d2 = np.einsum("ij,ij->i", a, a)[:, None] + b_sq[None, :] - 2.0 * (a @ b.T)
    np.maximum(d2, 0.0, out=d2)  # round-off can make tiny negatives
    return d2


def mean_shift(
    points: np.ndarray,
    bandwidth: float,
    kernel: str = "flat",
    n_seeds: int | None = 32,
    seed: int = 0,
    max_iter: int = 300,
    tol: float = 1e-3,
    seeds: np.ndarray | None = None,
) -> MeanShiftResult:
    """Seeded non-blurring mean shift of ``points``.

    Rows holding NaN or inf are dropped before clustering (they get label ``-1``).

    Args:
        points: (N, D) float or int array.
        bandwidth: kernel radius ``h`` (flat) or standard deviation (gaussian), > 0, in the units of
            ``points``; also the merge distance and the support/label radius.
        kernel: ``"flat"`` or ``"gaussian"``.
        n_seeds: number of seeds drawn without replacement from the finite points with
            ``numpy.random.default_rng(seed)``; all points when ``None`` or when there are fewer
            finite points than ``n_seeds``. Ignored when ``seeds`` is given.
        seed: RNG seed of the seed subset (the result is deterministic for a given seed).
        max_iter: maximum number of iterations (>= 1).
        tol: a seed has converged when it moves by at most ``tol * bandwidth`` in one iteration
            (scikit-learn's stop threshold is ``1e-3 * bandwidth``).
        seeds: optional (S, D) start positions; seeds with no point within reach (flat: none within
            ``h``; gaussian: all weights underflow) are dropped.

    Returns:
        :class:`MeanShiftResult` with the modes sorted by support, descending.

    Raises:
        ShapeError: ``points`` / ``seeds`` not 2-D numeric arrays of matching width, ``points`` has no
            finite row, or no seed reaches any point.
        ValueError: ``bandwidth`` <= 0 or non-finite, unknown ``kernel``, or a bad ``n_seeds``,
            ``max_iter`` or ``tol``.
    """
    check_real(points, (None, None), "points")
    h = _check_bandwidth(bandwidth)
    if kernel not in KERNELS:
        raise ValueError(f"unknown kernel {kernel!r}; valid kernels: {', '.join(KERNELS)}")
    if int(max_iter) < 1:
        raise ValueError(f"max_iter must be >= 1, got {max_iter!r}")
    if not (np.isfinite(tol) and tol >= 0.0):
        raise ValueError(f"tol must be a finite number >= 0, got {tol!r}")
    if points.shape[1] == 0:
        raise ShapeError("points must have at least one coordinate column, got shape "
                         f"{tuple(points.shape)}")

    pts_all = np.asarray(points, dtype=np.float64)
    finite = np.all(np.isfinite(pts_all), axis=1)
    pts = pts_all[finite]
    n = pts.shape[0]
    if n == 0:
        raise ShapeError(f"points has no finite rows (shape {tuple(points.shape)})")

    if seeds is not None:
        check_real(seeds, (None, pts.shape[1]), "seeds")
        start = np.asarray(seeds, dtype=np.float64)
        if start.shape[0] == 0 or not np.all(np.isfinite(start)):
            raise ShapeError("seeds must hold at least one row and be finite")
    else:
        if n_seeds is not None and int(n_seeds) < 1:
            raise ValueError(f"n_seeds must be >= 1 or None, got {n_seeds!r}")
        if n_seeds is None or int(n_seeds) >= n:
            start = pts
        else:
            rng = np.random.default_rng(seed)
            start = pts[np.sort(rng.choice(n, size=int(n_seeds), replace=False))]

    # Work relative to the centroid: the |a|^2 + |b|^2 - 2ab distance expansion then loses no
    # precision when the votes are far from the origin (a target tens of metres away).
    offset = pts.mean(axis=0)
    pts = pts - offset
    modes, n_iter, converged = _shift_seeds(pts, start - offset, h, kernel, int(max_iter), float(tol))
    if modes.shape[0] == 0:
        raise ShapeError("no seed has any point within reach of the bandwidth")
    modes, support = _merge_modes(pts, modes, h)

    labels = np.full(pts_all.shape[0], -1, dtype=np.int64)
    d2 = _squared_distances(pts, modes, np.einsum("ij,ij->i", modes, modes))
    nearest = np.argmin(d2, axis=1)
    close = d2[np.arange(n), nearest] <= h * h
    labels[np.flatnonzero(finite)] = np.where(close, nearest, -1)
    return MeanShiftResult(modes=modes + offset, support=support, labels=labels, n_iter=n_iter,
                           converged=converged)


def _shift_seeds(pts: np.ndarray, start: np.ndarray, h: float, kernel: str, max_iter: int,
                 tol: float) -> tuple[np.ndarray, int, bool]:
    """Move seeds to their modes; converged seeds are frozen. Returns (modes, n_iter, converged)."""
    pts_sq = np.einsum("ij,ij->i", pts, pts)
    current = start
    alive = np.ones(current.shape[0], dtype=bool)   # False: dropped (no point within reach)
    active = np.ones(current.shape[0], dtype=bool)  # still moving
    h2 = h * h
    stop = (tol * h) ** 2
    n_iter = 0
    while n_iter < max_iter and active.any():
        n_iter += 1
        idx = np.flatnonzero(active)
        d2 = _squared_distances(current[idx], pts, pts_sq)
        if kernel == "flat":
            weight = (d2 <= h2).astype(np.float64)
        else:
            weight = np.exp(d2 * (-0.5 / h2))
        total = weight.sum(axis=1)
        empty = total <= 0.0
        if empty.any():
            alive[idx[empty]] = False
            active[idx[empty]] = False
            idx, weight, total = idx[~empty], weight[~empty], total[~empty]
        new = (weight @ pts) / total[:, None]
        moved = np.einsum("ij,ij->i", new - current[idx], new - current[idx])
        current[idx] = new
        active[idx[moved <= stop]] = False
    converged = not active.any()
    if not converged:
        logger.debug("mean shift: %d of %d seeds did not converge in %d iterations",
                     int(active.sum()), len(active), max_iter)
    return current[alive], n_iter, converged


def _merge_modes(pts: np.ndarray, modes: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Greedy suppression: by support descending, drop modes within ``h`` of a kept mode."""
    pts_sq = np.einsum("ij,ij->i", pts, pts)
    support = (_squared_distances(modes, pts, pts_sq) <= h * h).sum(axis=1).astype(np.int64)
    order = np.argsort(-support, kind="stable")
    modes, support = modes[order], support[order]
    mode_d2 = _squared_distances(modes, modes, np.einsum("ij,ij->i", modes, modes))
    keep = np.ones(len(modes), dtype=bool)
    for i in range(len(modes)):
        if keep[i]:
            dup = mode_d2[i] <= h * h
            dup[: i + 1] = False
            keep[dup] = False
    return modes[keep], support[keep]


def centre_first_inliers(
    centre_votes: np.ndarray,
    bandwidth: float,
    kernel: str = "gaussian",
    n_seeds: int | None = 16,
    seed: int = 0,
    max_iter: int = 300,
    tol: float = 1e-3,
) -> CentreInliers:
    """FFB6D's centre-first filter: the winning mode of the centre votes and the points voting for it.

    Args:
        centre_votes: (N, 3) per-point votes for the object centre (point - predicted offset);
            rows with NaN/inf are never inliers.
        bandwidth: mean-shift bandwidth and inlier radius (metres). Scale it with the object size and
            the stereo depth noise; FFB6D's 0.04 m is for 10-30 cm objects.
        kernel, n_seeds, seed, max_iter, tol: as in :func:`mean_shift` (defaults: FFB6D's Gaussian
            kernel, 16 seeds).

    Returns:
        :class:`CentreInliers` (``centre`` (3,), ``inliers`` (N,) bool, ``support`` int); unpacks as a
        tuple ``centre, inliers, support = centre_first_inliers(...)``.

    Raises:
        ShapeError: ``centre_votes`` is not (N, 3) numeric or has no finite row.
        ValueError: bad ``bandwidth`` or other parameters (see :func:`mean_shift`).
    """
    check_real(centre_votes, (None, 3), "centre_votes")
    result = mean_shift(centre_votes, bandwidth, kernel=kernel, n_seeds=n_seeds, seed=seed,
                        max_iter=max_iter, tol=tol)
    centre = result.modes[0]
    votes = np.asarray(centre_votes, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        inliers = np.sum((votes - centre) ** 2, axis=1) <= float(bandwidth) ** 2
    return CentreInliers(centre=centre.copy(), inliers=inliers, support=int(inliers.sum()))


def vote_keypoints(
    kp_votes: np.ndarray,
    inliers: np.ndarray,
    bandwidth: float,
    kernel: str = "gaussian",
    n_seeds: int | None = 16,
    seed: int = 0,
    max_iter: int = 300,
    tol: float = 1e-3,
) -> KeypointVotes:
    """Keypoints as the winning mean-shift mode of the inliers' votes, one keypoint at a time.

    Args:
        kp_votes: (M, N, 3) votes of the N points for the M keypoints.
        inliers: (N,) bool, the points allowed to vote (from :func:`centre_first_inliers`).
        bandwidth, kernel, n_seeds, seed, max_iter, tol: as in :func:`mean_shift`.

    Returns:
        :class:`KeypointVotes` (``keypoints`` (M, 3) float64, ``support`` (M,) int64). A keypoint
        whose inlier votes are all NaN/inf comes back as a NaN row with support 0 (drop it, or give it
        zero weight, before :func:`spacepose.fit.fit_rigid`).

    Raises:
        ShapeError: wrong shapes/dtypes, or ``inliers`` selects no point.
        ValueError: bad ``bandwidth`` or other parameters (see :func:`mean_shift`).
    """
    check_real(kp_votes, (None, None, 3), "kp_votes")
    check_shape(inliers, (kp_votes.shape[1],), "inliers", dtypes=(np.bool_,))
    _check_bandwidth(bandwidth)
    if not inliers.any():
        raise ShapeError("inliers selects no point; nothing can vote for the keypoints")
    votes = np.asarray(kp_votes, dtype=np.float64)[:, inliers]
    n_kp = votes.shape[0]
    keypoints = np.full((n_kp, 3), np.nan)
    support = np.zeros(n_kp, dtype=np.int64)
    for j in range(n_kp):
        if not np.any(np.all(np.isfinite(votes[j]), axis=1)):
            logger.debug("vote_keypoints: keypoint %d has no finite vote", j)
            continue
        result = mean_shift(votes[j], bandwidth, kernel=kernel, n_seeds=n_seeds, seed=seed,
                            max_iter=max_iter, tol=tol)
        keypoints[j] = result.modes[0]
        support[j] = result.support[0]
    return KeypointVotes(keypoints=keypoints, support=support)
