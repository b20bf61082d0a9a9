"""The model bundle: the only thing that crosses from training to flight (numpy + onnxruntime).

A bundle is a folder::

    <bundle>/stereo.onnx     stereo graph (TSCA-Stereo, fixed input size and iterations)
    <bundle>/pose.onnx       pose graph (RGB crop + points -> segmentation, keypoint/centre offsets)
    <bundle>/bundle.json     the manifest below
    <bundle>/MODEL_CARD.md   how the graphs were trained and what they measured

``bundle.json`` (schema ``"spacepose.bundle/1"``; every key required unless marked optional)::

    {
      "schema": "spacepose.bundle/1",
      "target": {"name": "tdrs", "mesh_scale": 0.0473501498,
                 "keypoints": [[x, y, z], ...],        # (M, 3) object frame, metres, M >= 3
                 "centre": [x, y, z],
                 "radius": 3.03,                       # bounding-sphere radius about "centre", metres
                 "bbox_min": [x, y, z], "bbox_max": [x, y, z],
                 "surface_points": [[x, y, z], ...],   # optional (S, 3), for ICP refinement
                 "surface_normals": [[x, y, z], ...],  # optional (S, 3) unit normals of those
                                                       # (PCA normals of the samples if absent)
                 "silhouette_points": [[x, y, z], ...]},  # optional (Q, 3) dense area-uniform
                                                       # samples whose splat is the target's outline
      "stereo": {"file": "stereo.onnx", "input_size": [256, 256], "iters": 8,
                 "normalisation": "rgb_0_255", "max_disp": 192,
                 "disparity_range_px": [lo, hi],       # optional: disparities (graph input px) seen
                                                       # in training; derived from "rig" if absent
                 "window_margin": 1.25},               # optional, roi.square_window's margin
      "pose": {"file": "pose.onnx", "n_keypoints": 8,
               "n_points": 1024, "k": 16, "n_levels": 3, "crop_size": [128, 128],
               "ratio": 4, "xyz_scale": 2.5, "use_normals": false,   # optional (PoseInputSpec
               "sampling": "fps", "seed": 0,                         #  defaults)
               "offset_sign": 1},                      # optional: vote = point + sign * offset
      "voting": {"bandwidth_fraction": 0.05,           # of the target diameter (2 * radius)
                 "k_sigma": 3.0, "sigma_d_px": 0.25,   # stereo disparity noise, graph input px
                 "kernel": "gaussian", "n_seeds": 16,
                 "min_points": 64, "min_cluster_fraction": 0.3,
                 "min_keypoint_fraction": 0.3, "max_fit_rms_factor": 1.0,
                 "seg_threshold": 0.5, "depth_margin": 0.2},   # all optional (defaults here)
      "registration": {"starts": 48, "min_margin": 0.01, ...},   # optional: multi-start ICP of the
                                       # surface to the stereo points decides the pose (its fields:
                                       # spacepose.registration.RegistrationConfig); absent: off
      "silhouette": {"max_chamfer_px": 1.2, ...},   # optional, needs registration and
                                       # target.silhouette_points: the outline decides between the
                                       # registered pose and its flip (spacepose.silhouette.
                                       # SilhouetteConfig); absent: off
      "flip_classifier": {"file": "flip.onnx", "size": 128, "axis": "z",
                          "decide_prob": 0.97, "veto_prob": 0.1},   # optional, needs silhouette: a
                                       # graph that tells the outline's winner from its flip in the
                                       # left image (spacepose.flip_classifier.FlipClassifierConfig)
      "outline_refiner": {"file": "outline.onnx", "grow_px": 2},   # optional, needs the
                                       # silhouette's polish: a graph that sharpens the stereo outline
                                       # the polish reads (spacepose.outline_refiner)
      "range_fit": {"window_px": 7, "span_px": 1.0, "step_px": 0.1},   # optional, needs
                                       # target.surface_points: a valid pose's range measured again
                                       # from the images at full resolution (spacepose.range_fit)
      "uncertainty": {"range_k": 0.3, "lateral_px": 0.5, "lateral_floor_m": 0.02,
                      "rotation_k_deg": 20.0, "rotation_floor_deg": 0.0,
                      "rotation_chamfer_deg": 1.5},   # optional, needs
                                       # registration: a valid pose's position covariance and
                                       # rotation sigma (spacepose.uncertainty.UncertaintyConfig)
      "position_uncertainty": {"range_k": 0.25, "range_chamfer_k": 0.12, "lateral_px": 0.0,
                               "lateral_floor_m": 0.0, "lateral_chamfer_m": 0.035},   # optional,
                                       # needs registration: the covariance of a position reported
                                       # without a pose (PositionUncertaintyConfig)
      "confidence": {"position_m": 0.1, "rotation_deg": 2.0, "bias": 1.6,
                     "slope": 1.3, "min_valid": 0.08},   # optional, needs uncertainty: a valid pose's
                                       # confidence is the (recalibrated) probability of being within the
                                       # tolerance; a pose under min_valid (optional, default 0) is reported
                                       # weak_votes (spacepose.confidence.ConfidenceConfig)
      "rig": {"image_size": [640, 480], "focal_px": 800.0, "baseline_m": 1.0},
      "distance_range_m": [10.0, 50.0],
      "dataset": {"seed": 0, "size": 10000},
      "training_commit": "abc1234",
      "metrics": {...}                                 # free-form measured test metrics
    }

Each ONNX file carries JSON metadata under ``custom_metadata_map["spacepose"]``; every key it
shares with the bundle's section for that graph (``input_size``, ``iters``, ``normalisation``,
``max_disp`` for stereo; every :class:`~spacepose.pose_inputs.PoseInputSpec` field but ``seed``,
``n_keypoints``, ``keypoints``, ``centre`` for pose; ``target`` for both) must agree, and a ``kind`` key, when
present, must name the graph. :func:`load_bundle` refuses a bundle that breaks any of this with
:class:`~spacepose.errors.BundleError`, and :meth:`ModelBundle.check_fits` refuses a calibration
under which the target's disparities leave the range the stereo graph was trained for.
"""

