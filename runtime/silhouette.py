"""Silhouette refinement: which of a pose and its flip the target's outline shows (numpy + OpenCV).

The stereo points cannot tell the shipped target (``tdrs``) from its 180° flip about body z: the
flip moves 4 % of the surface, by at most 0.9 m, and the depth tolerance at 30 m is 0.5 m. The
outline can: the flip puts a 0.5 m dish and a 1 m boom on the other side, several pixels at 50 m.
But the outline of a pose 5–10° off (what registration gives) differs from the image by more than
the flip does, so each candidate is first refined against the outline, then the two are compared.

*Observed outline*: the pixels the stereo disparity puts nearer than the far end of the target
(``d > f B / (distance + margin)``); space and the Earth sit at zero disparity. This is the stereo
graph's own mask, so it does not depend on the image's brightness or on the renderer's materials.

*Model outline*: the object-frame silhouette samples (``target.silhouette_points`` of the bundle,
area-uniform, dense enough to leave no holes at the working scale) projected and splatted into a
:class:`SilhouetteFrame` — the stereo window, downscaled to at most ``max_side_px``. Contour
samples are those that land on the splat's boundary.

*Refinement* (:func:`refine_outline`): Gauss-Newton on the 6-DoF pose, residuals of two kinds,
each group weighted by the inverse of its count and its noise: every contour sample to the nearest
observed contour pixel and every observed contour pixel to the nearest contour sample (2-D, pixels
of the silhouette frame; pairs beyond ``trunc_px`` dropped), and every stereo point to the surface
at the pose (point-to-plane over ``tau``, which keeps the depth that the outline alone fixes poorly).
With ``range_weight`` < 1 the contour residuals' pull along the line of sight is scaled down: the
stereo outline is a little too large (the network carries the target's disparity into the sky), so
the range it implies is biased near, and at 0 the range is the stereo points' alone.

*Decision* (:func:`decide_outline`): the symmetric chamfer distance of the refined outline to the
observed one for every candidate, and for the flip of the best one, refined in turn (a candidate
too far off to converge can leave its flip the better fit; the flip of that precise wrong pose is
a precise right one). The lowest wins; the margin is the gap to the best pose more than
``rival_deg`` (90°) from it. Both are measured in
*outline pixels*: pixels of a ``max_side_px`` view of the stereo window, whatever its size. The
window is a fixed multiple of the target's extent, so an outline pixel is a fixed fraction of the
target: the parts the flip moves are as many outline pixels across at 10 m as at 50 m, at
640x480 as at 1280x960, and one gate serves every distance and rig (a far target, seen smaller
than ``max_side_px``, gets a proportionally stricter gate in image pixels).

*Image vote* (with ``image_vote``; :mod:`spacepose.image_vote`): the left image's lit pixels where
the winner's outline and its exact flip's differ. It can decide a frame with a smaller margin (and,
up to ``image_max_chamfer_px``, a looser fit), refuse one it does not back, and its pixel count
refuses every frame whose pose and flip the outline cannot tell apart (``min_flip_pixels``;
:class:`SilhouetteConfig`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np

from .errors import ShapeError, check_shape
from .image_vote import ImageVote, crop_to_frame, image_vote, window_grey
from .outline_search import OutlineTemplates, search_outline
from .registration import SurfaceModel, cross_into, exp_so3, rotation_angle_deg

__all__ = ["SilhouetteConfig", "SilhouetteFrame", "OutlineFit", "OutlineDecision", "silhouette_frame",
           "splat_mask", "observed_mask", "contour", "chamfer_px", "points_residual", "refine_outline",
           "decide_outline", "polish_pose", "align_centroid", "ObservedEdges", "observed_edges"]

_KERNEL = np.ones((3, 3), np.uint8)


@dataclass(frozen=True)
class SilhouetteConfig:
    """Settings of the silhouette stage (bundle ``silhouette`` section).

    max_side_px: side of the silhouette frame (the stereo window downscaled to it, never upscaled).
    iterations: Gauss-Newton steps per candidate. trunc_px: contour pairs farther apart than this
        (silhouette-frame pixels) are left out of a step. contour_points, stereo_points: most
        residuals of each kind per step (fixed-seed subsamples). sigma_px: contour noise (frame px).
        reverse: 1 adds the observed-to-model contour pairs (each observed contour pixel to the
        nearest model contour sample) to the model-to-observed ones; 0 leaves them out.
    range_weight: in [0, 1], how much the contour residuals may move the pose along the line of sight
        (the target's range). A stereo network carries the target's disparity a little into a
        textureless sky, so the observed outline is slightly too large and pulls the pose nearer (on
        the train split by 0.1-0.2 m); with 0 the range comes from the stereo points alone and the
        outline fixes the orientation and the direction. 1 (the default) is the plain Gauss-Newton.
    image_vote: 1 lets the left image's lit pixels, where the winner's outline and its flip's differ,
        take part (:mod:`spacepose.image_vote`): a usable vote (the sky ring at most
        ``image_max_background`` lit, at least ``image_min_pixels`` differing pixels) scoring at least
        ``image_min_score`` for the winner decides a frame whose margin is below ``min_margin_px`` but at
        least ``image_min_margin_px``; one scoring ``image_veto_score`` or less leaves even a frame with
        a large margin undecided (negative: the image must back the flip; 0: it must lean to the
        winner whenever it can vote, since a vote of 0 means the differing pixels are all dark, and
        in shadow the stereo outline that gave the margin is guessed too). 0 (the default, and every
        bundle without these keys) leaves the decision to the margin alone.
    image_max_chamfer_px: the image route's own chamfer gate, when larger than ``max_chamfer_px``
        (0: the same gate). An outline that fits less well (the stereo mask ragged at the edges) can
        still be told from its flip by the image; the margin route keeps ``max_chamfer_px``.
    min_flip_pixels: with ``image_vote``, the fewest pixels in which the winner's outline and its exact
        flip's must differ (the vote's ``pixels``) for the outline to decide anything, by margin or by
        image: where they differ in fewer, the outline cannot tell the two apart, and a large margin
        was measured against a rival that converged badly, not against the flip. 0 turns it off.
    polish: 1 refines a decided pose once more against the outline (:func:`polish_pose`), with the
        contours' pull along the line of sight at ``polish_range_weight``: the decision stays the
        one made with ``range_weight``; the pose reported is polished. 0 (the default, and every bundle
        without the key) reports the decided pose as it is.
    polish_range_weight: in [0, 1], ``range_weight`` of the polish. The range from the stereo points
        alone (0) comes out a little far and the outline's alone (1) a little near (the stereo outline
        is a little too large); the polish weighs the two.
    polish_max_deg, polish_max_m: a polish that moves the pose farther than either is not used (the
        decided pose is reported): it refines, it must not turn the pose into another one.
    max_decided_polish_deg: a pose the outline, image or registration route decided is refused (``weak_votes``;
        in a sequence the previous pose may still decide the frame) when the polish turns it by more than this
        many degrees, as ``flip_classifier.max_polish_deg`` refuses the classifier's: on session 22's fresh frames
        the poses more than 10° off were turned further (reports/wrong_s31). 0 (the default, and every bundle
        without the key): never.
    max_refused_track_polish_deg: a frame whose decided pose a polish cap refused (``max_decided_polish_deg``, or
        the flip classifier's ``max_polish_deg``) is reported from the previous pose (tracked) only when the polish
        turns the tracked pose by at most this many degrees. The tracked pose is mostly the refused one again, which
        the caps do not refuse on the tracking route (session 32, model card "The polish cap in sequences"). 0 (the
        default, and every bundle without the key): no such check.
    track_needs_outline: 1 reports a tracked pose (the previous pose decides between the pose and its
        flip) only when it is one of the outline-refined fits, within ``max_chamfer_px`` and near the
        previous pose; the registered pose alone is then neither reported nor kept to fall back on. On the
        39 rendered sequences of sessions 13-22, 17 of the 24 tracked poses off by more than 20° or 0.5 m
        had no outline fit within 1.5 px, against 44 of the 439 right ones (the model card). 0 (the
        default, and every bundle without the key): the registered pose near the previous one is reported
        when no refined fit is.
    track_max_chamfer_px: the chamfer gate (outline px) of the outline-refined fits the tracking route
        asks (route 3 of :meth:`spacepose.estimator.PoseEstimator`'s registration decision), when larger
        than ``max_chamfer_px``: near the previous pose, a fit that matches the outline less well is
        still told from its flip by the prior, where alone it decides nothing. 0 (the default, and every
        bundle without the key): ``max_chamfer_px``.
    image_exclusion_px: band (frame px) around each outline left out of the vote.
    points_weight: the decision ranks the refined fits by ``chamfer_px + points_weight * points_res``
        (:class:`OutlineFit`; the margin is the gap in that score): the stereo points weigh in where
        two outlines fit alike. 0 (the default, and every bundle without the key): the chamfer alone.
    rival_deg: the margin is measured against the best fit more than this far from the winner: 90
        (the default) compares with the flip and other far poses; with the outline search, poses 30-60°
        apart can fit alike too, and a smaller angle makes the margin count them.
    search_candidates: with :class:`spacepose.outline_search.OutlineTemplates` given to
        :func:`decide_outline`, this many more candidates from a global search of the outline
        (:mod:`spacepose.outline_search`; those within ``search_separation_deg`` of a given candidate or
        of each other are dropped). 0 (the default, and every bundle without the key) searches nothing.
        search_views, search_grid: the templates' view directions and grid side; search_angles: turns
        of the observed outline about the line of sight.
    stop_rad, stop_m: a step smaller than both (rotation, translation) ends the refinement.
    depth_margin_m: the observed mask keeps pixels nearer than ``distance + depth_margin_m``.
    max_chamfer_px: the winner's chamfer distance (outline px, module docstring) above which its outline does not
        match the image well enough to decide anything. min_margin_px: least chamfer gap between
        the two candidates for a decision.
    """

    max_side_px: int = 192
    iterations: int = 8
    trunc_px: float = 8.0
    contour_points: int = 800
    stereo_points: int = 300
    sigma_px: float = 1.0
    depth_margin_m: float = 4.0
    max_chamfer_px: float = 1.2
    min_margin_px: float = 0.2
    reverse: int = 1
    range_weight: float = 1.0
    image_vote: int = 0
    image_min_score: float = 0.1
    image_min_margin_px: float = 0.2
    image_max_background: float = 0.02
    image_exclusion_px: int = 2
    image_min_pixels: int = 16
    image_veto_score: float = -0.1
    image_max_chamfer_px: float = 0.0
    min_flip_pixels: int = 0
    polish: int = 0
    polish_range_weight: float = 0.25
    polish_max_deg: float = 15.0
    polish_max_m: float = 1.0
    max_decided_polish_deg: float = 0.0
    max_refused_track_polish_deg: float = 0.0
    track_needs_outline: int = 0
    track_max_chamfer_px: float = 0.0
    points_weight: float = 0.0
    rival_deg: float = 90.0
    search_candidates: int = 0
    search_views: int = 1000
    search_angles: int = 36
    search_grid: int = 32
    search_separation_deg: float = 30.0
    stop_rad: float = 2e-4
    stop_m: float = 2e-3
    seed: int = 0

    def __post_init__(self) -> None:
        if self.max_side_px < 16 or self.iterations < 0 or self.contour_points < 12 or self.stereo_points < 0:
            raise ValueError(f"invalid silhouette config {self}")
        if not (self.trunc_px > 0 and self.sigma_px > 0 and self.depth_margin_m >= 0):
            raise ValueError(f"invalid silhouette config {self}")
        if not 0.0 <= self.range_weight <= 1.0:
            raise ValueError(f"invalid silhouette config {self}")
        if (self.image_vote not in (0, 1) or self.image_exclusion_px < 0 or self.image_min_pixels < 0
                or self.min_flip_pixels < 0
                or not 0 <= self.image_max_background <= 1 or not self.image_max_chamfer_px >= 0
                or not self.track_max_chamfer_px >= 0):
            raise ValueError(f"invalid silhouette config {self}")
        if (self.polish not in (0, 1) or self.track_needs_outline not in (0, 1)
                or not 0.0 <= self.polish_range_weight <= 1.0
                or not self.polish_max_deg > 0 or not self.polish_max_m > 0
                or not self.max_decided_polish_deg >= 0 or not self.max_refused_track_polish_deg >= 0):
            raise ValueError(f"invalid silhouette config {self}")
        if not (self.points_weight >= 0 and 0 < self.rival_deg < 180):
            raise ValueError(f"invalid silhouette config {self}")
        if (self.search_candidates < 0 or self.search_views < 1 or self.search_angles < 1 or self.search_grid < 8
                or not 0.0 <= self.search_separation_deg <= 180.0):
            raise ValueError(f"invalid silhouette config {self}")
        if not -1.0 <= self.image_veto_score < self.image_min_score:
            raise ValueError(f"invalid silhouette config {self}: image_veto_score must be in [-1, image_min_score)")


@dataclass(frozen=True)
class SilhouetteFrame:
    """A full-frame box ``(x0, y0)`` + ``side`` seen at ``scale`` (frame px per full-frame px).

    ``K``: (3, 3) intrinsics of the frame; ``size``: its side in pixels.
    """

    x0: int
    y0: int
    side: int
    scale: float
    K: np.ndarray

    @property
    def size(self) -> int:
        return max(1, int(round(self.side * self.scale)))


def silhouette_frame(K_full: np.ndarray, x0: int, y0: int, side: int, max_side_px: int) -> SilhouetteFrame:
    """The frame of the full-frame box ``(x0, y0, side)`` downscaled to at most ``max_side_px``."""
    check_shape(K_full, (3, 3), "K_full")
    side = max(1, int(side))
    scale = min(1.0, max_side_px / side)
    size = max(1, int(round(side * scale)))
    s = size / side
    K = np.asarray(K_full, dtype=np.float64).copy()
    K[0, 0] *= s
    K[1, 1] *= s
    K[0, 2] = (K[0, 2] - x0 + 0.5) * s - 0.5
    K[1, 2] = (K[1, 2] - y0 + 0.5) * s - 0.5
    return SilhouetteFrame(int(x0), int(y0), side, s, K)


def splat_mask(points: np.ndarray, R: np.ndarray, t: np.ndarray, frame: SilhouetteFrame
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Splat the object-frame ``points`` (S, 3) at pose (R, t) into ``frame`` (computed in the
    points' dtype: float32 points halve the cost, at 1e-4 px).

    Returns ``(mask (n, n) uint8 after a 3x3 closing, pixel (S, 2) int column/row, inside (S,) bool)``.
    """
    mask, ij, _, inside = _splat(_transposed(points), R, t, frame)
    return mask, ij.T, inside


def _transposed(points: np.ndarray) -> np.ndarray:
    """(S, 3) points as the C-contiguous (3, S) array :func:`_splat` reads, in their float dtype (float64 for
    any other)."""
    points = np.asarray(points)
    if points.dtype not in (np.float32, np.float64):
        points = points.astype(np.float64)
    return np.ascontiguousarray(points.T)


def _splat(points_t: np.ndarray, R: np.ndarray, t: np.ndarray, frame: SilhouetteFrame
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`splat_mask` of the points given transposed and C-contiguous, ``points_t`` (3, S): returns
    ``(mask, pixel (2, S) int32 column/row, row-major pixel index (S,) int64 (meaningful where
    inside), inside (S,))``.

    Row-wise, in place: the same products and sums as projecting the (S, 3) points one by one (bit for
    bit), without (S, 3) strided temporaries (4x faster at S = 24,000).
    """
    n = frame.size
    dtype = points_t.dtype
    X = np.asarray(R, dtype=dtype) @ points_t                       # (3, S) = R P^T
    X += np.asarray(t, dtype=dtype)[:, None]
    K = frame.K.astype(dtype)
    z = np.maximum(X[2], 1e-6)
    uv = np.empty((2, X.shape[1]), dtype=np.result_type(X, K))
    np.multiply(K[0, 0], X[0], out=uv[0])
    uv[0] /= z
    uv[0] += K[0, 2]
    np.multiply(K[1, 1], X[1], out=uv[1])
    uv[1] /= z
    uv[1] += K[1, 2]
    if not np.isfinite(uv).all():
        uv = np.nan_to_num(uv, nan=-1.0)
    np.clip(uv, -1.0, float(n), out=uv)        # before the cast: no int overflow
    ij = np.rint(uv, out=uv).astype(np.int32)
    u = ij.view(np.uint32)                      # a negative pixel wraps to a huge one
    inside = u[0] < n
    inside &= u[1] < n
    inside &= X[2] > 1e-3
    flat = ij[1].astype(np.int64)
    flat *= n
    flat += ij[0]
    mask = np.zeros((n, n), np.uint8)
    mask.reshape(-1)[flat[inside]] = 1
    return cv2.morphologyEx(mask, cv2.MORPH_CLOSE, _KERNEL), ij, flat, inside


def observed_mask(disparity: np.ndarray, frame: SilhouetteFrame, min_disparity: float) -> np.ndarray:
    """(n, n) uint8: full-frame ``disparity`` (H, W) > ``min_disparity`` over ``frame``'s box."""
    check_shape(disparity, (None, None), "disparity")
    crop = crop_to_frame(disparity, frame.x0, frame.y0, frame.side, frame.size,
                         convert=lambda box: (box > min_disparity).astype(np.float32))   # threshold the box only
    return (crop > 0.5).astype(np.uint8)


def contour(mask: np.ndarray) -> np.ndarray:
    """(n, n) bool: pixels of ``mask`` with a background 8-neighbour (or on the frame's edge)."""
    return (mask > 0) & (cv2.erode(mask, _KERNEL, borderType=cv2.BORDER_CONSTANT, borderValue=0) == 0)


def _outline_unit(frame: SilhouetteFrame, config: SilhouetteConfig) -> float:
    """Frame pixels per outline pixel (module docstring): 1 for a window downscaled to the frame."""
    return frame.size / float(config.max_side_px)


def _distance_to(edge: np.ndarray) -> np.ndarray:
    return cv2.distanceTransform((~edge).astype(np.uint8), cv2.DIST_L2, 3)


def chamfer_px(mask: np.ndarray, observed: np.ndarray, cap_px: float, scale: float = 1.0) -> float:
    """Symmetric mean contour distance of two masks, each distance capped at ``cap_px`` (pixels of
    the masks), divided by ``scale`` (e.g. mask px per outline px); ``cap_px / scale`` when either
    contour is empty."""
    a, b = contour(mask), contour(observed)
    if not a.any() or not b.any():
        return cap_px / scale
    d_ab = np.minimum(_distance_to(b)[a], cap_px).mean()
    d_ba = np.minimum(_distance_to(a)[b], cap_px).mean()
    return float(0.5 * (d_ab + d_ba) / scale)


@dataclass(frozen=True, eq=False)
class OutlineFit:
    """A pose refined against the outline: ``R``, ``t``, its ``chamfer_px`` (outline px, module docstring)
    and ``points_res``, the stereo points' mean point-to-plane distance to the surface at the pose in
    units of the noise ``tau``, each capped at 3 (0 when not measured: ``points_weight`` 0)."""

    R: np.ndarray
    t: np.ndarray
    chamfer_px: float
    points_res: float = 0.0

    def score(self, config: SilhouetteConfig) -> float:
        """What the decision ranks the fits by: ``chamfer_px + points_weight * points_res``."""
        return self.chamfer_px + config.points_weight * self.points_res


def points_residual(R: np.ndarray, t: np.ndarray, points: np.ndarray, surface: SurfaceModel, tau_m: float,
                    cap: float = 3.0) -> float:
    """Mean point-to-plane distance of the finite camera-frame ``points`` (N, 3) to ``surface`` at pose
    (R, t), in units of ``tau_m``, each capped at ``cap`` (a point with no surface within ``cap * tau_m``
    counts ``cap``): :class:`OutlineFit` ``points_res``. NaN when no point is finite."""
    check_shape(points, (None, 3), "points")
    P = np.asarray(points, dtype=np.float64)
    P = P[np.all(np.isfinite(P), axis=1)]
    if len(P) == 0:
        return float("nan")
    Xo = (P - t) @ R                                                         # R^T (P - t)
    q, nrm, d = surface.query(Xo, cap * tau_m)
    ok = np.isfinite(d)
    e = np.full(len(P), cap)
    e[ok] = np.minimum(np.abs(np.einsum("ij,ij->i", nrm[ok], Xo[ok] - q[ok])) / tau_m, cap)
    return float(e.mean())


@dataclass(frozen=True, eq=False)
class ObservedEdges:
    """What every refinement against one observed (n, n) outline reads: its contour pixels ``ex``, ``ey``
    (row-major order) and ``flat`` (their row-major indices), and per frame pixel the distance to the
    nearest of them (``dist``, OpenCV's 5x5 L2 distance transform) and which one it is (``label``, k + 1
    for the k-th contour pixel). Made once per outline by :func:`observed_edges`."""

    ex: np.ndarray
    ey: np.ndarray
    flat: np.ndarray
    dist: np.ndarray
    label: np.ndarray


def observed_edges(observed: np.ndarray) -> ObservedEdges:
    """The :class:`ObservedEdges` of an observed (n, n) outline mask."""
    check_shape(observed, (None, None), "observed")
    edge = contour(observed)
    dist, labels = cv2.distanceTransformWithLabels((~edge).astype(np.uint8), cv2.DIST_L2, 5,
                                                   labelType=cv2.DIST_LABEL_PIXEL)
    ey, ex = np.nonzero(edge)   # label k (1-based) is the k-th edge pixel in row-major order
    return ObservedEdges(ex=ex, ey=ey, flat=ey.astype(np.int64) * edge.shape[1] + ex, dist=dist.reshape(-1),
                         label=labels.reshape(-1))


def refine_outline(R: np.ndarray, t: np.ndarray, silhouette_points: np.ndarray, observed: np.ndarray,
                   frame: SilhouetteFrame, config: SilhouetteConfig = SilhouetteConfig(), *,
                   stereo_points: np.ndarray | None = None, surface: SurfaceModel | None = None,
                   tau_m: float = 0.5, edges: ObservedEdges | None = None) -> OutlineFit:
    """Gauss-Newton refinement of (R, t) against the ``observed`` (n, n) outline (module docstring).

    ``stereo_points`` (N, 3, camera frame) with the target's ``surface`` add the point-to-plane
    residuals (noise ``tau_m``). A step that the data cannot support (too few residuals, a
    singular system) ends the refinement; the pose so far is returned. ``edges``: the outline's
    :func:`observed_edges`, when several poses are refined against it (made here otherwise).
    """
    check_shape(silhouette_points, (None, 3), "silhouette_points")
    check_shape(observed, (frame.size, frame.size), "observed")
    points_t = _transposed(silhouette_points)
    R = np.asarray(R, dtype=np.float64).copy()
    t = np.asarray(t, dtype=np.float64).copy()
    Kf = frame.K
    if edges is None:
        edges = observed_edges(observed)
    elif len(edges.dist) != observed.size:
        raise ShapeError(f"edges are of a {len(edges.dist)}-pixel outline, observed has {observed.size}")
    ey, ex, e_flat, dist_flat, labels_flat = edges.ey, edges.ex, edges.flat, edges.dist, edges.label
    rng = np.random.default_rng(config.seed)
    P = None
    if stereo_points is not None and surface is not None and config.stereo_points > 0:
        P = np.asarray(stereo_points, dtype=np.float64)
        P = P[np.all(np.isfinite(P), axis=1)]
        P = P[rng.permutation(len(P))[: config.stereo_points]] if len(P) >= 12 else None
    if len(ey) >= 12:
        for _ in range(config.iterations):
            mask, _, flat, inside = _splat(points_t, R, t, frame)
            on = np.flatnonzero(inside)
            on = on[contour(mask).reshape(-1)[flat[on]]]
            if len(on) < 12:
                break
            # model contour -> nearest observed contour pixel
            fwd = on[dist_flat[flat[on]] < config.trunc_px]
            k = labels_flat[flat[fwd]] - 1
            fwd_target = np.stack([ex[k], ey[k]], axis=1)
            if config.reverse:
                # observed contour pixel -> nearest model contour sample (pulls the model over what it misses)
                ids = np.full(mask.size, -1, np.int64)
                ids[flat[on]] = on
                m_edge = ids.reshape(mask.shape) >= 0
                m_dist, m_lab = cv2.distanceTransformWithLabels((~m_edge).astype(np.uint8), cv2.DIST_L2, 5,
                                                                labelType=cv2.DIST_LABEL_PIXEL)
                m_flat = np.flatnonzero(m_edge)   # label k (1-based) is the k-th edge pixel in row-major order
                near = m_dist.reshape(-1)[e_flat] < config.trunc_px
                kk = m_lab.reshape(-1)[e_flat[near]] - 1
                rev = ids[m_flat[kk]]
                rev_target = np.stack([ex[near], ey[near]], axis=1)
                fwd, fwd_target = np.concatenate([fwd, rev]), np.concatenate([fwd_target, rev_target])
            if len(fwd) < 12:
                break
            if len(fwd) > config.contour_points:
                pick = rng.choice(len(fwd), config.contour_points, replace=False)
                fwd, fwd_target = fwd[pick], fwd_target[pick]
            on, target = fwd, fwd_target.astype(np.float64)
            Xc = silhouette_points[on].astype(np.float64) @ R.T + t
            X, Y, z = Xc[:, 0], Xc[:, 1], Xc[:, 2]
            x, y = X / z, Y / z
            fx, fy = Kf[0, 0], Kf[1, 1]
            r = np.stack([fx * x + Kf[0, 2], fy * y + Kf[1, 2]], axis=1) - target      # (C, 2) px
            # image Jacobian of X_c' = exp(w) X_c + v at (w, v) = 0: rows u, v; columns w, v
            J = np.empty((len(on), 2, 6))
            J[:, 0, 0], J[:, 0, 1], J[:, 0, 2] = -fx * x * y, fx * (1.0 + x * x), -fx * y
            J[:, 0, 3], J[:, 0, 4], J[:, 0, 5] = fx / z, 0.0, -fx * x / z
            J[:, 1, 0], J[:, 1, 1], J[:, 1, 2] = -fy * (1.0 + y * y), fy * x * y, fy * x
            J[:, 1, 3], J[:, 1, 4], J[:, 1, 5] = 0.0, fy / z, -fy * y / z
            J = J.reshape(-1, 6)
            if config.range_weight < 1.0:   # scale the contour's pull along the line of sight (config docstring)
                ray = t / max(float(np.linalg.norm(t)), 1e-9)
                J[:, 3:] = J[:, 3:] @ (np.eye(3) - (1.0 - config.range_weight) * np.outer(ray, ray))
            wc = 1.0 / (len(on) * config.sigma_px ** 2)
            H = wc * J.T @ J
            g = wc * J.T @ r.reshape(-1)
            if P is not None:
                Xo = (P - t) @ R                                             # R^T (P - t)
                q, nrm, d = surface.query(Xo, 3.0 * tau_m)
                ok = np.isfinite(d)
                if ok.sum() >= 12:
                    qc = q[ok] @ R.T + t
                    nc = nrm[ok] @ R.T
                    e = np.einsum("ij,ij->i", nc, qc - P[ok])                # model minus data along n
                    Js = np.empty((len(qc), 6))                               # d e / d(w, v): [q x n, n]
                    cross_into(qc, nc, Js[:, :3])
                    Js[:, 3:] = nc
                    ws = 1.0 / (ok.sum() * tau_m ** 2)
                    H += ws * Js.T @ Js
                    g += ws * Js.T @ e
            H += 1e-9 * np.trace(H) * np.eye(6) + 1e-12 * np.eye(6)
            try:
                step = -np.linalg.solve(H, g)
            except np.linalg.LinAlgError:
                break
            if not np.all(np.isfinite(step)):
                break
            dR = exp_so3(step[:3])
            R, t = dR @ R, dR @ t + step[3:]
            if np.linalg.norm(step[:3]) < config.stop_rad and np.linalg.norm(step[3:]) < config.stop_m:
                break
    mask = _splat(points_t, R, t, frame)[0]
    points_res = points_residual(R, t, P, surface, tau_m) if config.points_weight > 0 and P is not None else 0.0
    return OutlineFit(R=R, t=t, chamfer_px=chamfer_px(mask, observed, config.trunc_px, _outline_unit(frame, config)),
                      points_res=points_res)


@dataclass(frozen=True, eq=False)
class OutlineDecision:
    """Candidates refined: ``best`` (lowest :meth:`OutlineFit.score`, the chamfer unless ``points_weight``
    is set), ``other`` (the best more than ``rival_deg`` from it, NaN pose when none), ``margin_px``
    between their scores; ``best_index``: which candidate won (the given ones, then the outline
    search's; their count: the flip of the best one); ``turned_deg``: angle between the two;
    ``vote``: the left image's vote for ``best`` against its exact flip (against ``other`` when no flip
    was given; :mod:`spacepose.image_vote`), ``None`` when it was not taken (no image, the stage's
    ``image_vote`` off, or neither a flip nor a rival). ``frame``, ``observed``: the silhouette frame
    and the observed (n, n) outline the candidates were refined against (for :func:`polish_pose`);
    ``min_disparity``: the disparity (pixels) that outline is thresholded at."""

    best: OutlineFit
    other: OutlineFit
    best_index: int
    margin_px: float
    turned_deg: float
    vote: ImageVote | None = None
    frame: SilhouetteFrame | None = None
    observed: np.ndarray | None = None
    min_disparity: float = float("nan")

    def decided(self, config: SilhouetteConfig) -> bool:
        """Whether the outline picks ``best``: a fine enough fit and a clear enough gap, or (with
        ``config.image_vote``) a smaller gap, and up to ``image_max_chamfer_px`` a looser fit, that the
        image's lit pixels back; never when a usable vote vetoes it or the winner's and its flip's
        outlines differ in fewer than ``min_flip_pixels`` pixels (class docstring of
        :class:`SilhouetteConfig`)."""
        if self.image_vetoes(config) or self.too_few_flip_pixels(config):
            return False
        if self.best.chamfer_px <= config.max_chamfer_px and self.margin_px >= config.min_margin_px:
            return True
        return self.decided_by_image(config)

    def _usable_vote(self, config: SilhouetteConfig) -> ImageVote | None:
        return self.vote if config.image_vote and self.vote is not None and self.vote.usable else None

    def too_few_flip_pixels(self, config: SilhouetteConfig) -> bool:
        """Whether the vote (taken with ``image_vote``) counted fewer than ``min_flip_pixels`` pixels in
        which the winner's outline and its flip's differ; False when no vote was taken."""
        return bool(config.image_vote and self.vote is not None and self.vote.pixels < config.min_flip_pixels)

    def image_vetoes(self, config: SilhouetteConfig) -> bool:
        """Whether a usable image vote scores ``image_veto_score`` or less for ``best``."""
        vote = self._usable_vote(config)
        return vote is not None and vote.score <= config.image_veto_score

    def decided_by_image(self, config: SilhouetteConfig) -> bool:
        """Whether the image vote, with a margin of at least ``image_min_margin_px`` and a chamfer within
        the larger of ``max_chamfer_px`` and ``image_max_chamfer_px``, picks ``best``."""
        vote = self._usable_vote(config)
        fits = self.best.chamfer_px <= max(config.max_chamfer_px, config.image_max_chamfer_px)
        return bool(vote is not None and fits and self.margin_px >= config.image_min_margin_px
                    and vote.score >= config.image_min_score)


def decide_outline(candidates: list[tuple[np.ndarray, np.ndarray]], silhouette_points: np.ndarray,
                   disparity: np.ndarray, K_full: np.ndarray, baseline_m: float, window: tuple[int, int, int],
                   config: SilhouetteConfig = SilhouetteConfig(), *, stereo_points: np.ndarray | None = None,
                   surface: SurfaceModel | None = None, tau_m: float = 0.5,
                   flip: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None,
                   image: np.ndarray | None = None, templates: OutlineTemplates | None = None) -> OutlineDecision:
    """Refine candidate poses against the outline the ``disparity`` (H, W) shows in ``window``
    (full-frame ``x0, y0, side``) and say which fits it best (module docstring).

    ``flip`` (pose -> its 180° flip): after the candidates, the flip of the best refined pose is
    refined too. A candidate too far from the truth for the refinement to reach it can leave its
    flip the better fit; the flip of that precise wrong pose is a precise right one, and the
    comparison is then between two converged poses. The margin is measured against the best pose
    more than ``rival_deg`` from the winner (``cap`` when there is none).

    ``image``: the left rectified image (H, W[, C], the disparity's pixels). With ``config.image_vote``
    its lit pixels vote between the winner's outline and that of the winner's exact ``flip`` (the
    best rival's without ``flip``; :mod:`spacepose.image_vote`).

    ``templates``: with ``config.search_candidates`` > 0, the outline is also searched globally
    (:func:`spacepose.outline_search.search_outline`) and up to that many of its poses, none within
    ``search_separation_deg`` of a given candidate, are refined after the given ones.
    """
    if not candidates:
        raise ValueError("decide_outline needs at least one candidate")
    check_shape(disparity, (None, None), "disparity")
    frame = silhouette_frame(K_full, *window, config.max_side_px)
    distance = float(np.mean([np.linalg.norm(t) for _, t in candidates]))
    far = distance + config.depth_margin_m
    min_disparity = float(K_full[0, 0]) * float(baseline_m) / max(far, 1e-6)
    observed = observed_mask(np.asarray(disparity, dtype=np.float32), frame, min_disparity)

    edges = observed_edges(observed)

    def fit(R: np.ndarray, t: np.ndarray) -> OutlineFit:
        return refine_outline(R, t, silhouette_points, observed, frame, config, stereo_points=stereo_points,
                              surface=surface, tau_m=tau_m, edges=edges)

    candidates = list(candidates)
    if templates is not None and config.search_candidates > 0:
        found = search_outline(templates, observed, frame.K, distance, angles=config.search_angles,
                               candidates=config.search_candidates + len(candidates),
                               min_separation_deg=config.search_separation_deg)
        given = [R for R, _ in candidates]
        found = [c for c in found if all(rotation_angle_deg(R, c.R) >= config.search_separation_deg for R in given)]
        candidates += [(c.R, c.t) for c in found[: config.search_candidates]]
    fits = [fit(R, t) for R, t in candidates]
    if flip is not None:
        best = min(fits, key=lambda f: f.score(config))
        fits.append(fit(*flip(best.R, best.t)))
    order = sorted(range(len(fits)), key=lambda i: fits[i].score(config))
    best = fits[order[0]]
    turned = [float(rotation_angle_deg(best.R, fits[i].R)) for i in order[1:]]
    rivals = [i for i, a in zip(order[1:], turned) if a > config.rival_deg]
    cap = config.trunc_px / _outline_unit(frame, config)
    other = fits[rivals[0]] if rivals else OutlineFit(R=np.full((3, 3), np.nan), t=np.full(3, np.nan), chamfer_px=cap)
    margin = other.score(config) - best.score(config)
    vote = None
    if config.image_vote and image is not None and (rivals or flip is not None):
        # against the exact flip of the winner where there is one: its symmetric parts coincide with the
        # winner's, so only the parts the flip moves vote (a separately refined rival that converged
        # worse would lose the vote for its misfit, not for being the flip)
        R_o, t_o = flip(best.R, best.t) if flip is not None else (other.R, other.t)
        grey = window_grey(image, frame.x0, frame.y0, frame.side, frame.size)
        vote = image_vote(grey, splat_mask(silhouette_points, best.R, best.t, frame)[0],
                          splat_mask(silhouette_points, R_o, t_o, frame)[0],
                          exclusion_px=config.image_exclusion_px, max_background=config.image_max_background,
                          min_pixels=config.image_min_pixels)
    return OutlineDecision(best=best, other=other, best_index=min(order[0], len(candidates)),
                           margin_px=float(margin) if math.isfinite(margin) else 0.0,
                           turned_deg=float(rotation_angle_deg(best.R, other.R)) if rivals else float("nan"),
                           vote=vote, frame=frame, observed=observed, min_disparity=min_disparity)


def align_centroid(R: np.ndarray, t: np.ndarray, silhouette_points: np.ndarray, observed: np.ndarray,
                   frame: SilhouetteFrame) -> np.ndarray | None:
    """``t`` (3,) moved parallel to the image plane so that the centroid of the model's outline at
    ``(R, t)`` lands on the centroid of the ``observed`` (n, n) outline mask of ``frame``; the range
    (camera z) is kept. ``None`` when either mask is empty or touches the frame's edge (a cut
    outline has a shifted centroid).

    A pose whose orientation is a few degrees off (what registration gives where the outline does not
    fit) still puts the target's area where the image shows it: the shift moves the whole target, so
    where the flip leaves the target's centre (:class:`spacepose.estimator.PoseResult` ``position``)
    it moves that centre by the same amount.
    """
    n = frame.size
    check_shape(observed, (n, n), "observed")
    t = np.asarray(t, dtype=np.float64)
    model, _, _ = splat_mask(silhouette_points, R, t, frame)
    centroids = []
    for mask in (np.asarray(observed), model):
        if not mask.any() or mask[0].any() or mask[-1].any() or mask[:, 0].any() or mask[:, -1].any():
            return None
        rows, cols = np.nonzero(mask)
        centroids.append((cols.mean(), rows.mean()))
    (u_obs, v_obs), (u_mod, v_mod) = centroids
    if not t[2] > 0.0:
        return None
    return t + np.array([(u_obs - u_mod) * t[2] / frame.K[0, 0], (v_obs - v_mod) * t[2] / frame.K[1, 1], 0.0])


def polish_pose(decision: OutlineDecision, R: np.ndarray, t: np.ndarray, silhouette_points: np.ndarray,
                config: SilhouetteConfig, *, stereo_points: np.ndarray | None = None,
                surface: SurfaceModel | None = None, tau_m: float = 0.5) -> OutlineFit | None:
    """The decided pose (R, t) refined once more against ``decision``'s observed outline, with
    ``config.polish_range_weight`` as the range weight (class docstring of :class:`SilhouetteConfig`).

    ``None`` when the decision kept no outline, or the polish is not finite or moves the pose more
    than ``polish_max_deg`` / ``polish_max_m``: report the decided pose then.
    """
    if decision.frame is None or decision.observed is None:
        return None
    fit = refine_outline(R, t, silhouette_points, decision.observed, decision.frame,
                         dataclasses.replace(config, range_weight=config.polish_range_weight),
                         stereo_points=stereo_points, surface=surface, tau_m=tau_m)
    if not (np.all(np.isfinite(fit.R)) and np.all(np.isfinite(fit.t))):
        return None
    if (float(rotation_angle_deg(R, fit.R)) > config.polish_max_deg
            or float(np.linalg.norm(fit.t - np.asarray(t))) > config.polish_max_m):
        return None
    return fit
