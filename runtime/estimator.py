"""PoseEstimator: raw stereo pair -> pose of the target in the left rectified camera frame.

The flow of one frame (DESIGN.md), each step a named stage timed in ``PoseResult.timings_ms``::

    validate -> rectify -> stereo (coarse pass, or with prior_window the prior ROI; fine pass) -> pose_inputs (triangulate,
    back-project, sample, RGB crop, kNN indices: spacepose.pose_preprocess, shared with training)
    -> pose_net (ONNX) -> voting
    (MeanShift + SVD fit, validity, confidence) [-> registration (with the bundle's ``registration``
    section: multi-start point-to-plane ICP seeded with the voted pose and the previous valid pose;
    it replaces the voted pose and its validity, spacepose.registration)] [-> refine (point-to-plane
    ICP against the stereo points; off by default)] -> verify (without registration, with the
    bundle's ``voting.flip_axis``: the pose or its 180° flip, whichever the stereo points support,
    both refined when refine is on, spacepose.flip; surface fitness against the stereo points;
    left-right photometric consistency, spacepose.photometric) [-> range_fit (with the bundle's
    ``range_fit``: the checked pose moved along its centre's line of sight to the range the images show
    at full resolution, spacepose.range_fit)]. The checks judge the pose that is reported, refined or
    not, before the range fit, which changes only its range.

Input rule (one rule, no exceptions): an argument that is not a numpy array is a programming error
and raises :class:`~spacepose.errors.ShapeError`; every numpy array the estimator cannot use — wrong
rank or channel count, a dtype other than uint8/uint16/float, left and right of different shapes, a
size that does not match the calibration, NaN/inf in a float image — gives a result with
``valid=False, status="bad_input"`` and the reason in ``detail``. Float images are read on the
0-255 scale. An all-dark frame (eclipse) gives ``no_target``; a saturated frame ``bad_input``.

Thread safety: :meth:`PoseEstimator.estimate` may be called from several threads. The onnxruntime
sessions and the rectification maps are safe to share; the only mutable state, the prior (the last
valid pose and how many frames ago it was, used as the next frame's ROI and, with registration, to
decide an ambiguous frame), is read and written under ``self._lock``. With concurrent calls the
prior is that of whichever frame finished last.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from . import roi
from .bundle import ModelBundle, load_bundle
from .confidence import calibrated_confidence, within_probability
from .errors import ShapeError
from .flip import flipped_pose, resolve_flip
from .flip_classifier import FlipClassifier
from .image_vote import crop_to_frame, window_grey
from .outline_refiner import OutlineRefiner, refined_outline, refiner_planes
from .range_fit import fit_range
from .outline_search import OutlineTemplates
from .photometric import photometric_consistency
from .pose_preprocess import depth_window, pose_crop_window, prepare_pose_inputs
from .pose_stage import PoseStageResult, solve_pose, surface_fitness
from .profiler import StageTimer
from .registration import (SurfaceModel, near_prior, range_debiased, register, rotation_angle_deg,
                           select_with_prior)
from .silhouette import align_centroid, decide_outline, polish_pose
from .tails import nees_gate
from .uncertainty import PoseUncertainty, pose_uncertainty, position_uncertainty

__all__ = ["PoseResult", "PoseEstimator", "DECISION_ROUTES", "rotation_to_quaternion", "pose_crop_window",
           "refine_icp"]

logger = logging.getLogger(__name__)

#: a frame whose brightest pixel is at most this fraction of full scale is "dark" (eclipse)
DARK_FRACTION = 0.02
#: a frame with more than this fraction of pixels at full scale is "saturated"
SATURATED_FRACTION = 0.5
#: frames a valid pose stays the prior after it while no other is valid (see ``PoseEstimator``): 2 since
#: session 30 (0 before: with the previous pose's window, 5 gave more wrong poses; model card)
PRIOR_MAX_GAP = 2
#: statuses after which a frame run in the previous pose's window is run again with the coarse pass
_WINDOW_MISSES = frozenset({"no_target", "too_few_points", "out_of_range", "fit_residual"})
#: factors holding the registered centre (camera frame) of a frame that reached the flip decision
_POSITION_KEYS = ("position_x", "position_y", "position_z")

#: what can pick a valid pose from its flip (``PoseResult.decided_by``); the stage records its index
#: as the float factor ``route`` (0: no route recorded, a pose from the keypoint votes)
DECISION_ROUTES = ("votes", "outline", "image", "registration", "classifier", "tracked")


def _route_code(name: str) -> float:
    return float(DECISION_ROUTES.index(name))


def _route_name(factors: dict[str, float]) -> str:
    code = factors.get("route", 0.0)
    return DECISION_ROUTES[int(code)] if 0 <= code < len(DECISION_ROUTES) else "votes"


@dataclass(frozen=True, eq=False)
class PoseResult:
    """Pose of the target for one stereo frame.

    Attributes:
        R: (3, 3) float64, ``X_cam = R @ X_obj + t`` (left rectified camera); NaN when unknown.
        t: (3,) float64 metres; NaN when unknown.
        q_wxyz: (4,) float64 scalar-first quaternion of ``R`` (NaN when unknown).
        valid: whether the pose can be used.
        status: ``"ok"`` or why not (``no_target``, ``too_few_points``, ``weak_votes``,
            ``fit_residual``, ``out_of_range``, ``bad_input``).
        confidence: in [0, 1]; 0 when not valid. With the bundle's ``confidence`` section (the default
            bundle's since session 30): the probability that the pose is within that section's tolerance
            (0.10 m and 2 degrees), from its ``position_cov`` and ``sigma_rotation_deg``
            (:mod:`spacepose.confidence`; 0 for a valid pose without them); it falls as the errors grow. Without
            the section: ``decision_confidence``. A pose under the section's ``min_valid`` floor is not reported:
            the frame is ``weak_votes`` (``detail`` gives the confidence), with the position it would have had
            without a decision (``position_valid`` where the position gates pass), and the pose is not the next
            frame's prior.
        decision_confidence: how sure the route that decided the pose was (:mod:`spacepose.pose_stage`;
            with registration, the inlier share times a margin term, :meth:`PoseEstimator._register`); 0 when
            not valid. It does not rank the pose's errors. Not part of the JSON line.
        timings_ms: wall time per named stage.
        network_ms: of that, the time inside the stereo and pose graphs (the rest is the pipeline's
            own work: validation, rectification, windows, back-projection, voting, checks).
        n_points: target points the pose was voted from (centre-cluster inliers; 0 if none).
        roi: left-image box ``(x0, y0, x1, y1)`` of the stereo fine pass, or ``None``.
        detail: a human-readable reason for an invalid result ("" when valid).
        flip_margin: with the bundle's ``voting.flip_axis``, how much more of the stereo points the
            kept pose holds than its 180° flip (surface fitness gap, :mod:`spacepose.flip`); NaN when
            that check did not run. With the bundle's ``registration``: the score gap between the
            registered pose and its runner-up (:mod:`spacepose.registration`). Not part of the JSON line.
        depth_tolerance_m: the registration's depth tolerance ``tau`` for this frame (NaN without
            registration): the stereo depth noise ``Z**2 sigma_d / (f B)`` at the target, floored. It is
            also a measured bound on the pose's translation error: ``|t - t_true| <= tau`` for 818 of
            the 826 valid poses on 2,700 fresh frames at 640x480 (``reports/flip_s22/big2700_shipped.json.gz``)
            and for 381 of the 384 on nine sets of eight rigs with baselines of 0.3-2 m, where it reaches
            2.1 m (``python reports/rigs_s23/summarize.py``). In the JSON line (for a valid pose; ``null``
            otherwise) since session 23; since session 25 also where only ``position_valid`` holds.
        position: (3,) camera-frame position (m) of the target's centre (the bundle's ``centre``, on the
            flip axis): ``R @ centre + t`` of the reported pose; NaN when there is none.
        position_valid: whether ``position`` can be used. True for a valid pose, and also for a frame
            the estimator found, registered (enough stereo points on the surface, the distance in range)
            but could not tell from its 180° flip (``weak_votes`` from the flip decision): the flip turns
            the target about an axis through ``centre``, so both candidates put the centre at the same
            place. ``position`` is then the centre of the outline stage's best fit when that fits within
            ``silhouette.max_chamfer_px``, else of the registered pose (with ``registration.position_lateral``
            moved parallel to the image plane so that its outline's centroid is the observed one's), either
            moved nearer along its line of sight by ``registration.position_range_bias_outline`` or
            ``..._registered`` depth tolerances (session 32: the stereo points' range bias). A
            navigation filter can use the relative position on such frames without the attitude (``valid``
            stays false: the attitude is unknown up to the flip). Only where the frame's ``depth_tolerance_m``
            is at most the bundle's ``registration.position_max_tau_m`` (0, the default: only with a valid
            pose), and, with ``registration.position_max_chamfer_px``, where the outline's best fit is within
            it. Accuracy: the model card, "Target position without attitude" and "The position of a frame
            without a pose".
            In the JSON line since session 25.
        position_cov: (3, 3) covariance of ``position`` (m^2, camera frame) for a valid pose, from the
            bundle's ``uncertainty`` model (:mod:`spacepose.uncertainty`: long along the line of sight,
            where the stereo depth is coarse), and for a position without a pose from its
            ``position_uncertainty`` model (session 29; it widens with the outline's chamfer); NaN without a
            position, a depth tolerance or the section that applies.
            ``sigma_rotation_deg``: the per-axis standard deviation of the attitude's error (degrees), NaN
            likewise and where the model needs the outline's chamfer and there is none. In the JSON line since session 28 (``null`` where NaN). Measured coverage: the model
            card, "Per-frame uncertainty".
        tracked: the pose was decided by the prior, the last valid pose at most ``prior_max_gap``
            frames back (registration with ``use_prior``: the frame alone could not tell the pose
            from its flip). In the JSON line since session 13 (a key beyond the CONVENTIONS.md ones).
        outline_chamfer_px, outline_margin_px: with the bundle's ``silhouette`` stage, the chamfer
            distance (outline px: pixels of a ``max_side_px`` view of the stereo window) of the best outline-refined pose to the outline the stereo
            disparity shows, and the gap to the best pose more than 90° from it
            (:mod:`spacepose.silhouette`); NaN when the stage did not run. Not part of the JSON line.
        outline_image_score, outline_image_background, outline_image_pixels: the left image's vote for
            that pose against its flip, the lit share of the sky ring around them, and how many pixels
            their outlines differ in (:mod:`spacepose.image_vote`); NaN when the vote was not taken.
            Not part of the JSON line.
        polish_deg, polish_m: how far the silhouette stage's polish (``polish`` of the bundle's
            ``silhouette`` section, :func:`spacepose.silhouette.polish_pose`) moved the decided pose; NaN
            when it did not run or was not used. Not part of the JSON line.
        range_fit_m: with the bundle's ``range_fit`` (:mod:`spacepose.range_fit`), how far the fit moved a valid
            pose's centre along its line of sight (m, positive: farther), or, with its ``positions``, the position
            of a frame without a pose; NaN when it did not run or was not applied. Not part of the JSON line.
        flip_prob: with the bundle's ``flip_classifier``, the probability the classifier gives the outline
            stage's winner against its 180° flip (:mod:`spacepose.flip_classifier`); NaN when it did not
            run. Not part of the JSON line.
        decided: ``(R, t)`` before the polish, when it moved the pose (the next frame's tracking
            compares with it: the tracking gates were set on unpolished poses); ``None`` otherwise.
        decided_by: for a valid pose, what picked it from its flip (:data:`DECISION_ROUTES`):
            ``"outline"`` (the outline's fit and margin), ``"image"`` (the image vote's route of the
            silhouette stage), ``"registration"`` (the stereo points' score gap), ``"classifier"`` (the
            flip classifier), ``"tracked"`` (the prior) or ``"votes"`` (the keypoint votes, bundles
            without registration); ``""`` for an invalid result. Not part of the JSON line.
    """

    R: np.ndarray
    t: np.ndarray
    q_wxyz: np.ndarray
    valid: bool
    status: str
    confidence: float
    timings_ms: dict[str, float] = field(default_factory=dict)
    network_ms: float = 0.0
    n_points: int = 0
    roi: tuple[int, int, int, int] | None = None
    detail: str = ""
    flip_margin: float = float("nan")
    depth_tolerance_m: float = float("nan")
    tracked: bool = False
    outline_chamfer_px: float = float("nan")
    outline_margin_px: float = float("nan")
    outline_image_score: float = float("nan")
    outline_image_background: float = float("nan")
    outline_image_pixels: float = float("nan")
    polish_deg: float = float("nan")
    polish_m: float = float("nan")
    flip_prob: float = float("nan")
    range_fit_m: float = float("nan")
    decided: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False)
    decided_by: str = ""
    position: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    position_valid: bool = False
    position_cov: np.ndarray = field(default_factory=lambda: np.full((3, 3), np.nan))
    sigma_rotation_deg: float = float("nan")
    decision_confidence: float = 0.0

    def to_dict(self, frame: str | None = None) -> dict[str, Any]:
        """JSON-serialisable record (CONVENTIONS.md ``estimate`` line; NaN becomes ``null``)."""

        def clean(values: np.ndarray) -> Any:
            return [clean(v) for v in values] if values.ndim > 1 else [
                float(v) if math.isfinite(v) else None for v in values]

        out: dict[str, Any] = {} if frame is None else {"frame": frame}
        out.update({
            "valid": bool(self.valid),
            "status": self.status,
            "R": clean(np.asarray(self.R)),
            "t": clean(np.asarray(self.t)),
            "q_wxyz": clean(np.asarray(self.q_wxyz)),
            "confidence": float(self.confidence),
            "timings_ms": {k: round(float(v), 3) for k, v in self.timings_ms.items()},
            "n_points": int(self.n_points),
            "roi": None if self.roi is None else [int(v) for v in self.roi],
            "tracked": bool(self.tracked),
            "depth_tolerance_m": (float(self.depth_tolerance_m)
                                  if (self.valid or self.position_valid) and math.isfinite(self.depth_tolerance_m)
                                  else None),
            "position": clean(np.asarray(self.position)),
            "position_valid": bool(self.position_valid),
            "position_cov": clean(np.asarray(self.position_cov)) if np.all(np.isfinite(self.position_cov)) else None,
            "sigma_rotation_deg": float(self.sigma_rotation_deg) if math.isfinite(self.sigma_rotation_deg) else None,
        })
        if self.detail:
            out["detail"] = self.detail
        return out


def rotation_to_quaternion(R: np.ndarray) -> np.ndarray:
    """Scalar-first unit quaternion ``[w, x, y, z]`` of a rotation matrix (w >= 0; NaN in, NaN out)."""
    R = np.asarray(R, dtype=np.float64)
    if not np.all(np.isfinite(R)):
        return np.full(4, np.nan)
    m00, m11, m22 = R[0, 0], R[1, 1], R[2, 2]
    trace = m00 + m11 + m22
    if trace > 0.0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = [0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    elif m00 > m11 and m00 > m22:
        s = 2.0 * math.sqrt(1.0 + m00 - m11 - m22)
        q = [(R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s]
    elif m11 > m22:
        s = 2.0 * math.sqrt(1.0 + m11 - m00 - m22)
        q = [(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + m22 - m00 - m11)
        q = [(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s]
    q = np.asarray(q)
    q /= np.linalg.norm(q)
    return -q if q[0] < 0 else q


def _full_scale(image: np.ndarray) -> float:
    if image.dtype == np.uint16:
        return 65535.0
    return 255.0


def refine_icp(R: np.ndarray, t: np.ndarray, scene: np.ndarray, model: np.ndarray, model_normals: np.ndarray,
               max_distance: float, iterations: int = 5, max_points: int = 500, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Point-to-plane ICP of a pose against stereo points (numpy, brute-force nearest neighbours).

    Each scene point (camera frame) is paired with the nearest model surface sample under the
    current pose; pairs farther than ``max_distance`` are dropped; the linearised point-to-plane
    system ``[q x n, n] [w; tau] = n . (p - q)`` (model normals ``n``) is solved by least squares
    and the small rotation ``exp(w)`` and ``tau`` are applied to the pose. Stops early with fewer
    than 6 pairs. Returns the refined ``(R, t)``.
    """
    R = np.asarray(R, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    scene = np.asarray(scene, dtype=np.float64)
    if len(scene) > max_points:
        scene = scene[np.random.default_rng(seed).choice(len(scene), max_points, replace=False)]
    model = np.asarray(model, dtype=np.float64)
    normals = np.asarray(model_normals, dtype=np.float64)
    for _ in range(int(iterations)):
        q_all = model @ R.T + t
        n_all = normals @ R.T
        d2 = (np.einsum("ij,ij->i", scene, scene)[:, None] + np.einsum("ij,ij->i", q_all, q_all)[None]
              - 2.0 * scene @ q_all.T)
        nearest = np.argmin(d2, axis=1)
        close = d2[np.arange(len(scene)), nearest] <= max_distance ** 2
        if int(close.sum()) < 6:
            break
        p, q, n = scene[close], q_all[nearest[close]], n_all[nearest[close]]
        A = np.hstack([np.cross(q, n), n])
        b = np.einsum("ij,ij->i", n, p - q)
        x, *_ = np.linalg.lstsq(A, b, rcond=None)
        w, tau = x[:3], x[3:]
        angle = float(np.linalg.norm(w))
        if angle > 1e-12:
            k = w / angle
            K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
            dR = np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K
        else:
            dR = np.eye(3)
        R, t = dR @ R, dR @ t + tau
        if angle < 1e-6 and np.linalg.norm(tau) < 1e-6:
            break
    return R, t


def _stage_invalid(stage: PoseStageResult, status: str, factors: dict[str, float] | None = None) -> PoseStageResult:
    """``stage`` marked invalid with ``status`` (pose kept for diagnostics only, confidence 0)."""
    return dataclasses.replace(stage, valid=False, status=status, confidence=0.0,
                               factors={**stage.factors, **(factors or {})})


def _surface_normals(points: np.ndarray, k: int = 12) -> np.ndarray:
    """PCA normals of surface samples (orientation irrelevant for point-to-plane)."""
    from .pose_inputs import knn_indices

    if len(points) < 3:
        return np.zeros_like(points)
    nbr = knn_indices(points, points, min(k, len(points)))
    nb = points[nbr]
    centred = nb - nb.mean(axis=1, keepdims=True)
    _, vecs = np.linalg.eigh(np.einsum("nki,nkj->nij", centred, centred))
    return vecs[:, :, 0]


class PoseEstimator:
    """Stereo pose of the bundle's target from raw camera pairs (see the module docstring).

    Args:
        calib: calibration file (OpenCV FileStorage) or a :class:`~spacepose.calibration.rig.StereoRig`.
        bundle: model bundle folder, a loaded :class:`~spacepose.bundle.ModelBundle`, or ``None`` for
            the default bundle.
        threads: onnxruntime intra-op threads per graph.
        use_prior: let the previous valid pose decide between a registered pose and its flip
            (``tracked``), and, with ``prior_window``, give the next frame its stereo window.
        prior_max_gap: a valid pose stays the prior through this many following frames without one
            (an eclipse, a frame whose checks refuse its pose; a ``bad_input`` frame does not count and
            leaves the prior as it was); 0: only the frame right after it. With ``prior_window``, only the frame right after a valid one takes its window from the prior: after a
            frame without a valid pose the coarse pass looks at the whole frame again (on independent
            frames a stale window cost valid poses). The tracking gates
            (``registration.track_max_deg`` / ``track_max_m``) are not widened for the gap, so after a
            longer gap the target must still be within them of the old pose (a flip, 180° away, never
            is). Measured on rendered sequences (``python -m spacepose.tools.sequence eval``): in session 13,
            with the previous pose's window, 5 instead of 0 gave 349 instead of 291 valid frames of 560 on 14
            blind ones, no flip, but 20 instead of 8 valid poses off by more than 20° or 0.5 m. In session 30,
            with the coarse pass on every frame, 2 instead of 0 gave 239 instead of 211 valid poses on 16 fresh
            sequences, 1 wrong either way, 86 instead of 80 within 0.10 m and 2° (``reports/sequence_s30/rule2.txt``):
            the default since.
        refine: point-to-plane ICP against the stereo points (needs ``surface_points`` in the bundle).
        seed: seed of the point sampling and MeanShift seeds (results are deterministic).
        position_window: with ``use_prior``, a frame right after one that reported only a position
            (``position_valid`` without a valid pose) takes its stereo window from that position: the
            target's bounding sphere about it, widened by that frame's ``depth_tolerance_m`` (skips the
            coarse pass; a window that loses the target is looked for again with it). It never decides a
            pose: the prior stays the last valid pose. Off by default: on 13 fresh sequences it gave 178
            valid poses (18 off by > 20° or 0.5 m, one > 90° off) against 238 (26, none) without it (session
            25, ``reports/position_s25/judge3.py``).
        prior_window: with ``use_prior``, the frame right after a valid pose takes its stereo window from
            that pose (the target's bounding sphere about it; skips the coarse pass). Off by default since
            session 30: every frame's window comes from the coarse pass, and the previous pose still decides a
            pose from its flip. The sphere's window is larger than the coarse pass's box (median side 283
            against 227 px at 640x480), so the stereo graph sees the target coarser: on 16 fresh sequences the
            prior's window gave 267 valid poses, 11 wrong and 68 within 0.10 m and 2 degrees, the coarse pass
            260, 5 and 81, at about 45 ms more per frame (``reports/sequence_s30``).

    Raises:
        CalibrationError: unreadable calibration. BundleError: unusable bundle, or one that does not
            fit the calibration (:meth:`ModelBundle.check_fits`).
    """

    def __init__(self, calib: str | os.PathLike | Any, bundle: str | os.PathLike | ModelBundle | None = None,
                 threads: int = 2, use_prior: bool = True, refine: bool = False, seed: int = 0,
                 prior_max_gap: int = PRIOR_MAX_GAP, position_window: bool = False, prior_window: bool = False) -> None:
        from .calibration.rectify import rectify
        from .calibration.rig import StereoRig, load_rig
        from .onnx_session import make_session
        from .stereo_stage import StereoMatcher

        if isinstance(calib, (str, Path, os.PathLike)):
            rig = load_rig(calib)
        elif isinstance(calib, StereoRig):
            rig = calib
        else:
            raise TypeError(f"calib must be a path or a StereoRig, got {type(calib).__name__}")
        self.bundle = bundle if isinstance(bundle, ModelBundle) else load_bundle(bundle)
        self.bundle.check_fits(rig)
        self.rig = rig
        self.rectification = rectify(rig)
        self.K = self.rectification.K
        self.focal_px = self.rectification.focal_px
        self.baseline_m = self.rectification.baseline_m
        self.threads = int(threads)
        self.use_prior = bool(use_prior)
        if int(prior_max_gap) < 0:
            raise ValueError(f"prior_max_gap must be >= 0, got {prior_max_gap}")
        self.prior_max_gap = int(prior_max_gap)
        self.refine = bool(refine)
        self.seed = int(seed)
        self.stereo = StereoMatcher(self.bundle.stereo_path, threads=self.threads,
                                    margin=self.bundle.stereo.window_margin,
                                    coarse_tiles=self.bundle.coarse_tiles_for(rig))
        # fixed input sizes: onnxruntime's memory arena reuses its blocks (see StereoMatcher's mem_arena)
        self.pose_session = make_session(self.bundle.pose_path, threads=self.threads, mem_arena=True)
        self._pose_outputs = [o.name for o in self.pose_session.get_outputs()]
        self._pose_inputs = [i.name for i in self.pose_session.get_inputs()]  # variants drop unused inputs
        for name in ("seg_logits", "kp_offsets", "ctr_offsets"):
            if name not in self._pose_outputs:
                from .errors import BundleError

                raise BundleError(f"pose graph has no output {name!r} (outputs: {self._pose_outputs})")
        self._spec = self.bundle.pose.input_spec
        surface = np.asarray(self.bundle.surface_points)
        self._surface = np.asarray(surface, dtype=np.float64).reshape(-1, 3)   # the range fit's samples
        wants_normals = (self.refine or self.bundle.registration is not None) and len(surface)
        self._surface_normals = ((np.asarray(self.bundle.surface_normals) if len(self.bundle.surface_normals)
                                  else _surface_normals(surface)) if wants_normals else None)
        self._registration = (SurfaceModel(surface, self._surface_normals)
                              if self.bundle.registration is not None else None)
        self._outline_points = (np.ascontiguousarray(self.bundle.silhouette_points, dtype=np.float32)
                                if self.bundle.silhouette is not None and self._registration is not None else None)
        fc = self.bundle.flip_classifier
        self._flip_classifier = (FlipClassifier(self.bundle.path, fc, self.bundle.target_name, threads=self.threads)
                                 if fc is not None and self._outline_points is not None else None)
        orf = self.bundle.outline_refiner
        self._outline_refiner = (OutlineRefiner(self.bundle.path, orf, self.bundle.target_name, threads=self.threads)
                                 if orf is not None and self._outline_points is not None else None)
        sil = self.bundle.silhouette
        self._outline_templates = (
            OutlineTemplates(self._outline_points, np.asarray(self.bundle.centre), float(self.bundle.radius),
                             views=sil.search_views, grid=sil.search_grid)
            if self._outline_points is not None and sil.search_candidates > 0 else None)
        self._lock = threading.Lock()
        self._prior: PoseResult | None = None   # the last valid pose (the prior) ...
        self._prior_gap = 0                      # ... and how many frames since it
        self.position_window = bool(position_window)
        self.prior_window = bool(prior_window)
        self._last_position: tuple[np.ndarray, float] | None = None   # the last frame's position-only result

    def nees_gate(self, probability: float = 0.99) -> float:
        """The normalised squared error a right pose's position (against ``position_cov``, 3 axes) or rotation
        (against ``sigma_rotation_deg`` per axis, 3 axes) stays at or under with ``probability``: the gate a
        navigation filter sets to keep that share of right poses. From the bundle's ``uncertainty.tail_dof``
        (the errors' Student-t tails, :mod:`spacepose.tails`); chi-square when it is 0 or the bundle has no
        ``uncertainty`` section."""
        config = self.bundle.uncertainty
        return nees_gate(probability, 3, 0.0 if config is None else config.tail_dof)

    # ------------------------------------------------------------------ prior
    def reset(self) -> None:
        """Forget the previous pose (the next frame runs the coarse stereo pass)."""
        with self._lock:
            self._prior, self._prior_gap = None, 0
            self._last_position = None

    def _roi_hint(self):
        from .stereo_stage import RoiHint

        # a window only from the frame right before (see __init__)
        prior = self._valid_prior(max_gap=0) if self.prior_window else None
        r = self.bundle.radius
        if prior is not None:
            centre = prior[0] @ self.bundle.centre + prior[1]
        else:
            with self._lock:
                last = self._last_position if self.position_window and self.use_prior else None
            if last is None:
                return None
            centre, r = last[0], r + last[1]   # the position is known to its depth tolerance
        z = float(centre[2])
        if z - r <= 0.0:
            return None
        uv = self.K @ (centre / z)
        r_px = self.focal_px * r / (z - r)
        w, h = self.rig.image_size
        x0, y0 = int(math.floor(uv[0] - r_px)), int(math.floor(uv[1] - r_px))
        x1, y1 = int(math.ceil(uv[0] + r_px)) + 1, int(math.ceil(uv[1] + r_px)) + 1
        x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)
        if x1 - x0 < 2 or y1 - y0 < 2:
            return None
        fb = self.focal_px * self.baseline_m
        return RoiHint((x0, y0, x1, y1), fb / (z + r), fb / (z - r))

    # ------------------------------------------------------------------ checks
    def _input_problem(self, left: Any, right: Any) -> tuple[str, str] | None:
        """(status, detail) when the pair cannot be used, else None. Raises for non-arrays."""
        for name, image in (("left", left), ("right", right)):
            if not isinstance(image, np.ndarray):
                raise ShapeError(f"{name} must be a numpy array, got {type(image).__name__}")
        for name, image in (("left", left), ("right", right)):
            if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] not in (1, 3)):
                return "bad_input", f"{name} has shape {image.shape}; need (H, W), (H, W, 1) or (H, W, 3)"
            if not (image.dtype in (np.uint8, np.uint16) or np.issubdtype(image.dtype, np.floating)):
                return "bad_input", f"{name} has dtype {image.dtype}; need uint8, uint16 or float"
        if left.shape != right.shape or left.dtype != right.dtype:
            return "bad_input", f"left {left.shape} {left.dtype} and right {right.shape} {right.dtype} differ"
        w, h = self.rig.image_size
        if left.shape[1] != w or left.shape[0] != h:
            return "bad_input", f"images are {left.shape[1]}x{left.shape[0]}, the calibration is {w}x{h}"
        if np.issubdtype(left.dtype, np.floating):
            if not (np.all(np.isfinite(left)) and np.all(np.isfinite(right))):
                return "bad_input", "images hold NaN or inf"
        full = _full_scale(left)
        # compare in the image's own dtype (a Python float would promote a uint8 frame to float64)
        full_value = left.dtype.type(full)
        for name, image in (("left", left), ("right", right)):
            peak = image.max()
            if float(peak) <= DARK_FRACTION * full:
                return "no_target", f"{name} image is dark (eclipse?)"
            if peak >= full_value and np.count_nonzero(image >= full_value) > SATURATED_FRACTION * image.size:
                return "bad_input", f"{name} image is saturated"
        return None

    # ------------------------------------------------------------------ main
    def _result(self, status: str, timer: StageTimer, *, stage: PoseStageResult | None = None,
                window: roi.Window | None = None, detail: str = "") -> PoseResult:
        if stage is not None and stage.valid:
            R, t, conf, valid = stage.R, stage.t, stage.confidence, True
        else:
            R, t, conf, valid = np.full((3, 3), np.nan), np.full(3, np.nan), 0.0, False
        factors = {} if stage is None else stage.factors

        def factor(name: str) -> float:
            return float(factors.get(name, float("nan")))

        if valid:
            position = np.asarray(R, dtype=np.float64) @ np.asarray(self.bundle.centre, dtype=np.float64) + t
        elif status == "weak_votes" and all(key in factors for key in _POSITION_KEYS):
            position = np.array([factor(key) for key in _POSITION_KEYS])
        else:
            position = np.full(3, np.nan)
        position_valid = bool(np.all(np.isfinite(position)))

        result = PoseResult(R=R, t=t, q_wxyz=rotation_to_quaternion(R), valid=valid, status=status,
                            confidence=float(conf), decision_confidence=float(conf), timings_ms=dict(timer.timings_ms),
                            network_ms=timer.network_ms,
                            n_points=0 if stage is None else int(stage.n_inliers),
                            roi=None if window is None else window.bbox, detail=detail,
                            flip_margin=factor("flip_margin"), depth_tolerance_m=factor("depth_tolerance_m"),
                            tracked=bool(valid and factors.get("tracked", 0.0)),
                            outline_chamfer_px=factor("outline_chamfer_px"),
                            outline_margin_px=factor("outline_margin_px"),
                            outline_image_score=factor("outline_image_score"),
                            outline_image_background=factor("outline_image_background"),
                            outline_image_pixels=factor("outline_image_pixels"),
                            polish_deg=factor("polish_deg"), polish_m=factor("polish_m"),
                            flip_prob=factor("flip_prob"), range_fit_m=(factor("range_fit_m") if valid else
                                                                 factor("position_range_fit_m") if position_valid
                                                                 else math.nan),
                            decided=stage.decided if valid else None,
                            decided_by=_route_name(factors) if valid else "",
                            position=position, position_valid=position_valid)
        if valid and self.bundle.uncertainty is not None:
            spread = pose_uncertainty(position, result.depth_tolerance_m, self.focal_px, self.bundle.uncertainty,
                                      result.outline_chamfer_px)
            if spread is not None:
                result = dataclasses.replace(result, position_cov=spread.position_cov,
                                             sigma_rotation_deg=spread.sigma_rotation_deg)
            if self.bundle.confidence is not None:
                result = dataclasses.replace(result, confidence=self._pose_confidence(spread))
                floor = self.bundle.confidence.min_valid
                if result.confidence < floor:
                    # too unsure to hand to a navigation filter: the frame reports what it would without a
                    # decision (the position from the factors, where the position gates passed), and the pose
                    # does not become the next frame's prior
                    detail = (f"confidence {result.confidence:.3f} under the bundle's floor {floor:g} "
                              f"(confidence.min_valid)")
                    return self._result("weak_votes", timer, stage=_stage_invalid(stage, "weak_votes"),
                                        window=window, detail=detail)
        elif position_valid and not valid and self.bundle.position_uncertainty is not None:
            spread = position_uncertainty(position, result.depth_tolerance_m, self.focal_px,
                                          self.bundle.position_uncertainty, result.outline_chamfer_px)
            if spread is not None:
                result = dataclasses.replace(result, position_cov=spread.position_cov)
        if status == "bad_input":  # a bad frame says nothing about where the target is: the prior stays as it was
            return result
        with self._lock:
            tau = result.depth_tolerance_m
            self._last_position = ((result.position.copy(), float(tau))
                                   if position_valid and not valid and math.isfinite(tau) else None)
            if valid:
                self._prior, self._prior_gap = result, 0
            elif factors.get("prior_conflict"):  # decided, but half turned from the prior: trust neither
                self._prior, self._prior_gap = None, 0
            elif self._prior is not None:  # a frame without a valid pose: the prior ages (the target moves on)
                self._prior_gap += 1
                if self._prior_gap > self.prior_max_gap:
                    self._prior, self._prior_gap = None, 0
        return result

    def estimate(self, left: np.ndarray, right: np.ndarray) -> PoseResult:
        """Pose of the target in a raw stereo pair (see the module docstring for the input rule).

        Raises:
            ShapeError: ``left`` or ``right`` is not a numpy array.
        """
        timer = StageTimer()
        with timer.stage("validate"):
            problem = self._input_problem(left, right)
        if problem is not None:
            logger.info("frame rejected: %s (%s)", problem[0], problem[1])
            return self._result(problem[0], timer, detail=problem[1])

        with timer.stage("rectify"):
            left_r, right_r = self.rectification.rectify_pair(left, right)
        hint = self._roi_hint()
        outcome = self._pose_from_pair(left_r, right_r, hint, timer)
        if hint is not None and outcome[0] in _WINDOW_MISSES:
            # the previous pose's window may have lost the target (it moved, or the frames are not a
            # sequence): look again over the whole frame rather than report a miss. A frame that found
            # and registered the target but cannot tell its pose from the flip (weak_votes) would only
            # find the same target again, at twice the cost
            logger.info("prior window gave %s; retrying with the coarse pass", outcome[0])
            outcome = self._pose_from_pair(left_r, right_r, None, timer)
        status, stage, window, detail = outcome
        return self._result(status, timer, stage=stage, window=window, detail=detail)

    def _pose_confidence(self, spread: PoseUncertainty | None) -> float:
        """The bundle's ``confidence`` model for a valid pose's uncertainty ``spread`` (0 without one, or
        without finite positive sigmas: no accuracy is claimed)."""
        config = self.bundle.confidence
        sigmas = () if spread is None else (spread.sigma_range_m, spread.sigma_lateral_m, spread.sigma_rotation_deg)
        if config is None or not sigmas or not all(math.isfinite(v) and v > 0.0 for v in sigmas):
            return 0.0
        p = within_probability(spread.sigma_range_m, spread.sigma_lateral_m, spread.sigma_rotation_deg, config)
        return calibrated_confidence(p, config)

    def _register(self, xyz: np.ndarray, stage: PoseStageResult, stereo: Any, timer: StageTimer,
                  left_r: np.ndarray | None = None) -> tuple[PoseStageResult, str]:
        """Multi-start registration (:mod:`spacepose.registration`) seeded with the network's pose
        (and the prior, the last valid pose, with ``use_prior``), each with its flip; then, with
        the bundle's ``silhouette`` stage, the outline (:mod:`spacepose.silhouette`).

        The registered pose replaces the voted one; its validity is the registration's own
        (inlier share, the fitted distance in range). Which of the registered pose and its flip it
        is, is decided, in this order, by:

        1. the outline: both refined against the outline the stereo disparity shows; the winner
           is valid when it fits well (``max_chamfer_px``) and clearly better than the best pose
           more than 90° from it (``min_margin_px``); with the stage's ``image_vote``, the lit pixels of
           ``left_r`` where the winner's outline and its flip's differ may also decide a frame with a
           smaller margin, or leave one with a large margin undecided (:mod:`spacepose.image_vote`,
           :class:`spacepose.silhouette.SilhouetteConfig`). Confidence
           ``inlier_fraction * (1 - exp(-margin_px / min_margin_px))``. When the registration is
           conclusive (below) and picks the other one, the frame is ``weak_votes``.
        2. the registration's margin over its best distinct alternative (``min_margin``, with a
           depth fine enough, ``max_tau_m``), provided the outline's best fit, however undecided,
           is on the same side and the image vote does not veto it (else ``weak_votes``): confidence
           ``inlier_fraction * (1 - exp(-margin / min_margin))``; the pose is the outline-refined
           one when that refinement fits the outline within ``max_chamfer_px``.
        3. the prior (the last valid pose, at most ``prior_max_gap`` frames back), when exactly one
           of the two is near it
           (:func:`spacepose.registration.select_with_prior`): "tracked", confidence
           ``0.5 * inlier_fraction``. The outline-refined poses that fit within ``max_chamfer_px``
           are asked first (they are the more accurate, so they stay within the gates longer); when
           exactly one of them is near, it is reported, with the registered candidate near the
           previous pose (if any) to fall back to when the checks after refuse it. With the silhouette
           stage's ``track_needs_outline`` only such a refined pose is reported (no registered one,
           no fallback). A flip-classifier decision the polish cap refuses
           (``flip_classifier.max_polish_deg``) is left to this route too.

        Otherwise the frame is ``weak_votes``. A pose decided by 1 or 2 that is more than 90° from
        the prior is reported ``weak_votes`` too (one of the two is a flip, and the frame alone
        cannot say which), which also clears the prior. Frames that are not a sequence lose a little:
        an unrelated prior lies within the tracking gates of one of the two candidates only by rare
        chance (both 20° and 1 m by default), but a pose decided more than 90° from it is refused
        (with ``prior_max_gap`` 5, session 13's profile of 29 independent frames kept 7 valid
        instead of 8). Run them without a prior, as the evaluation of independent frames does.

        With the stage's ``polish``, the pose so decided is refined once more against the outline
        (:func:`spacepose.silhouette.polish_pose`) and reported; the next frame tracks from the pose as
        decided (``PoseResult.decided``).
        """
        config, bundle = self.bundle.registration, self.bundle
        axis = bundle.voting.flip_axis
        prior = self._valid_prior()
        seeds = []
        for R_s, t_s in ((stage.R, stage.t), prior or (None, None)):
            if R_s is not None and np.all(np.isfinite(R_s)) and np.all(np.isfinite(t_s)):
                seeds.append((R_s, t_s))
                if axis:
                    seeds.append(flipped_pose(R_s, t_s, bundle.centre, axis))
        with timer.stage("registration"):
            reg = register(xyz, self.K, self.baseline_m, self._registration, bundle.centre, config, seeds=seeds,
                           flip_axis=axis, sigma_d_px=config.sigma_d_px / max(stereo.scale, 1e-9))
        if reg is None:
            return _stage_invalid(stage, "too_few_points"), "too few stereo points to register the target"
        margin = reg.margin
        factors = {"registration_score": reg.score, "inliers": reg.inlier_fraction, "flip_margin": margin,
                   "runner_up_deg": reg.runner_up_angle_deg, "depth_tolerance_m": reg.tau_m}
        lo, hi = depth_window(bundle.distance_range_m, 0.0, bundle.voting.depth_margin)
        distance = float(np.linalg.norm(reg.t))  # as spacepose.pose_stage judges ||t||
        if reg.inlier_fraction < config.min_inlier_fraction:
            return _stage_invalid(stage, "fit_residual", factors), (
                f"only {reg.inlier_fraction:.0%} of the stereo points lie on the registered surface")
        if not lo <= distance <= hi:
            return _stage_invalid(stage, "out_of_range", factors), (
                f"registered target distance {distance:.1f} m outside {lo:.1f}-{hi:.1f} m")
        R, t, fallback = reg.R, reg.t, None
        conclusive = margin >= config.min_margin and reg.tau_m <= config.max_tau_m
        outline = None
        if self._outline_points is not None and stereo.window is not None:
            with timer.stage("silhouette"):
                outline = self._outline(reg, xyz, stereo, left_r)
            factors.update(outline_chamfer_px=outline.best.chamfer_px, outline_margin_px=outline.margin_px)
            if outline.vote is not None:
                factors.update(outline_image_score=outline.vote.score,
                               outline_image_background=outline.vote.background_lit,
                               outline_image_pixels=float(outline.vote.pixels))
        sil = bundle.silhouette
        outline_fits_position = config.position_max_chamfer_px <= 0.0 or (
            outline is not None and outline.best.chamfer_px <= config.position_max_chamfer_px)
        if 0.0 < config.position_max_tau_m and reg.tau_m <= config.position_max_tau_m and outline_fits_position:
            # the target's centre, the same for the pose and its flip, where the depth is fine enough to trust it
            # (PoseResult.position_valid; registration.position_max_tau_m, 0: not without a valid pose). From the
            # outline's winner when it fits: its size pins the range better than the stereo points
            # (reports/position_s25/plan.txt); else from the registered pose, with position_lateral moved in
            # the image plane onto the observed outline's centroid
            fits = (outline is not None and outline.best.chamfer_px <= sil.max_chamfer_px
                    and np.all(np.isfinite(outline.best.R)) and np.all(np.isfinite(outline.best.t)))
            R_c, t_c = (outline.best.R, outline.best.t) if fits else (reg.R, reg.t)
            if not fits and config.position_lateral and outline is not None and outline.observed is not None:
                # the registered pose's outline moved onto the observed one (session 26)
                shifted = align_centroid(reg.R, reg.t, self._outline_points, outline.observed, outline.frame)
                t_c = t_c if shifted is None else shifted
            position = range_debiased(R_c @ bundle.centre + t_c, reg.tau_m, config.position_range_bias_outline
                                      if fits else config.position_range_bias_registered)
            factors.update(zip(_POSITION_KEYS, (float(v) for v in position)))
            stage = dataclasses.replace(stage, position_pose=(R_c, position - R_c @ np.asarray(bundle.centre)))
        flip_p, flip_input = self._flip_probability(outline, stereo, left_r, timer)
        if flip_p is not None:
            factors["flip_prob"] = flip_p
            fc = bundle.flip_classifier
            if flip_p <= fc.veto_prob and (outline.decided(sil) or conclusive):
                return _stage_invalid(stage, "weak_votes", factors), (
                    f"the flip classifier gives the decided pose {flip_p:.2f} against its flip")
            if (fc.loose_fit_min_prob > 0.0 and outline.decided(sil) and outline.best.chamfer_px > sil.max_chamfer_px
                    and not flip_p >= fc.loose_fit_min_prob):
                return _stage_invalid(stage, "weak_votes", factors), (
                    f"the outline fits loosely ({outline.best.chamfer_px:.2f} px > {sil.max_chamfer_px:g} px) and the "
                    f"flip classifier gives the pose only {flip_p:.3f} (< {fc.loose_fit_min_prob:g})")
        learned = self._learned_choice(outline, flip_p, reg.tau_m, flip_input, timer)
        if outline is not None and outline.decided(sil):
            if conclusive and float(rotation_angle_deg(reg.R, outline.best.R)) > 90.0:
                return _stage_invalid(stage, "weak_votes", factors), (
                    "the outline and the stereo points pick opposite poses (the pose and its flip)")
            R, t = outline.best.R, outline.best.t
            confidence = reg.inlier_fraction * (1.0 - math.exp(-outline.margin_px / max(sil.min_margin_px, 1e-9)))
            by_margin = outline.best.chamfer_px <= sil.max_chamfer_px and outline.margin_px >= sil.min_margin_px
            factors["route"] = _route_code("outline" if by_margin else "image")
        elif conclusive:
            if outline is not None and float(rotation_angle_deg(reg.R, outline.best.R)) > 90.0:
                # the stereo points decide, but the outline, undecided as it is, leans to the flip: on
                # 9 frames so decided (session 8), both flips were of this kind and none of the 7 good poses
                return _stage_invalid(stage, "weak_votes", factors), (
                    f"the stereo points prefer the pose (score gap {margin:.4f}) but the outline leans to its flip "
                    f"(chamfer {outline.best.chamfer_px:.2f} px, margin {outline.margin_px:.2f} px)")
            if outline is not None and outline.image_vetoes(sil):
                return _stage_invalid(stage, "weak_votes", factors), (
                    f"the stereo points prefer the pose (score gap {margin:.4f}) but the image does not back it "
                    f"(image vote {outline.vote.score:+.2f})")
            if (self._flip_classifier is not None and (need := bundle.flip_classifier.registration_min_prob) > 0.0
                    and not (flip_p is not None and flip_p >= need)):
                # the one route the classifier need not back otherwise; a flip so decided at p 0.59 (session 27)
                return _stage_invalid(stage, "weak_votes", factors), (
                    f"the stereo points prefer the pose (score gap {margin:.4f}) but the flip classifier gives it "
                    + ("no probability" if flip_p is None else f"only {flip_p:.3f}") + f" (< {need:g})")
            if outline is not None and outline.best.chamfer_px <= sil.max_chamfer_px:
                R, t = outline.best.R, outline.best.t
            confidence = reg.inlier_fraction * (1.0 - math.exp(-margin / max(config.min_margin, 1e-9)))
            factors["route"] = _route_code("registration")
        elif learned is not None:
            R, t = learned
            confidence = reg.inlier_fraction * abs(2.0 * flip_p - 1.0)
            factors["flip_decided"] = 1.0
            factors["route"] = _route_code("classifier")
        else:
            track = self._track(reg, prior, outline, margin)
            if isinstance(track, str):
                return _stage_invalid(stage, "weak_votes", factors), track
            (R, t), fallback = track
            confidence = 0.5 * reg.inlier_fraction
            factors["tracked"] = 1.0
            factors["route"] = _route_code("tracked")
        if not factors.get("tracked") and prior is not None and (turned := float(rotation_angle_deg(prior[0], R))) > 90.0:
            # decided on its own, yet half turned from the prior: one of the two is
            # wrong and nothing says which; report neither, and the next frame starts without a prior
            return _stage_invalid(stage, "weak_votes", {**factors, "prior_conflict": 1.0}), (
                f"the pose is {turned:.0f}° from the previous valid pose")
        decided, R, t = self._polish(outline, R, t, xyz, reg, factors, timer, left_r, stereo.disparity)
        if refusal := self._polish_refusal(factors, decided):
            # a refused decision is no decision: the previous pose may still pick one, as without the classifier
            track = self._track(reg, prior, outline, margin) if prior is not None else ""
            if isinstance(track, str):
                return _stage_invalid(stage, "weak_votes", factors), refusal + (f"; {track}" if track else "")
            for key in ("flip_decided", "polish_deg", "polish_m"):
                factors.pop(key, None)
            (R, t), fallback = track
            confidence = 0.5 * reg.inlier_fraction
            factors.update(tracked=1.0, route=_route_code("tracked"))
            decided, R, t = self._polish(outline, R, t, xyz, reg, factors, timer, left_r, stereo.disparity)
            cap = 0.0 if bundle.silhouette is None else bundle.silhouette.max_refused_track_polish_deg
            if cap > 0.0 and decided is not None and factors.get("polish_deg", 0.0) > cap:
                return _stage_invalid(stage, "weak_votes", factors), (
                    f"{refusal}; the previous pose tracks it, but the polish turns that pose "
                    f"{factors['polish_deg']:.1f}° too (more than {cap:.1f}°)")
        bandwidth = stage.bandwidth if math.isfinite(stage.bandwidth) else reg.tau_m  # tolerance of the checks after
        n_inliers = int(round(reg.inlier_fraction * reg.n_points))  # PoseResult.n_points: the points it rests on
        return dataclasses.replace(stage, R=R, t=t, valid=True, status="ok", confidence=float(confidence),
                                   bandwidth=bandwidth, n_inliers=n_inliers, factors={**stage.factors, **factors},
                                   fallback=fallback, decided=decided), ""

    def _polish_refusal(self, factors: dict[str, float], decided: tuple[np.ndarray, np.ndarray] | None) -> str:
        """Why the polish refuses the pose just decided ("" when it does not): a flip-classifier decision needs a
        polish within ``flip_classifier.max_polish_deg`` (a polish that did not run, or was not used, refuses
        too); a decision of the outline, image or registration route one within
        ``silhouette.max_decided_polish_deg`` when that is set (a polish that did not run does not refuse)."""
        moved = factors.get("polish_deg", float("nan")) if decided is not None else float("nan")
        if factors.get("flip_decided"):
            cap = self.bundle.flip_classifier.max_polish_deg
            if cap > 0.0 and not moved <= cap:
                return (f"the flip classifier decided the pose, but the polish turned it {moved:.1f}° "
                        f"(more than {cap:.1f}°, or it did not run)")
            return ""
        sil, route = self.bundle.silhouette, _route_name(factors)
        cap = 0.0 if sil is None else sil.max_decided_polish_deg
        if cap > 0.0 and route in ("outline", "image", "registration") and moved > cap:
            return (f"the {route} route decided the pose, but the polish turned it {moved:.1f}° (more than "
                    f"{cap:.1f}°: session 31, such turns mark poses far off)")
        return ""

    def _track(self, reg: Any, prior: tuple[np.ndarray, np.ndarray] | None, outline: Any,
               margin: float) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray] | None] | str:
        """The pose the previous one picks (route 3 of :meth:`_register`): ``((R, t), fallback)``, or why
        it picks none. The outline-refined fits within ``max_chamfer_px`` (or the looser
        ``track_max_chamfer_px``) are asked first; when exactly
        one is near the prior it is the pose, with the registered candidate near the prior (if any) to
        fall back on. Else the registered candidate near the prior, unless the silhouette stage's
        ``track_needs_outline`` asks for an outline fit (then no fallback either)."""
        config, sil = self.bundle.registration, self.bundle.silhouette
        needs_outline = outline is not None and bool(sil.track_needs_outline)
        tracked = (select_with_prior(reg, prior[0], prior[1], config)
                   if prior is not None and not needs_outline else None)
        refined = []
        if prior is not None and outline is not None:  # the outline-refined poses fit the tracking gates best
            gate = max(sil.max_chamfer_px, sil.track_max_chamfer_px)
            refined = [(fit.R, fit.t) for fit in (outline.best, outline.other)
                       if fit.chamfer_px <= gate and near_prior(fit.R, fit.t, prior[0], prior[1], config)]
        if tracked is None and len(refined) != 1:
            why = (f"a pose {reg.runner_up_angle_deg:.0f}° away fits the stereo points almost as well "
                   f"(score gap {margin:.4f} < {config.min_margin:.4f})" if margin < config.min_margin else
                   f"the stereo depth (tolerance {reg.tau_m:.2f} m > {config.max_tau_m:.2f} m) is too coarse "
                   "to tell the pose from its flip")
            if outline is not None:
                vote = ("" if outline.vote is None else
                        f", image vote {outline.vote.score:+.2f} on {outline.vote.pixels} px")
                why += (f"; the outline does not decide (chamfer {outline.best.chamfer_px:.2f} px, "
                        f"margin {outline.margin_px:.2f} px{vote})")
            if prior is not None:
                why += ("; no outline fit within the chamfer gate is near the previous pose" if needs_outline else
                        "; the previous pose does not pick one")
            return why
        if len(refined) == 1:  # the refined pose near the previous one; the registered one if the checks refuse it
            return refined[0], tracked
        return tracked, None

    def _refined(self, outline: Any, left_r: np.ndarray | None, disparity: np.ndarray | None,
                 timer: StageTimer) -> Any:
        """``outline`` (an :class:`spacepose.silhouette.OutlineDecision`) with its observed outline refined by the
        bundle's ``outline_refiner`` graph (:mod:`spacepose.outline_refiner`) against the rectified left image
        ``left_r`` and the full-frame ``disparity``; unchanged without the graph, an outline, the image or the
        disparity. The graph's run is network time."""
        if (self._outline_refiner is None or left_r is None or disparity is None or outline.frame is None
                or outline.observed is None or not (outline.min_disparity > 0.0)):
            return outline
        fr = outline.frame
        with timer.stage("silhouette"):
            grey = window_grey(left_r, fr.x0, fr.y0, fr.side, fr.size)
            ratio = crop_to_frame(np.asarray(disparity, dtype=np.float32), fr.x0, fr.y0, fr.side,
                                  fr.size) / np.float32(outline.min_disparity)
            planes = refiner_planes(grey, outline.observed, ratio)
        with timer.stage("outline_net"):
            t_net = time.perf_counter()
            logit = self._outline_refiner.logits(planes)
            timer.add_network((time.perf_counter() - t_net) * 1e3)
        refined = refined_outline(logit, outline.observed, self._outline_refiner.config.grow_px)
        return dataclasses.replace(outline, observed=refined)

    def _polish(self, outline: Any, R: np.ndarray, t: np.ndarray, xyz: np.ndarray, reg: Any, factors: dict,
                timer: StageTimer, left_r: np.ndarray | None = None, disparity: np.ndarray | None = None
                ) -> tuple[tuple[np.ndarray, np.ndarray] | None, np.ndarray, np.ndarray]:
        """``(decided, R, t)``: with the silhouette stage's ``polish``, the pose refined once more against
        the outline (``decided`` the pose before it; ``polish_deg`` and ``polish_m`` added to
        ``factors``), else ``(None, R, t)``. With the bundle's ``outline_refiner``, a polish that succeeded is
        done again against the refined outline (:meth:`_refined`; ``left_r``, ``disparity``: the rectified left
        image and the full-frame disparity), and when that succeeds too its rotation is reported, with the target's
        centre where the first polish put it (``keep_centre``) or its own position. ``polish_deg`` and
        ``polish_m``, which the polish caps read, are the first polish's in either case."""
        sil = self.bundle.silhouette
        if outline is None or not sil.polish:
            return None, R, t
        with timer.stage("silhouette"):
            polished = polish_pose(outline, R, t, self._outline_points, sil, stereo_points=xyz,
                                   surface=self._registration, tau_m=reg.tau_m)
        if polished is None:
            return None, R, t
        # the polish caps (_polish_refusal) read how far the polish against the stereo outline moved the pose,
        # with or without the refiner: which poses are refused does not change with it (session 41, round 1: caps
        # read on the refined polish refused a sixth of the valid poses)
        factors.update(polish_deg=float(rotation_angle_deg(R, polished.R)),
                       polish_m=float(np.linalg.norm(polished.t - np.asarray(t))))
        refined = self._refined(outline, left_r, disparity, timer)
        if refined is not outline:
            with timer.stage("silhouette"):
                fit = polish_pose(refined, R, t, self._outline_points, sil, stereo_points=xyz,
                                  surface=self._registration, tau_m=reg.tau_m)
            if fit is not None and self._outline_refiner.config.keep_centre:
                centre = np.asarray(self.bundle.centre, dtype=np.float64)
                fit = dataclasses.replace(fit, t=polished.R @ centre + polished.t - fit.R @ centre)
            polished = polished if fit is None else fit
        return (R, t), polished.R, polished.t

    def _verify(self, stage: PoseStageResult, xyz: np.ndarray, left_r: np.ndarray, right_r: np.ndarray,
                timer: StageTimer, fitness: float | None) -> tuple[str, str] | None:
        """The checks of a fitted pose against the data: the stereo points on the target's surface
        (``voting.min_surface_fitness``; ``fitness`` when already known) and the left and right images
        agreeing there (``voting.min_photo_consistency``). ``(status, detail)`` of the first that fails,
        else ``None``."""
        bundle, voting = self.bundle, self.bundle.voting
        if voting.min_surface_fitness > 0.0 and len(bundle.surface_points):
            if fitness is None:
                with timer.stage("verify"):
                    fitness = surface_fitness(stage.R, stage.t, xyz, np.asarray(bundle.surface_points),
                                              stage.bandwidth)
            if fitness < voting.min_surface_fitness:
                logger.info("pose rejected: surface fitness %.2f < %.2f", fitness, voting.min_surface_fitness)
                return "fit_residual", (
                    f"only {fitness:.0%} of the stereo points lie on the target surface at the fitted pose")
        if voting.min_photo_consistency > -1.0 and len(bundle.surface_points):
            with timer.stage("verify"):
                photo = photometric_consistency(stage.R, stage.t, np.asarray(bundle.surface_points), left_r, right_r,
                                                self.K, self.baseline_m)
            if photo.score is not None and photo.score < voting.min_photo_consistency:
                logger.info("pose rejected: photometric consistency %.2f < %.2f", photo.score,
                            voting.min_photo_consistency)
                return "fit_residual", f"the left and right images disagree at the fitted pose (patch ZNCC {photo.score:.2f})"
            if photo.score is None:
                logger.info("photometric check skipped: %d textured patches", photo.patches)
        return None

    def _outline(self, reg: Any, xyz: np.ndarray, stereo: Any, left_r: np.ndarray | None = None) -> Any:
        """The outline decision (:func:`spacepose.silhouette.decide_outline`) between the registered
        pose and its runner-up (when that is more than 90° away), plus the flip of the better one;
        ``left_r`` (the left rectified image) for the stage's image vote."""
        bundle = self.bundle
        axis, centre = bundle.voting.flip_axis, bundle.centre
        candidates = [(reg.R, reg.t)]
        if (reg.runner_up_angle_deg > 90.0 and np.all(np.isfinite(reg.runner_up_R))
                and np.all(np.isfinite(reg.runner_up_t))):
            candidates.append((reg.runner_up_R, reg.runner_up_t))
        flip = (lambda R, t: flipped_pose(R, t, centre, axis)) if axis else None
        w = stereo.window
        return decide_outline(candidates, self._outline_points, stereo.disparity, self.K, self.baseline_m,
                              (w.x0, w.y0, w.side), bundle.silhouette, stereo_points=xyz,
                              surface=self._registration, tau_m=reg.tau_m, flip=flip, image=left_r,
                              templates=self._outline_templates)

    def _flip_probability(self, outline: Any, stereo: Any, left_r: np.ndarray | None, timer: StageTimer
                          ) -> tuple[float | None, np.ndarray | None]:
        """The flip classifier's probability for the outline's winner against its exact flip and the
        (1, 3, S, S) views it was given (``(None, None)`` without a classifier, an outline decision or an
        image); times ``flip_net`` (the graph's run is network time, the view's making is not)."""
        if self._flip_classifier is None or outline is None or left_r is None or outline.frame is None:
            return None, None
        best = outline.best
        if not (np.all(np.isfinite(best.R)) and np.all(np.isfinite(best.t))):
            return None, None
        axis = self._flip_classifier.config.axis
        w = outline.frame
        with timer.stage("flip_net"):
            views = self._flip_classifier.views(left_r, self.K, (w.x0, w.y0, w.side), self._outline_points,
                                                (best.R, best.t), flipped_pose(best.R, best.t, self.bundle.centre, axis))
            t_net = time.perf_counter()
            p = self._flip_classifier.probability(views)
            timer.add_network((time.perf_counter() - t_net) * 1e3)
        return p, views

    def _decided_under_tones(self, views: np.ndarray | None, winner: bool, timer: StageTimer) -> bool:
        """Whether the classifier still gives the ``winner`` (else its flip) at least ``decide_prob`` with the
        views' grey plane under the tone curves of ``decide_tone_gamma`` (always, when that is 1); times
        ``flip_net`` (network time)."""
        fc = self.bundle.flip_classifier
        if fc.decide_tone_gamma == 1.0:
            return True
        if views is None:
            return False
        with timer.stage("flip_net"):
            t_net = time.perf_counter()
            p = self._flip_classifier.toned_probabilities(views, fc.decide_tone_gamma)
            timer.add_network((time.perf_counter() - t_net) * 1e3)
        return bool(np.all(p >= fc.decide_prob) if winner else np.all(p <= 1.0 - fc.decide_prob))

    def _learned_choice(self, outline: Any, flip_p: float | None, tau_m: float, views: np.ndarray | None,
                        timer: StageTimer) -> tuple[np.ndarray, np.ndarray] | None:
        """The pose the flip classifier decides on a frame (``None`` when it does not): the outline's
        winner when it gives it at least ``decide_prob``, the outline's rival when it gives the winner
        at most ``1 - decide_prob`` and that rival is the winner's flip (within 20°, refined); either
        only when the pose fits the outline within ``max_chamfer_px``, the outline margin is at least
        ``min_margin_px``, the outlines differ in enough pixels, a usable image vote does not
        back the other one, the registration's depth tolerance ``tau_m`` is at most
        ``max_depth_tolerance_m`` (when set; NaN refuses) and the decision holds under other tone curves of
        the ``views`` (``decide_tone_gamma``)."""
        if flip_p is None:
            return None
        fc, sil = self.bundle.flip_classifier, self.bundle.silhouette
        if fc.max_depth_tolerance_m > 0.0 and not tau_m <= fc.max_depth_tolerance_m:
            return None
        if outline.too_few_flip_pixels(sil) or outline.margin_px < fc.min_margin_px:
            return None
        vote = outline.vote if sil.image_vote and outline.vote is not None and outline.vote.usable else None
        best, other = outline.best, outline.other
        if flip_p >= fc.decide_prob and best.chamfer_px <= fc.max_chamfer_px:
            if vote is not None and vote.score <= sil.image_veto_score:
                return None
            return (best.R, best.t) if self._decided_under_tones(views, True, timer) else None
        if flip_p <= 1.0 - fc.decide_prob and other.chamfer_px <= fc.max_chamfer_px and np.all(np.isfinite(other.R)):
            flip_R, _ = flipped_pose(best.R, best.t, self.bundle.centre, fc.axis)
            if float(rotation_angle_deg(flip_R, other.R)) > 20.0:
                return None
            if vote is not None and vote.score >= -sil.image_veto_score:
                return None
            return (other.R, other.t) if self._decided_under_tones(views, False, timer) else None
        return None

    def _valid_prior(self, max_gap: int | None = None) -> tuple[np.ndarray, np.ndarray] | None:
        """The last valid pose, at most ``max_gap`` (default ``prior_max_gap``) frames back, when
        ``use_prior`` is on, else ``None``."""
        if not self.use_prior:
            return None
        with self._lock:
            prior, gap = self._prior, self._prior_gap
        if prior is None or not prior.valid or gap > (self.prior_max_gap if max_gap is None else max_gap):
            return None
        R, t = prior.decided if prior.decided is not None else (prior.R, prior.t)
        return np.asarray(R), np.asarray(t)

    def _pose_from_pair(self, left_r: np.ndarray, right_r: np.ndarray, hint, timer: StageTimer
                        ) -> tuple[str, PoseStageResult | None, roi.Window | None, str]:
        """stereo -> pose_inputs -> pose_net -> voting [-> refine] on a rectified pair.

        Returns ``(status, pose stage result or None, fine window or None, detail)``.
        """
        with timer.stage("stereo"):
            stereo = self.stereo.match(left_r, right_r, roi_hint=hint)
        timer.add_network(stereo.timings_ms.get("net_ms", 0.0))
        if stereo.window is None:
            return "no_target", None, None, "the coarse stereo pass found no target"

        bundle, voting = self.bundle, self.bundle.voting
        with timer.stage("pose_inputs"):
            # the very function the pose net was trained with (spacepose.tools.pose_data)
            prep = prepare_pose_inputs(
                left_r, stereo.disparity, self.K, self.baseline_m, self._spec, seed=self.seed,
                depth_range_m=depth_window(bundle.distance_range_m, bundle.radius, voting.depth_margin),
                min_points=voting.min_points)
        if prep.status != "ok":
            return prep.status, None, stereo.window, prep.detail
        xyz = prep.xyz_cam
        inputs = {name: prep.feeds[name] for name in self._pose_inputs}
        with timer.stage("pose_net"):
            t_net = time.perf_counter()
            outputs = dict(zip(self._pose_outputs, self.pose_session.run(self._pose_outputs, inputs)))
            timer.add_network((time.perf_counter() - t_net) * 1e3)
        with timer.stage("voting"):
            stage = solve_pose(
                xyz, outputs["seg_logits"].astype(np.float32),
                outputs["kp_offsets"].astype(np.float32), outputs["ctr_offsets"].astype(np.float32),
                bundle.keypoints, bundle.centre, config=voting, diameter_m=bundle.diameter,
                distance_range_m=bundle.distance_range_m, focal_px=self.focal_px, baseline_m=self.baseline_m,
                sigma_d_px=voting.sigma_d_px / max(stereo.scale, 1e-9), offset_sign=bundle.pose.offset_sign,
                seed=self.seed)
        if self._registration is not None:
            stage, detail = self._register(xyz, stage, stereo, timer, left_r)  # times "registration", "silhouette"
            if not stage.valid:  # the invalid stage still carries its diagnostics (flip_margin)
                if (stage.position_pose is not None and bundle.range_fit is not None and bundle.range_fit.positions
                        and all(key in stage.factors for key in _POSITION_KEYS)):
                    stage = self._position_range_fit(stage, left_r, right_r, stereo.disparity, timer)
                return stage.status, stage, stereo.window, detail
        refine = None
        if stage.valid and self.refine and self._surface_normals is not None:
            surface, normals, reach = np.asarray(bundle.surface_points), self._surface_normals, 2.0 * stage.bandwidth

            def refine(R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
                return refine_icp(R, t, xyz, surface, normals, max_distance=reach, iterations=10, seed=self.seed)

            if not voting.flip_axis:
                with timer.stage("refine"):
                    R, t = refine(stage.R, stage.t)
                stage = dataclasses.replace(stage, R=R, t=t)
        fitness = None
        if stage.valid and voting.flip_axis and len(bundle.surface_points) and self._registration is None:
            with timer.stage("refine" if refine is not None else "verify"):
                flip = resolve_flip(stage.R, stage.t, xyz, np.asarray(bundle.surface_points), bundle.centre,
                                    voting.flip_axis, stage.bandwidth, refine=refine)
            stage = dataclasses.replace(stage, R=flip.R, t=flip.t, factors={**stage.factors, "flip_margin": flip.margin})
            fitness = flip.fitness
            if flip.margin < voting.min_flip_margin:
                logger.info("pose rejected: flip margin %.3f < %.3f", flip.margin, voting.min_flip_margin)
                return "weak_votes", None, stereo.window, (
                    f"the pose and its 180° flip about body {voting.flip_axis} fit the stereo points almost "
                    f"equally (surface fitness {flip.fitness:.3f} vs {flip.fitness_other:.3f})")
        problem = self._verify(stage, xyz, left_r, right_r, timer, fitness) if stage.valid else None
        if problem is not None and stage.fallback is not None:
            # a tracked pose refined against the outline that the other checks refuse: the unrefined one
            logger.info("outline-refined tracked pose rejected (%s); trying the registered one", problem[1])
            stage = dataclasses.replace(stage, R=stage.fallback[0], t=stage.fallback[1], fallback=None, decided=None)
            problem = self._verify(stage, xyz, left_r, right_r, timer, None)
        if problem is not None:
            return problem[0], None, stereo.window, problem[1]
        if stage.valid and bundle.range_fit is not None and len(bundle.surface_points):
            stage = self._range_fit(stage, left_r, right_r, stereo.disparity, timer)
        return stage.status, stage, stereo.window, "" if stage.valid else f"pose stage: {stage.status}"

    def _range_fit(self, stage: PoseStageResult, left_r: np.ndarray, right_r: np.ndarray, disparity: np.ndarray,
                   timer: StageTimer) -> PoseStageResult:
        """The valid, checked pose moved along its centre's line of sight to the range the images show at full
        resolution (:mod:`spacepose.range_fit`, the bundle's ``range_fit``); unchanged when the fit is not
        applied. Everything decided before (validity, route, polish caps) stands. Factors: ``range_fit_m`` (the
        move, NaN without a fit) and ``range_fit_samples``."""
        bundle = self.bundle
        with timer.stage("range_fit"):
            fit = fit_range(stage.R, stage.t, np.asarray(bundle.centre), self._surface, left_r, right_r, disparity,
                            self.K, self.baseline_m, bundle.range_fit)
        factors = {**stage.factors, "range_fit_m": fit.move_m if fit.t is not None else math.nan,
                   "range_fit_samples": float(fit.samples)}
        if fit.t is None:
            logger.info("range fit not applied: %s", fit.why)
            return dataclasses.replace(stage, factors=factors)
        return dataclasses.replace(stage, t=fit.t, factors=factors)

    def _position_range_fit(self, stage: PoseStageResult, left_r: np.ndarray, right_r: np.ndarray,
                            disparity: np.ndarray, timer: StageTimer) -> PoseStageResult:
        """The position of a frame without a pose (its factors) moved along its line of sight to the range the
        images show, read with the rotation of ``stage.position_pose`` (the outline's winner or the registered
        pose: a pose and its flip put the centre at the same place) — the bundle's ``range_fit`` with
        ``positions`` 1. Unchanged when the fit is not applied. Factor ``position_range_fit_m``: the move (NaN
        without a fit)."""
        bundle = self.bundle
        R_c, t_c = stage.position_pose
        with timer.stage("range_fit"):
            fit = fit_range(R_c, t_c, np.asarray(bundle.centre), self._surface, left_r, right_r, disparity,
                            self.K, self.baseline_m, bundle.range_fit)
        factors = {**stage.factors, "position_range_fit_m": fit.move_m if fit.t is not None else math.nan}
        if fit.t is None:
            logger.info("range fit of the position not applied: %s", fit.why)
        else:
            factors.update(zip(_POSITION_KEYS, (float(v) for v in R_c @ np.asarray(bundle.centre) + fit.t)))
        return dataclasses.replace(stage, factors=factors)