from __future__ import annotations

import json
import logging
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from .confidence import ConfidenceConfig, parse_confidence
from .errors import BundleError
from .flip_classifier import FlipClassifierConfig, parse_flip_classifier
from .outline_refiner import OutlineRefinerConfig, parse_outline_refiner
from .range_fit import RangeFitConfig, parse_range_fit
from .uncertainty import PositionUncertaintyConfig, UncertaintyConfig, parse_position_uncertainty, parse_uncertainty
from .pose_inputs import PoseInputSpec
from .registration import RegistrationConfig
from .roi import COARSE_TILE_OVERLAP_PX, WINDOW_DISPARITY_FILL
from .silhouette import SilhouetteConfig

__all__ = [
    "SCHEMA",
    "DEFAULT_BUNDLE_DIR",
    "StereoGraphConfig",
    "PoseGraphConfig",
    "VotingConfig",
    "TrainingRig",
    "ModelBundle",
    "load_bundle",
    "read_graph_metadata",
    "expected_disparity_px",
    "DISPARITY_TOLERANCE",
    "COARSE_DETECTION_FLOOR_PX",
    "MAX_COARSE_TILES",
]

logger = logging.getLogger(__name__)

SCHEMA = "spacepose.bundle/1"
DEFAULT_BUNDLE_DIR = Path(__file__).resolve().parent / "bundles" / "default"
#: most tiles per side of a tiled coarse pass (:meth:`ModelBundle.coarse_tiles_for`; n**2 graph runs)
MAX_COARSE_TILES = 3
#: relative slack on the trained disparity range accepted by :meth:`ModelBundle.check_fits`
DISPARITY_TOLERANCE = 0.25
#: smallest coarse-pass disparity (graph input px) at which the target still stands out of the
#: zero-disparity background (1.5x the stereo stage's 2 px detection threshold)
COARSE_DETECTION_FLOOR_PX = 3.0
REQUIRED_FILES = ("bundle.json", "MODEL_CARD.md")


# ----------------------------------------------------------------------------------- configs
@dataclass(frozen=True)
class StereoGraphConfig:
    """The stereo graph's contract: input size (w, h), iterations, normalisation, disparity range."""

    file: str = "stereo.onnx"
    input_size: tuple[int, int] = (256, 256)
    iters: int = 8
    normalisation: str = "rgb_0_255"
    max_disp: float = 192.0
    disparity_range_px: tuple[float, float] | None = None
    window_margin: float = 1.25


@dataclass(frozen=True)
class PoseGraphConfig:
    """The pose graph's contract: its input spec (what :mod:`spacepose.pose_inputs` builds; its
    fields sit flat in the ``pose`` section of bundle.json) and keypoint count. ``offset_sign``: a
    vote is ``point + offset_sign * offset`` (the graph's convention is ``offset = keypoint - point``,
    sign +1)."""

    file: str = "pose.onnx"
    n_keypoints: int = 8
    offset_sign: int = 1
    input_spec: PoseInputSpec = field(default_factory=PoseInputSpec)


@dataclass(frozen=True)
class VotingConfig:
    """MeanShift bandwidth rule and the validity thresholds of :mod:`spacepose.pose_stage`.

    bandwidth = max(bandwidth_fraction * target diameter, k_sigma * sigma_Z) with
    sigma_Z = Z^2 * sigma_d / (f * B) (``sigma_d_px`` in stereo graph input pixels).
    """

    bandwidth_fraction: float = 0.05
    k_sigma: float = 3.0
    sigma_d_px: float = 0.25
    kernel: str = "gaussian"
    n_seeds: int = 16
    min_points: int = 64
    min_cluster_fraction: float = 0.3
    min_keypoint_fraction: float = 0.3
    max_fit_rms_factor: float = 1.0
    seg_threshold: float = 0.5
    depth_margin: float = 0.2
    #: keypoints (besides the centre) whose votes must agree before a fit is trusted; more than
    #: the 3 a rigid fit needs guards against near-symmetric (180°-flipped) solutions
    min_keypoints: int = 3
    #: poses below this confidence are reported ``weak_votes`` (set from the error-vs-confidence
    #: table of the evaluation; 0 keeps every pose that passes the other checks)
    min_confidence: float = 0.0
    #: share of the stereo points that must lie within one bandwidth of the target's surface
    #: (``target.surface_points``) placed at the fitted pose; 0 disables the check. It compares
    #: the pose with the data, not with the votes, so a confident but wrong fit is caught.
    min_surface_fitness: float = 0.0
    #: least median left-right patch ZNCC of the target's visible surface at the fitted pose
    #: (:mod:`spacepose.photometric`); it goes back to the images, so it catches poses fitted to
    #: wrong stereo disparities. -1 disables the check; a view with too few textured patches to
    #: score is not rejected by it.
    min_photo_consistency: float = -1.0
    #: body axis ("x", "y" or "z") of the target's near-symmetry: the fitted pose and its 180° flip
    #: about it are both scored against the stereo points and the better kept (:mod:`spacepose.flip`);
    #: "" disables this (a pose graph trained with the paper's loss, or a target without one)
    flip_axis: str = ""
    #: least surface-fitness gap between the kept pose and its flip; below it the frame is
    #: ``weak_votes`` (the points do not say which of the two it is)
    min_flip_margin: float = 0.0


