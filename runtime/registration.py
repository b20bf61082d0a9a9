"""Multi-start registration of the target's surface to the stereo points (numpy only).

The pose network's orientation is a seed, not the answer: point-to-plane ICP only converges from
within a few tens of degrees, so :func:`register` runs it from many starts at once — the network's
pose and its 180° flip (when given) plus a fixed, well-spread set of orientations — and scores
every converged pose by the truncated point-to-surface cost of the stereo points,
``score = mean(min(d, tau)^2) / tau^2`` in [0, 1] (lower is better), ``d`` the distance of a
stereo point to the nearest surface sample at the pose, ``tau`` the depth tolerance of the frame.

The best pose is returned with the score of the best *distinct* alternative (more than
``distinct_deg`` away in orientation): the gap between the two is the evidence that the kept pose
and not, say, its 180° flip about the target's near-symmetry axis is the one the data show.
(A free-space term — surface the pose puts where the stereo data see nothing — was tried as a
second score in session 7 and made the flip decision worse: 7 of the first 16 test frames came out
flipped with it, 3 without (an exploratory script, not kept). The stereo graph's holes and
fattened outline are not clean enough evidence of empty space.)

Nearest surface samples come from :class:`SurfaceLookup`, a voxel grid in the object frame filled
once per bundle (each cell holds its nearest sample within ``reach``), so one ICP iteration over all
starts is a gather, not a nearest-neighbour search.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .errors import check_shape

__all__ = ["RegistrationConfig", "SurfaceLookup", "SurfaceModel", "RegistrationResult", "start_rotations", "register",
           "select_with_prior", "near_prior", "rotation_angle_deg", "exp_so3", "cross_into"]


@dataclass(frozen=True)
class RegistrationConfig:
    """Settings of :func:`register` (bundle ``registration`` section).

    starts: orientations tried besides the seeds (:func:`start_rotations`).
    iterations: coarse ICP iterations per start, on ``coarse_points`` stereo points; the pairing
        distance shrinks from ``reach_start_m`` by ``reach_decay`` per iteration down to
        ``max(reach_min_m, 2 * tau)``.
    refine_top, fine_iterations: the best ``refine_top`` starts after the coarse iterations get
        ``fine_iterations`` more on ``max_points`` stereo points; they are scored on those.
    max_points, coarse_points: stereo points used (fixed-seed subsamples).
    sigma_d_px: disparity noise in stereo-graph input pixels behind the frame's depth tolerance
        ``tau = max(tau_min_m, Z^2 sigma_d / (f B))`` (the estimator divides it by the window's
        scale, net px per full-frame px, to get pixels of ``f``).
    distinct_deg: an alternative pose counts as distinct beyond this orientation difference.
    min_margin: least ``margin`` (runner-up score minus best score) for a valid pose: below it the
        data do not say which of the two poses it is (``weak_votes``).
    min_inlier_fraction: least share of the stereo points within ``tau`` of the surface at the
        kept pose (``fit_residual`` below it).
    max_tau_m: the largest depth tolerance at which a margin can decide the pose. The target's flip
        about its near-symmetry axis moves only small parts of it (on ``tdrs`` 4.3 % of the surface
        by more than 10 cm, at most 0.9 m: ``python -m spacepose.tools.flip_relief``), so with a
        coarser depth the margin measures the noise, not the target: beyond it a frame is undecided
        whatever its margin (tracking may still decide it).
    track_max_deg, track_max_m: with a valid pose of the previous frame (the estimator's prior), a
        frame whose margin is too small is still decided when exactly one of the best pose and its
        runner-up lies within this rotation and translation of that prior (:func:`select_with_prior`):
        the target cannot have turned half round between two frames.
    position_max_tau_m: a frame registered but left undecided between the pose and its flip
        (``weak_votes``) still reports the target centre's position (``PoseResult.position_valid``)
        when its depth tolerance ``tau`` is at most this; 0: only a valid pose reports a position.
        The flip leaves the centre in place, so the position does not depend on the flip; ``tau``
        bounds its error (session 25: model card, "Target position without attitude").
    position_lateral: 1: where that position comes from the registered pose (the outline's best fit is
        looser than ``silhouette.max_chamfer_px``), move it parallel to the image plane so that the
        registered pose's outline centroid lands on the observed outline's
        (:func:`spacepose.silhouette.align_centroid`); 0: the registered pose's centre as it is.
    position_max_chamfer_px: with ``position_max_tau_m``, such a frame also needs an outline stage whose best fit
        is within this chamfer (outline px); 0: no outline gate. A registration whose outline fits this badly
        can be wrong in range by metres where ``tau`` says under 1 m (session 26, model card).
    position_range_bias_outline, position_range_bias_registered: such a position is moved towards the camera,
        along its line of sight, by this many depth tolerances ``tau``, when it comes from the outline's best fit
        and from the registered pose respectively; 0: not moved. The stereo graph reads the target's disparity
        low by a fraction of a pixel, so the stereo points, and the ranges fitted to them, lie too far by a
        share of ``tau`` (which scales with the depth a disparity pixel spans; session 32, model card).
    """

    starts: int = 48
    iterations: int = 10
    fine_iterations: int = 8
    max_points: int = 800
    coarse_points: int = 300
    reach_start_m: float = 1.6
    reach_decay: float = 0.75
    reach_min_m: float = 0.15
    tau_min_m: float = 0.1
    sigma_d_px: float = 1.0
    distinct_deg: float = 30.0
    refine_top: int = 8
    seed: int = 0
    min_margin: float = 0.01
    min_inlier_fraction: float = 0.5
    max_tau_m: float = 1e9
    track_max_deg: float = 20.0
    track_max_m: float = 1.0
    position_max_tau_m: float = 0.0
    position_lateral: int = 0
    position_max_chamfer_px: float = 0.0
    position_range_bias_outline: float = 0.0
    position_range_bias_registered: float = 0.0


def rotation_angle_deg(R_a: np.ndarray, R_b: np.ndarray) -> np.ndarray:
    """Angle(s) of ``R_a^T R_b`` in degrees; broadcasts over leading axes of (..., 3, 3)."""
    tr = np.einsum("...ji,...ji->...", R_a, R_b)
    return np.degrees(np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0)))


def start_rotations(n: int, seed: int = 0) -> np.ndarray:
    """(n, 3, 3) orientations spread over SO(3): quaternions on a super-Fibonacci spiral (Alexa 2022),
    deterministic, no clustering; ``seed`` rotates the whole set."""
    if n < 1:
        return np.zeros((0, 3, 3))
    i = np.arange(n, dtype=np.float64) + 0.5
    phi, psi = math.sqrt(2.0), 1.533751168755204288118041
    s = i / n
    r, R_ = np.sqrt(s), np.sqrt(1.0 - s)
    alpha, beta = 2.0 * math.pi * i / phi, 2.0 * math.pi * i / psi
    q = np.stack([r * np.sin(alpha), r * np.cos(alpha), R_ * np.sin(beta), R_ * np.cos(beta)], axis=1)
    rots = _quat_to_matrix(q)
    if seed:
        rng = np.random.default_rng(seed)
        g = _quat_to_matrix(rng.normal(size=(1, 4)))[0]
        rots = g @ rots
    return rots


def _quat_to_matrix(q: np.ndarray) -> np.ndarray:
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], -2)


def exp_so3(w: np.ndarray) -> np.ndarray:
    """(..., 3) rotation vectors -> (..., 3, 3) (Rodrigues)."""
    angle = np.linalg.norm(w, axis=-1, keepdims=True)
    k = w / np.maximum(angle, 1e-12)
    K = np.zeros(k.shape + (3,), dtype=k.dtype)                          # the skew matrix of k
    K[..., 0, 1], K[..., 0, 2] = -k[..., 2], k[..., 1]
    K[..., 1, 0], K[..., 1, 2] = k[..., 2], -k[..., 0]
    K[..., 2, 0], K[..., 2, 1] = -k[..., 1], k[..., 0]
    a = angle[..., None]
    return np.eye(3) + np.sin(a) * K + (1.0 - np.cos(a)) * (K @ K)


class SurfaceLookup:
    """Nearest surface sample of object-frame points, read from a voxel grid.

    Each cell of a grid of pitch ``cell_m`` over the samples' bounding box widened by ``reach_m``
    holds the index of the sample nearest to the cell centre, if one lies within ``reach_m`` of it
    (else -1). :meth:`query` returns that sample and the exact distance to it; beyond the grid or
    the reach a point has no neighbour (index -1, distance inf). The sample found is the nearest
    to the cell centre, so it is within ``cell_m * sqrt(3)`` of being the nearest to the point.

    Args:
        points: (S, 3) surface samples; normals: (S, 3) their unit normals (sign irrelevant).
    """

    def __init__(self, points: np.ndarray, normals: np.ndarray, cell_m: float, reach_m: float) -> None:
        check_shape(points, (None, 3), "points")
        check_shape(normals, (len(points), 3), "normals")
        if len(points) == 0:
            raise ValueError("SurfaceLookup needs at least one surface sample")
        if not (cell_m > 0 and reach_m > 0):
            raise ValueError(f"cell_m and reach_m must be > 0, got {cell_m}, {reach_m}")
        self.points = np.ascontiguousarray(points, dtype=np.float64)
        self.normals = np.ascontiguousarray(normals, dtype=np.float64)
        self.cell = float(cell_m)
        self.reach = float(reach_m)
        self.origin = self.points.min(axis=0) - self.reach
        self.shape = tuple(int(v) for v in np.ceil((self.points.max(axis=0) + self.reach - self.origin) / self.cell) + 1)
        self.grid = self._fill()
        self._flat = self.grid.reshape(-1)
        self._samples = np.concatenate([self.points, self.normals], axis=1)   # (M, 6): one gather for both

    def _fill(self) -> np.ndarray:
        r = int(math.ceil(self.reach / self.cell))
        offs = np.stack(np.meshgrid(*([np.arange(-r, r + 1)] * 3), indexing="ij"), -1).reshape(-1, 3)
        home = np.round((self.points - self.origin) / self.cell).astype(np.int64)
        shape = np.array(self.shape)
        best_d2 = np.full(int(np.prod(shape)), np.inf)
        best_i = np.full(int(np.prod(shape)), -1, dtype=np.int64)
        chunk = max(1, 2_000_000 // len(offs))
        for s0 in range(0, len(self.points), chunk):
            cells = home[s0:s0 + chunk, None, :] + offs[None]                      # (c, O, 3)
            ok = np.all((cells >= 0) & (cells < shape), axis=-1)
            centres = self.origin + cells * self.cell
            d2 = np.sum((centres - self.points[s0:s0 + chunk, None, :]) ** 2, axis=-1)
            ok &= d2 <= self.reach ** 2
            flat = np.ravel_multi_index(tuple(cells[ok].T), self.shape)
            idx = np.broadcast_to(np.arange(s0, s0 + len(cells))[:, None], ok.shape)[ok]
            d2 = d2[ok]
            # one sort on (cell, quantised distance) packed in an int64: nearest first within each cell
            key = flat * (1 << 24) + np.minimum(d2 / self.reach ** 2 * ((1 << 24) - 1), (1 << 24) - 1).astype(np.int64)
            order = np.argsort(key, kind="stable")
            flat, idx, d2 = flat[order], idx[order], d2[order]
            first = np.ones(len(flat), dtype=bool)
            first[1:] = flat[1:] != flat[:-1]
            flat, idx, d2 = flat[first], idx[first], d2[first]
            better = d2 < best_d2[flat]
            best_d2[flat[better]] = d2[better]
            best_i[flat[better]] = idx[better]
        return best_i.reshape(self.shape)

    def query(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(..., 3) object-frame points -> (index (...,) int64, -1 for none; distance (...,), inf for none)."""
        idx, _, _, dist = self.lookup(X)
        return idx, dist

    def lookup(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`query` with what it gathered on the way: ``(index, sample (..., 3), its normal
        (..., 3), distance)``; the sample and normal of index 0 where the index is -1."""
        cells = np.rint((X - self.origin) * (1.0 / self.cell)).astype(np.int64)
        s0, s1, s2 = self.shape
        u = cells.view(np.uint64)   # one unsigned comparison per axis: a negative cell wraps to a huge one
        inside = (u[..., 0] < s0) & (u[..., 1] < s1) & (u[..., 2] < s2)
        flat = (cells[..., 0] * s1 + cells[..., 1]) * s2 + cells[..., 2]
        idx = self._flat[np.where(inside, flat, 0)]
        idx[~inside] = -1
        both = np.take(self._samples, np.maximum(idx, 0), axis=0)
        sample = both[..., :3]
        diff = X - sample
        dist = np.sqrt(np.einsum("...i,...i->...", diff, diff))
        return idx, sample, both[..., 3:], np.where(idx >= 0, dist, np.inf)


class SurfaceModel:
    """The target's surface samples in the two lookups :func:`register` reads.

    ``coarse``: every ``coarse_stride``-th sample on a ``coarse_cell_m`` grid reaching
    ``coarse_reach_m`` (the first, wide-reaching ICP iterations and far targets); ``fine``: all
    samples on a ``fine_cell_m`` grid reaching ``fine_reach_m``. ``extent_m``: the samples' largest
    bounding-box side.
    """

    def __init__(self, points: np.ndarray, normals: np.ndarray, *, coarse_cell_m: float = 0.25,
                 coarse_reach_m: float = 2.0, coarse_stride: int = 10, fine_cell_m: float = 0.05,
                 fine_reach_m: float = 0.2) -> None:
        check_shape(points, (None, 3), "points")
        check_shape(normals, (len(points), 3), "normals")
        if len(points) < 12:
            raise ValueError(f"registration needs at least 12 surface samples, got {len(points)}")
        points = np.asarray(points, dtype=np.float64)
        normals = np.asarray(normals, dtype=np.float64)
        self.points = points
        self.fine = SurfaceLookup(points, normals, fine_cell_m, fine_reach_m)
        step = max(1, int(coarse_stride))
        self.coarse = SurfaceLookup(points[::step], normals[::step], coarse_cell_m, coarse_reach_m)
        self.extent_m = float(np.ptp(points, axis=0).max())

    def query(self, X: np.ndarray, reach_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Nearest sample of each (..., 3) point up to ``reach_m``: its point, normal and distance
        (inf beyond). The fine grid answers where it reaches; the coarse one beyond it. A reach of
        more than twice the fine grid's (the first, wide ICP iterations) reads the coarse grid alone."""
        if reach_m > 2.0 * self.fine.reach:
            _, pts, nrm, dist = self.coarse.lookup(X)
            return pts, nrm, np.where(dist <= reach_m, dist, np.inf)
        idx, pts, nrm, dist = self.fine.lookup(X)
        if reach_m > self.fine.reach:
            far = idx < 0
            if far.any():
                _, pts_c, nrm_c, dist_c = self.coarse.lookup(X[far])
                pts[far] = pts_c
                nrm[far] = nrm_c
                dist[far] = dist_c
        return pts, nrm, np.where(dist <= reach_m, dist, np.inf)


@dataclass(frozen=True, eq=False)
class RegistrationResult:
    """Outcome of :func:`register`.

    R, t: the best pose (``X_cam = R X_obj + t``). score: its score (module docstring). runner_up_score: the best score of a pose more than ``distinct_deg`` away
    (inf when every start converged to the same pose), ``runner_up_R``/``runner_up_t`` that pose (NaN
    without one) and ``runner_up_angle_deg`` how far it is from the best.
    inlier_fraction: stereo points within ``tau`` of the surface at the best pose. tau_m: the
    frame's depth tolerance. starts: poses tried. n_points: stereo points registered (after the subsample).
    """

    R: np.ndarray
    t: np.ndarray
    score: float
    runner_up_score: float
    runner_up_angle_deg: float
    runner_up_R: np.ndarray
    runner_up_t: np.ndarray
    inlier_fraction: float
    tau_m: float
    starts: int
    n_points: int = 0

    @property
    def margin(self) -> float:
        """``runner_up_score - score`` (>= 0; inf without a distinct alternative)."""
        return self.runner_up_score - self.score


def cross_into(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """``out[...] = np.cross(a, b)`` for (..., 3) arrays, with the same products and differences (bit-equal)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    np.subtract(a1 * b2, a2 * b1, out=out[..., 0])
    np.subtract(a2 * b0, a0 * b2, out=out[..., 1])
    np.subtract(a0 * b1, a1 * b0, out=out[..., 2])


def _icp(R: np.ndarray, t: np.ndarray, P: np.ndarray, model: SurfaceModel, reaches: list[float]
         ) -> tuple[np.ndarray, np.ndarray]:
    """Batched point-to-plane ICP of K poses (K, 3, 3), (K, 3) to the points P (N, 3)."""
    for reach in reaches:
        X = (P[None] - t[:, None, :]) @ R                                     # R^T (P - t), (K, N, 3)
        q, n, dist = model.query(X, reach)
        w = np.isfinite(dist).astype(np.float64)
        A = np.empty(X.shape[:-1] + (6,))                                     # (K, N, 6): [X x n, n]
        cross_into(X, n, A[..., :3])
        A[..., 3:] = n
        b = np.einsum("kni,kni->kn", n, q - X)
        Aw = A * w[..., None]
        H = np.swapaxes(Aw, 1, 2) @ A + 1e-6 * np.eye(6)
        g = np.einsum("kni,kn->ki", Aw, b)
        enough = w.sum(axis=1) >= 12
        step = np.linalg.solve(H, g[..., None])[..., 0]
        step[~enough] = 0.0
        dR = exp_so3(step[:, :3])
        R = R @ np.swapaxes(dR, 1, 2)                                         # X' = dR X + v
        t = t - np.einsum("kij,kj->ki", R, step[:, 3:])
    return R, t


def register(points: np.ndarray, K: np.ndarray, baseline_m: float, model: SurfaceModel,
             centre: np.ndarray, config: RegistrationConfig = RegistrationConfig(),
             seeds: list[tuple[np.ndarray, np.ndarray]] | None = None, flip_axis: str = "",
             sigma_d_px: float | None = None) -> RegistrationResult | None:
    """Best pose of the surface in ``model`` for the stereo ``points`` (N, 3, camera frame).

    Args:
        model: the target's surface samples (:class:`SurfaceModel`, built once per bundle).
        K, baseline_m: rectified left intrinsics and baseline (``tau`` from the disparity noise).
        centre: (3,) object-frame centre (the starts put it behind the points' median).
        seeds: extra starting poses ``(R, t)``, e.g. the pose network's and its flip.
        flip_axis: body axis of the target's near-symmetry (``"x"``, ``"y"``, ``"z"``; ``""`` none):
            the best pose's 180° flip about it is refined and scored too, so the margin always
            measures the pose against its flip, even when no start converged to the flip.
        sigma_d_px: disparity noise in pixels of ``K`` (default ``config.sigma_d_px``); a disparity
            map upsampled from a smaller stereo window is noisier by the upsampling factor.

    Returns ``None`` with fewer than 12 points.
    """
    check_shape(points, (None, 3), "points")
    check_shape(K, (3, 3), "K")
    P = np.asarray(points, dtype=np.float64)
    P = P[np.all(np.isfinite(P), axis=1)]
    if len(P) < 12:
        return None
    P = P[np.random.default_rng(config.seed).permutation(len(P))[: config.max_points]]
    med = np.median(P, axis=0)
    z_med = float(max(med[2], 1e-3))
    sigma_d = config.sigma_d_px if sigma_d_px is None else float(sigma_d_px)
    tau = max(config.tau_min_m, z_med ** 2 * sigma_d / (float(K[0, 0]) * float(baseline_m)))
    ray = med / max(float(np.linalg.norm(med)), 1e-9)
    c = np.asarray(centre, dtype=np.float64)
    R0 = start_rotations(config.starts, config.seed)
    t0 = (med + ray * min(0.5, 0.2 * model.extent_m))[None] - R0 @ c
    for R_s, t_s in seeds or []:
        R_s, t_s = np.asarray(R_s, dtype=np.float64), np.asarray(t_s, dtype=np.float64)
        if np.all(np.isfinite(R_s)) and np.all(np.isfinite(t_s)):
            R0, t0 = np.concatenate([R0, R_s[None]]), np.concatenate([t0, t_s[None]])
    floor = max(config.reach_min_m, 2.0 * tau)
    reaches = [max(config.reach_start_m * config.reach_decay ** i, floor) for i in range(config.iterations)]
    P_coarse = P[: config.coarse_points]           # P is already a random order (subsample) or all points
    R, t = _icp(R0, t0, P_coarse, model, reaches)
    costs = _scene_cost(R, t, P_coarse, model, tau)
    top = np.argsort(costs, kind="stable")[: max(1, config.refine_top)]
    R, t = _icp(R[top], t[top], P, model, [floor] * config.fine_iterations)
    score = _scene_cost(R, t, P, model, tau)
    if flip_axis:
        from .flip import flipped_pose  # here: spacepose.flip -> pose_stage -> bundle imports this module

        k = int(np.argmin(score))
        R_f, t_f = flipped_pose(R[k], t[k], c, flip_axis)
        R_f, t_f = _icp(R_f[None], t_f[None], P, model, [floor] * config.fine_iterations)
        R, t = np.concatenate([R, R_f]), np.concatenate([t, t_f])
        score = np.concatenate([score, _scene_cost(R_f, t_f, P, model, tau)])
    best = int(np.argmin(score))
    angles = rotation_angle_deg(R[best][None], R)
    distinct = angles > config.distinct_deg
    if distinct.any():
        k_run = int(np.flatnonzero(distinct)[np.argmin(score[distinct])])
        runner, runner_angle, R_run, t_run = float(score[k_run]), float(angles[k_run]), R[k_run], t[k_run]
    else:
        runner, runner_angle, R_run, t_run = float("inf"), 0.0, np.full((3, 3), np.nan), np.full(3, np.nan)
    X = (P - t[best]) @ R[best]
    _, _, dist = model.query(X, tau)
    return RegistrationResult(R=R[best], t=t[best], score=float(score[best]), runner_up_score=runner,
                              runner_up_angle_deg=runner_angle, runner_up_R=R_run, runner_up_t=t_run,
                              inlier_fraction=float(np.mean(dist < tau)), tau_m=float(tau), starts=len(R0),
                              n_points=len(P))


def range_debiased(position: np.ndarray, tau_m: float, bias_tau: float) -> np.ndarray:
    """``position`` (3,) camera frame moved towards the camera along its line of sight by ``bias_tau * tau_m``
    metres (:class:`RegistrationConfig` ``position_range_bias_*``), never past the camera: the range ``r``
    becomes ``max(r - bias_tau * tau_m, 0)``. Returned as a new float64 array; unchanged (a copy) when the
    shift is 0 or not finite or the position is at the camera or not finite."""
    check_shape(position, (3,), "position")
    p = np.array(position, dtype=np.float64)
    r = float(np.linalg.norm(p))
    shift = float(bias_tau) * float(tau_m)
    if not (math.isfinite(r) and r > 0.0 and math.isfinite(shift) and shift != 0.0):
        return p
    return p * (max(r - shift, 0.0) / r)


def select_with_prior(result: RegistrationResult, R_prior: np.ndarray, t_prior: np.ndarray,
                      config: RegistrationConfig) -> tuple[np.ndarray, np.ndarray] | None:
    """Of the best pose and its runner-up, the one a previous frame's pose ``(R_prior, t_prior)``
    supports: within ``config.track_max_deg`` and ``config.track_max_m`` of it. ``None`` when
    neither or both are (the prior does not decide)."""
    near = [(R, t) for R, t in ((result.R, result.t), (result.runner_up_R, result.runner_up_t))
            if near_prior(R, t, R_prior, t_prior, config)]
    return near[0] if len(near) == 1 else None


def near_prior(R: np.ndarray, t: np.ndarray, R_prior: np.ndarray, t_prior: np.ndarray,
               config: RegistrationConfig) -> bool:
    """Whether the pose (R, t) is finite and within ``config.track_max_deg`` and ``config.track_max_m``
    of the previous frame's pose ``(R_prior, t_prior)``."""
    if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
        return False
    return (float(rotation_angle_deg(R_prior, R)) <= config.track_max_deg
            and float(np.linalg.norm(np.asarray(t) - np.asarray(t_prior))) <= config.track_max_m)


def _scene_cost(R: np.ndarray, t: np.ndarray, P: np.ndarray, model: SurfaceModel, tau: float) -> np.ndarray:
    X = (P[None] - t[:, None, :]) @ R
    _, _, dist = model.query(X, tau)
    return np.mean(np.minimum(dist, tau) ** 2, axis=1) / tau ** 2