@dataclass(frozen=True)
class TrainingRig:
    """The (rectified) rig the graphs were trained with: image size (w, h), focal, baseline."""

    image_size: tuple[int, int]
    focal_px: float
    baseline_m: float


def _frozen(array: np.ndarray) -> np.ndarray:
    array = np.array(array, dtype=np.float64, copy=True)
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class ModelBundle:
    """A loaded, validated model bundle (see the module docstring for the file format).

    Attributes:
        path: the bundle folder.
        target_name, mesh_scale: which target and how its mesh was scaled (metres per mesh unit).
        keypoints: (M, 3) float64 object-frame keypoints; ``centre`` (3,) the object-frame centre.
        radius: bounding-sphere radius about ``centre`` (m); ``bbox_min``/``bbox_max`` (3,) the
            object-frame bounding box (overlays, ICP sanity); ``surface_points`` (S, 3), maybe empty,
            and ``surface_normals`` (S, 3) their normals (empty when the manifest has none);
            ``silhouette_points`` (Q, 3) the outline samples (empty when the manifest has none).
        registration: multi-start registration settings, ``None`` when the bundle does not use it.
        silhouette: outline-stage settings, ``None`` when the bundle does not use it.
        flip_classifier: the optional flip graph's section (:mod:`spacepose.flip_classifier`), ``None``
            when the bundle has none.
        outline_refiner: the optional outline graph's section (:mod:`spacepose.outline_refiner`: the polish
            reads its refined outline), ``None`` when the bundle has none.
        range_fit: the optional range fit (:mod:`spacepose.range_fit`: a valid pose's range from the images at
            full resolution), ``None`` when the bundle has none.
        uncertainty: the optional per-frame uncertainty model (:mod:`spacepose.uncertainty`), ``None``
            when the bundle has none (no covariance is then reported).
        position_uncertainty: the optional covariance model of a position reported without a pose
            (:class:`spacepose.uncertainty.PositionUncertaintyConfig`), ``None`` when the bundle has none.
        confidence: the optional model of a valid pose's confidence from its uncertainty
            (:mod:`spacepose.confidence`); ``None`` when the bundle has none (the decision routes' own
            confidence is then reported).
        stereo, pose, voting: graph and voting configs; ``rig``: the training rig.
        distance_range_m: (near, far) target distance the graphs were trained for.
        dataset_seed, dataset_size, training_commit, metrics: provenance and measured numbers.
        graph_metadata: the JSON metadata read from each graph (``{"stereo": {...}, "pose": {...}}``).
    """

    path: Path
    target_name: str
    mesh_scale: float
    keypoints: np.ndarray
    centre: np.ndarray
    radius: float
    bbox_min: np.ndarray
    bbox_max: np.ndarray
    surface_points: np.ndarray
    surface_normals: np.ndarray
    stereo: StereoGraphConfig
    pose: PoseGraphConfig
    voting: VotingConfig
    rig: TrainingRig
    distance_range_m: tuple[float, float]
    dataset_seed: int | None
    dataset_size: int | None
    training_commit: str
    metrics: Mapping[str, Any] = field(default_factory=dict)
    registration: RegistrationConfig | None = None
    silhouette_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    silhouette: SilhouetteConfig | None = None
    flip_classifier: FlipClassifierConfig | None = None
    outline_refiner: OutlineRefinerConfig | None = None
    range_fit: RangeFitConfig | None = None
    uncertainty: UncertaintyConfig | None = None
    position_uncertainty: PositionUncertaintyConfig | None = None
    confidence: ConfidenceConfig | None = None
    graph_metadata: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)

    @property
    def stereo_path(self) -> Path:
        return self.path / self.stereo.file

    @property
    def pose_path(self) -> Path:
        return self.path / self.pose.file

    @property
    def diameter(self) -> float:
        return 2.0 * self.radius

    @property
    def bbox_corners(self) -> np.ndarray:
        """(8, 3) object-frame corners of the bounding box (for overlays)."""
        lo, hi = self.bbox_min, self.bbox_max
        return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])

    def trained_disparity_px(self) -> tuple[float, float]:
        """Disparity range (stereo graph input pixels) the stereo graph was trained for."""
        if self.stereo.disparity_range_px is not None:
            return self.stereo.disparity_range_px
        ranges = expected_disparity_px(self, self.rig.focal_px, self.rig.baseline_m, self.rig.image_size)
        return (min(r[0] for r in ranges.values()), max(r[1] for r in ranges.values()))

    def _coarse_problem(self, focal: float, baseline: float, size: tuple[int, int], tiles: int
                        ) -> tuple[str, tuple[float, float]] | None:
        lo, hi = self.trained_disparity_px()
        lo_ok, hi_ok = lo * (1.0 - DISPARITY_TOLERANCE), hi * (1.0 + DISPARITY_TOLERANCE)
        for name, (d_lo, d_hi) in expected_disparity_px(self, focal, baseline, size, tiles).items():
            floor = min(lo_ok, COARSE_DETECTION_FLOOR_PX) if name == "coarse" else lo_ok
            if d_lo < floor or d_hi > hi_ok:
                return name, (d_lo, d_hi)
        return None

    def coarse_tiles_for(self, rig: Any) -> int:
        """How many tiles per side the coarse pass needs under ``rig`` (1: one letterboxed run): the
        fewest, up to :data:`MAX_COARSE_TILES`, with which :meth:`check_fits` accepts it (1 when none does)."""
        focal, baseline, size = _rig_numbers(rig)
        for n in range(1, MAX_COARSE_TILES + 1):
            if self._coarse_problem(focal, baseline, size, n) is None:
                return n
        return 1

    def check_fits(self, rig: Any) -> None:
        """Refuse a calibration under which the stereo graph would see disparities it never saw.

        For the target anywhere in ``distance_range_m``, the disparity in graph input pixels of the
        coarse (letterboxed full frame, tiled if :meth:`coarse_tiles_for` says so) and the fine (ROI
        window) pass must lie within the trained range widened by :data:`DISPARITY_TOLERANCE`. The
        coarse pass only has to *find* the target, so its low end may go down to
        :data:`COARSE_DETECTION_FLOOR_PX` (the fine pass, whose disparity does not depend on the focal
        length, keeps the trained range).

        Args:
            rig: a :class:`~spacepose.calibration.rig.StereoRig` (focal from ``M1``, baseline
                ``||T||``) or a :class:`~spacepose.calibration.rectify.Rectification`.

        Raises:
            BundleError: saying which pass, the disparity range it would see and the trained one.
        """
        focal, baseline, size = _rig_numbers(rig)
        tiles = self.coarse_tiles_for(rig)
        problem = self._coarse_problem(focal, baseline, size, tiles)
        if problem is not None:
            name, (d_lo, d_hi) = problem
            lo, hi = self.trained_disparity_px()
            near, far = self.distance_range_m
            where = f" ({tiles}x{tiles} tiles)" if name == "coarse" and tiles > 1 else ""
            raise BundleError(
                f"bundle {self.path.name!r} does not fit this calibration: at {near:g}-{far:g} m the "
                f"{name} pass{where} would see {d_lo:.1f}-{d_hi:.1f} px disparity (f={focal:.1f} px, "
                f"B={baseline:.3f} m, {size[0]}x{size[1]}), but the stereo graph was trained for "
                f"{lo:.1f}-{hi:.1f} px (rig f={self.rig.focal_px:g} px, B={self.rig.baseline_m:g} m, "
                f"{self.rig.image_size[0]}x{self.rig.image_size[1]}); retrain or use a matching rig"
            )


def _rig_numbers(rig: Any) -> tuple[float, float, tuple[int, int]]:
    if hasattr(rig, "focal_px") and hasattr(rig, "image_size"):  # Rectification
        return float(rig.focal_px), float(rig.baseline_m), tuple(rig.image_size)
    try:
        return float(np.asarray(rig.M1)[0, 0]), float(rig.baseline_m), tuple(rig.image_size)
    except AttributeError as err:
        raise TypeError(f"check_fits needs a StereoRig or Rectification, got {type(rig).__name__}") from err


def expected_disparity_px(bundle: ModelBundle, focal_px: float, baseline_m: float,
                          image_size: tuple[int, int], coarse_tiles: int = 1) -> dict[str, tuple[float, float]]:
    """Disparity (stereo graph input px) of the target over the bundle's distance range, per pass.

    * coarse: d = f B / Z times the letterbox scale ``min(v_w / W, v_h / H)``, the view ``v`` being
      the graph input (``coarse_tiles`` 1) or ``n`` of them less ``n - 1`` tile overlaps;
    * fine: the ROI window's side is ``margin * (target width + d)`` so the window disparity,
      ``w_in * B / (margin * (width_m + B))``, does not depend on Z or f; the target's width in
      metres lies between its smallest bounding-box extent and its bounding-sphere diameter. The
      window is widened where that would exceed ``WINDOW_DISPARITY_FILL * max_disp``
      (:func:`spacepose.roi.square_window`), so neither end goes above that cap.
    """
    near, far = bundle.distance_range_m
    w_in, h_in = bundle.stereo.input_size
    n, o = int(coarse_tiles), (COARSE_TILE_OVERLAP_PX if coarse_tiles > 1 else 0)
    s = min((n * w_in - (n - 1) * o) / image_size[0], (n * h_in - (n - 1) * o) / image_size[1])
    coarse = (focal_px * baseline_m / far * s, focal_px * baseline_m / near * s)
    margin = bundle.stereo.window_margin
    smallest = float(np.min(bundle.bbox_max - bundle.bbox_min))
    cap = WINDOW_DISPARITY_FILL * bundle.stereo.max_disp
    fine = (min(w_in * baseline_m / (margin * (2.0 * bundle.radius + baseline_m)), cap),
            min(w_in * baseline_m / (margin * (smallest + baseline_m)), cap))
    return {"coarse": coarse, "fine": fine}


# ----------------------------------------------------------------------------------- parsing
def _get(section: Mapping[str, Any], key: str, where: str) -> Any:
    if not isinstance(section, Mapping):
        raise BundleError(f"bundle.json: {where} must be an object, got {type(section).__name__}")
    if key not in section:
        raise BundleError(f"bundle.json: missing key {where}.{key}")
    return section[key]


def _number(value: Any, where: str, positive: bool = True) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise BundleError(f"bundle.json: {where} must be a finite number, got {value!r}")
    if positive and value <= 0:
        raise BundleError(f"bundle.json: {where} must be > 0, got {value!r}")
    return float(value)


def _integer(value: Any, where: str, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise BundleError(f"bundle.json: {where} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def _vector(value: Any, where: str, shape: tuple[int | None, ...]) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise BundleError(f"bundle.json: {where} must be numeric, got {value!r:.80}") from err
    if arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape)):
        want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
        raise BundleError(f"bundle.json: {where} must have shape {want}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise BundleError(f"bundle.json: {where} must be finite")
    return arr


def _size(value: Any, where: str) -> tuple[int, int]:
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise BundleError(f"bundle.json: {where} must be [width, height], got {value!r}")
    return (_integer(value[0], where + "[0]"), _integer(value[1], where + "[1]"))


def _range(value: Any, where: str) -> tuple[float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise BundleError(f"bundle.json: {where} must be [low, high], got {value!r}")
    lo, hi = _number(value[0], where + "[0]"), _number(value[1], where + "[1]")
    if not lo < hi:
        raise BundleError(f"bundle.json: {where} must have low < high, got {value!r}")
    return (lo, hi)


def _optional_fields(cls: type, section: Mapping[str, Any], where: str) -> dict[str, Any]:
    known = set(cls.__dataclass_fields__)
    unknown = sorted(set(section) - known)
    if unknown:
        raise BundleError(f"bundle.json: unknown keys in {where}: {unknown}; valid: {sorted(known)}")
    return dict(section)


def _parse_stereo(section: Any) -> StereoGraphConfig:
    where = "stereo"
    data = _optional_fields(StereoGraphConfig, section if isinstance(section, Mapping) else {}, where)
    _get(section, "file", where)
    out = StereoGraphConfig(
        file=str(data["file"]),
        input_size=_size(_get(section, "input_size", where), "stereo.input_size"),
        iters=_integer(_get(section, "iters", where), "stereo.iters"),
        normalisation=str(_get(section, "normalisation", where)),
        max_disp=_number(_get(section, "max_disp", where), "stereo.max_disp"),
        disparity_range_px=(None if data.get("disparity_range_px") is None
                            else _range(data["disparity_range_px"], "stereo.disparity_range_px")),
        window_margin=_number(data.get("window_margin", 1.25), "stereo.window_margin"),
    )
    if out.window_margin < 1.0:
        raise BundleError(f"bundle.json: stereo.window_margin must be >= 1, got {out.window_margin}")
    return out


def _parse_pose(section: Any) -> PoseGraphConfig:
    where = "pose"
    if not isinstance(section, Mapping):
        raise BundleError(f"bundle.json: pose must be an object, got {type(section).__name__}")
    known = {"file", "n_keypoints", "offset_sign", *PoseInputSpec.__dataclass_fields__}
    unknown = sorted(set(section) - known)
    if unknown:
        raise BundleError(f"bundle.json: unknown keys in {where}: {unknown}; valid: {sorted(known)}")
    data = dict(section)
    sign = data.get("offset_sign", 1)
    if sign not in (1, -1) or isinstance(sign, bool):
        raise BundleError(f"bundle.json: pose.offset_sign must be 1 or -1, got {sign!r}")
    use_normals = data.get("use_normals", False)
    if not isinstance(use_normals, bool):
        raise BundleError(f"bundle.json: pose.use_normals must be true/false, got {use_normals!r}")
    fields = dict(
        n_points=_integer(_get(section, "n_points", where), "pose.n_points"),
        k=_integer(_get(section, "k", where), "pose.k"),
        n_levels=_integer(_get(section, "n_levels", where), "pose.n_levels"),
        ratio=_integer(data.get("ratio", 4), "pose.ratio"),
        crop_size=_size(_get(section, "crop_size", where), "pose.crop_size"),
        xyz_scale=_number(data.get("xyz_scale", 2.5), "pose.xyz_scale"),
        use_normals=use_normals,
        sampling=str(data.get("sampling", "fps")),
        seed=_integer(data.get("seed", 0), "pose.seed", minimum=0),
    )
    try:
        spec = PoseInputSpec(**fields)
    except ValueError as err:
        raise BundleError(f"bundle.json: invalid pose input spec: {err}") from err
    out = PoseGraphConfig(
        file=str(_get(section, "file", where)),
        n_keypoints=_integer(_get(section, "n_keypoints", where), "pose.n_keypoints", minimum=3),
        offset_sign=int(sign),
        input_spec=spec,
    )
    return out


def _parse_voting(section: Any) -> VotingConfig:
    if section is None:
        return VotingConfig()
    if not isinstance(section, Mapping):
        raise BundleError(f"bundle.json: voting must be an object, got {type(section).__name__}")
    data = _optional_fields(VotingConfig, section, "voting")
    defaults = VotingConfig()
    values: dict[str, Any] = {}
    for name in VotingConfig.__dataclass_fields__:
        default = getattr(defaults, name)
        value = data.get(name, default)
        where = f"voting.{name}"
        if isinstance(default, str):
            if not isinstance(value, str):
                raise BundleError(f"bundle.json: {where} must be a string, got {value!r}")
        elif isinstance(default, int):
            value = _integer(value, where)
        else:
            value = _number(value, where, positive=name not in ("min_confidence", "min_surface_fitness",
                                                                     "min_photo_consistency", "min_flip_margin"))
        values[name] = value
    if values["flip_axis"] not in ("", "x", "y", "z"):
        raise BundleError(f"bundle.json: voting.flip_axis must be '', 'x', 'y' or 'z', got {values['flip_axis']!r}")
    if not 0.0 <= values["min_flip_margin"] < 1.0:
        raise BundleError(f"bundle.json: voting.min_flip_margin must be in [0, 1), got {values['min_flip_margin']!r}")
    if values["kernel"] not in ("flat", "gaussian"):
        raise BundleError(f"bundle.json: voting.kernel must be 'flat' or 'gaussian', got {values['kernel']!r}")
    if values["min_keypoints"] < 3:
        raise BundleError(f"bundle.json: voting.min_keypoints must be >= 3, got {values['min_keypoints']!r}")
    if not 0.0 <= values["min_confidence"] < 1.0:
        raise BundleError(f"bundle.json: voting.min_confidence must be in [0, 1), got {values['min_confidence']!r}")
    if not 0.0 <= values["min_surface_fitness"] <= 1.0:
        raise BundleError(f"bundle.json: voting.min_surface_fitness must be in [0, 1], got {values['min_surface_fitness']!r}")
    if not -1.0 <= values["min_photo_consistency"] < 1.0:
        raise BundleError("bundle.json: voting.min_photo_consistency must be in [-1, 1), got "
                          f"{values['min_photo_consistency']!r}")
    for name in ("min_cluster_fraction", "min_keypoint_fraction", "seg_threshold"):
        if not 0.0 < values[name] < 1.0:
            raise BundleError(f"bundle.json: voting.{name} must be in (0, 1), got {values[name]!r}")
    return VotingConfig(**values)


def _config_fields(cls: type, section: Mapping[str, Any], where: str, zero_ints: tuple[str, ...],
                   zero_numbers: tuple[str, ...]) -> dict[str, Any]:
    """Every field of the frozen dataclass ``cls`` from ``section`` (its default where absent): integer
    fields >= 1 (>= 0 for ``zero_ints``), the others finite numbers > 0 (>= any for ``zero_numbers``)."""
    data = _optional_fields(cls, section, where)
    defaults = cls()
    values: dict[str, Any] = {}
    for name in cls.__dataclass_fields__:
        default = getattr(defaults, name)
        value, key = data.get(name, default), f"{where}.{name}"
        if isinstance(default, int):
            value = _integer(value, key, minimum=0 if name in zero_ints else 1)
        else:
            value = _number(value, key, positive=name not in zero_numbers)
        values[name] = value
    return values


def _parse_registration(section: Any, n_surface: int) -> RegistrationConfig | None:
    if section is None:
        return None
    if not isinstance(section, Mapping):
        raise BundleError(f"bundle.json: registration must be an object, got {type(section).__name__}")
    if n_surface < 12:
        raise BundleError("bundle.json: registration needs target.surface_points (at least 12)")
    values = _config_fields(RegistrationConfig, section, "registration", zero_ints=("seed", "position_lateral"),
                            zero_numbers=("min_margin", "min_inlier_fraction", "position_max_tau_m",
                                          "position_max_chamfer_px", "position_range_bias_outline",
                                          "position_range_bias_registered"))
    if not 0.0 <= values["min_inlier_fraction"] <= 1.0:
        raise BundleError(f"bundle.json: registration.min_inlier_fraction must be in [0, 1], "
                          f"got {values['min_inlier_fraction']!r}")
    if not 0.0 <= values["min_margin"] < 1.0:
        raise BundleError(f"bundle.json: registration.min_margin must be in [0, 1), got {values['min_margin']!r}")
    if not 0.0 < values["reach_decay"] <= 1.0:
        raise BundleError(f"bundle.json: registration.reach_decay must be in (0, 1], got {values['reach_decay']!r}")
    if values["position_max_tau_m"] < 0.0:
        raise BundleError(f"bundle.json: registration.position_max_tau_m must be >= 0 (0: off), "
                          f"got {values['position_max_tau_m']!r}")
    if values["position_max_chamfer_px"] < 0.0:
        raise BundleError(f"bundle.json: registration.position_max_chamfer_px must be >= 0 (0: off), "
                          f"got {values['position_max_chamfer_px']!r}")
    for key in ("position_range_bias_outline", "position_range_bias_registered"):
        if not 0.0 <= values[key] < 1.0:
            raise BundleError(f"bundle.json: registration.{key} must be in [0, 1) (0: off), got {values[key]!r}")
    if values["position_lateral"] not in (0, 1):
        raise BundleError(f"bundle.json: registration.position_lateral must be 0 or 1, "
                          f"got {values['position_lateral']!r}")
    return RegistrationConfig(**values)


def _parse_silhouette(section: Any, n_points: int, has_registration: bool) -> SilhouetteConfig | None:
    if section is None:
        return None
    if not isinstance(section, Mapping):
        raise BundleError(f"bundle.json: silhouette must be an object, got {type(section).__name__}")
    if n_points < 100 or not has_registration:
        raise BundleError("bundle.json: silhouette needs target.silhouette_points (at least 100) and a registration "
                          "section (it decides between the registered pose and its flip)")
    values = _config_fields(SilhouetteConfig, section, "silhouette",
                            zero_ints=("seed", "iterations", "stereo_points", "reverse", "image_vote",
                                       "image_exclusion_px", "image_min_pixels", "min_flip_pixels", "polish",
                                       "track_needs_outline", "search_candidates"),
                            zero_numbers=("depth_margin_m", "min_margin_px", "range_weight", "image_min_score",
                                          "image_min_margin_px", "image_max_background", "image_veto_score",
                                          "image_max_chamfer_px", "polish_range_weight", "search_separation_deg",
                                          "points_weight", "track_max_chamfer_px", "max_decided_polish_deg",
                                          "max_refused_track_polish_deg"))
    try:
        return SilhouetteConfig(**values)
    except ValueError as err:
        raise BundleError(f"bundle.json: {err}") from err


def _parse_manifest(data: Any, path: Path) -> ModelBundle:
    if not isinstance(data, dict):
        raise BundleError(f"bundle.json must hold an object, got {type(data).__name__}")
    schema = data.get("schema")
    if schema != SCHEMA:
        raise BundleError(f"bundle.json: schema must be {SCHEMA!r}, got {schema!r}")
    target = _get(data, "target", "")
    keypoints = _vector(_get(target, "keypoints", "target"), "target.keypoints", (None, 3))
    if keypoints.shape[0] < 3:
        raise BundleError(f"bundle.json: target.keypoints needs >= 3 keypoints, got {keypoints.shape[0]}")
    bbox_min = _vector(_get(target, "bbox_min", "target"), "target.bbox_min", (3,))
    bbox_max = _vector(_get(target, "bbox_max", "target"), "target.bbox_max", (3,))
    if not np.all(bbox_max > bbox_min):
        raise BundleError("bundle.json: target.bbox_max must exceed target.bbox_min on every axis")
    surface = target.get("surface_points")
    surface = np.zeros((0, 3)) if surface is None else _vector(surface, "target.surface_points", (None, 3))
    normals = target.get("surface_normals")
    normals = np.zeros((0, 3)) if normals is None else _vector(normals, "target.surface_normals", (len(surface), 3))
    if len(normals) and not np.allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-2):
        raise BundleError("bundle.json: target.surface_normals must be unit vectors")
    outline = target.get("silhouette_points")
    outline = np.zeros((0, 3)) if outline is None else _vector(outline, "target.silhouette_points", (None, 3))
    pose = _parse_pose(_get(data, "pose", ""))
    if pose.n_keypoints != keypoints.shape[0]:
        raise BundleError(f"bundle.json: pose.n_keypoints={pose.n_keypoints} but target.keypoints holds "
                          f"{keypoints.shape[0]}")
    rig = _get(data, "rig", "")
    dataset = data.get("dataset") or {}
    metrics = data.get("metrics") or {}
    if not isinstance(metrics, dict) or not isinstance(dataset, dict):
        raise BundleError("bundle.json: metrics and dataset must be objects")
    return ModelBundle(
        path=path,
        target_name=str(_get(target, "name", "target")),
        mesh_scale=_number(_get(target, "mesh_scale", "target"), "target.mesh_scale"),
        keypoints=_frozen(keypoints),
        centre=_frozen(_vector(_get(target, "centre", "target"), "target.centre", (3,))),
        radius=_number(_get(target, "radius", "target"), "target.radius"),
        bbox_min=_frozen(bbox_min),
        bbox_max=_frozen(bbox_max),
        surface_points=_frozen(surface),
        surface_normals=_frozen(normals),
        stereo=_parse_stereo(_get(data, "stereo", "")),
        pose=pose,
        voting=_parse_voting(data.get("voting")),
        rig=TrainingRig(
            image_size=_size(_get(rig, "image_size", "rig"), "rig.image_size"),
            focal_px=_number(_get(rig, "focal_px", "rig"), "rig.focal_px"),
            baseline_m=_number(_get(rig, "baseline_m", "rig"), "rig.baseline_m"),
        ),
        distance_range_m=_range(_get(data, "distance_range_m", ""), "distance_range_m"),
        dataset_seed=dataset.get("seed"),
        dataset_size=dataset.get("size"),
        training_commit=str(data.get("training_commit", "unknown")),
        metrics=metrics,
        registration=_parse_registration(data.get("registration"), len(surface)),
        silhouette_points=_frozen(outline),
        silhouette=_parse_silhouette(data.get("silhouette"), len(outline), data.get("registration") is not None),
        flip_classifier=_parse_flip(data),
        outline_refiner=_parse_outline_refiner(data),
        range_fit=_parse_range_fit(data, len(surface)),
        uncertainty=_parse_uncertainty(data, "uncertainty", parse_uncertainty),
        position_uncertainty=_parse_uncertainty(data, "position_uncertainty", parse_position_uncertainty),
        confidence=_parse_confidence(data),
    )


def _parse_flip(data: Mapping[str, Any]) -> FlipClassifierConfig | None:
    config = parse_flip_classifier(data.get("flip_classifier"))
    if config is not None and data.get("silhouette") is None:
        raise BundleError("bundle.json: flip_classifier needs a silhouette section (it judges the outline's winner)")
    return config


def _parse_range_fit(data: Mapping[str, Any], n_surface: int) -> RangeFitConfig | None:
    config = parse_range_fit(data.get("range_fit"))
    if config is not None and n_surface < config.min_samples:
        raise BundleError(f"bundle.json: range_fit needs at least min_samples ({config.min_samples}) surface points, "
                          f"the target has {n_surface}")
    return config


def _parse_outline_refiner(data: Mapping[str, Any]) -> OutlineRefinerConfig | None:
    config = parse_outline_refiner(data.get("outline_refiner"))
    if config is not None and not (data.get("silhouette") or {}).get("polish"):
        raise BundleError("bundle.json: outline_refiner needs a silhouette section with polish on (the polish reads "
                          "its outline)")
    return config


def _parse_uncertainty(data: Mapping[str, Any], key: str, parse: Callable[[Any], Any]) -> Any:
    config = parse(data.get(key))
    if config is not None and data.get("registration") is None:
        raise BundleError(f"bundle.json: {key} needs a registration section (its depth tolerance scales the range)")
    return config


def _parse_confidence(data: Mapping[str, Any]) -> ConfidenceConfig | None:
    config = parse_confidence(data.get("confidence"))
    if config is not None and data.get("uncertainty") is None:
        raise BundleError("bundle.json: confidence needs an uncertainty section (it is computed from the pose's "
                          "covariance)")
    return config


# ----------------------------------------------------------------------------------- graphs
def read_graph_metadata(path: str | os.PathLike) -> dict[str, Any]:
    """The JSON contract stored under ``custom_metadata_map["spacepose"]`` of an ONNX file.

    Raises:
        BundleError: the file is missing, not a loadable ONNX model, or its metadata is absent or
            not a JSON object.
    """
    from .onnx_session import read_metadata

    return read_metadata(path)


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, str) or isinstance(b, str):
        return str(a) == str(b)
    try:
        x, y = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    except (TypeError, ValueError):
        return a == b
    return x.shape == y.shape and bool(np.allclose(x, y, rtol=1e-6, atol=1e-9))


def _check_metadata(bundle: ModelBundle, kind: str, meta: Mapping[str, Any]) -> None:
    if "kind" in meta and str(meta["kind"]) != kind:
        raise BundleError(f"{kind} graph metadata says kind={meta['kind']!r}")
    if kind == "stereo":
        s = bundle.stereo
        expect = {"input_size": list(s.input_size), "iters": s.iters, "normalisation": s.normalisation,
                  "max_disp": s.max_disp}
    else:
        p = bundle.pose
        expect = {name: getattr(p.input_spec, name) for name in PoseInputSpec.__dataclass_fields__ if name != "seed"}
        expect["crop_size"] = list(p.input_spec.crop_size)
        expect.update({"n_keypoints": p.n_keypoints, "keypoints": bundle.keypoints, "centre": bundle.centre})
    expect["target"] = bundle.target_name
    for key, value in expect.items():
        if key in meta and not _same(meta[key], value):
            raise BundleError(f"{kind} graph metadata disagrees with bundle.json on {key!r}: "
                              f"graph {meta[key]!r:.120} vs bundle {value!r:.120}")


# ----------------------------------------------------------------------------------- loading
def load_bundle(path: str | os.PathLike | None = None, verify_graphs: bool = True) -> ModelBundle:
    """Load and validate a model bundle folder (``None``: the default bundle shipped in the package).

    Args:
        path: bundle folder.
        verify_graphs: read each graph's embedded metadata and check it against ``bundle.json``
            (opens a short-lived onnxruntime session per graph).

    Raises:
        BundleError: missing folder or files, invalid JSON or schema, or graph metadata that
            disagrees with ``bundle.json``.
    """
    folder = DEFAULT_BUNDLE_DIR if path is None else Path(path)
    if not folder.is_dir():
        hint = " (no default bundle is installed: train and export one, or pass a bundle folder)" if path is None else ""
        raise BundleError(f"model bundle folder {folder} does not exist{hint}")
    for name in REQUIRED_FILES:
        if not (folder / name).is_file():
            raise BundleError(f"model bundle {folder} is missing {name}")
    try:
        data = json.loads((folder / "bundle.json").read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise BundleError(f"model bundle {folder}: bundle.json is unreadable or not JSON: {err}") from err
    bundle = _parse_manifest(data, folder)
    files = [("stereo", bundle.stereo_path), ("pose", bundle.pose_path)]
    if bundle.flip_classifier is not None:
        files.append(("flip", folder / bundle.flip_classifier.file))
    if bundle.outline_refiner is not None:
        files.append(("outline", folder / bundle.outline_refiner.file))
    for kind, file in files:
        if not file.is_file():
            raise BundleError(f"model bundle {folder} is missing {file.name}")
    if verify_graphs:
        metadata = {}
        for kind, file in (("stereo", bundle.stereo_path), ("pose", bundle.pose_path)):
            metadata[kind] = read_graph_metadata(file)
            _check_metadata(bundle, kind, metadata[kind])
        object.__setattr__(bundle, "graph_metadata", metadata)
    logger.debug("loaded bundle %s (target %s, commit %s)", folder, bundle.target_name, bundle.training_commit)
    return bundle
