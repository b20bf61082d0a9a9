"""Classical baseline: OpenCV StereoSGBM -> target points -> FPFH + RANSAC -> point-to-plane ICP.

This is the pipeline a user would pick without a learned model (issue 6), kept as the baseline
column of the pose evaluation. Stages:

1. **SGBM** (``cv2.StereoSGBM``, 3-way mode) on the grey rectified pair. Both images are padded on
   the left by ``numDisparities`` black columns so SGBM's invalid left band falls in the padding.
2. **Target points**: disparity -> depth (Z = fx·B/d); pixels with depth in
   ``[min_depth_m, max_depth_m]`` (the Earth and stars sit at ~0 disparity, i.e. beyond the far
   gate); the largest connected blob of those pixels gives a robust 3D centre (median), and every
   point within ``gate_radius_m`` of it is kept (a target split into several blobs survives, stray
   star or speckle matches do not).
3. **Global registration**: voxel down-sampling, normals, FPFH features of the scene and of the
   model cloud, ``registration_ransac_based_on_feature_matching`` (Open3D, seeded).
4. **Refinement**: point-to-plane ICP of the scene points onto the model (model normals).

Registration runs scene -> model so that ICP fitness is the share of *observed* points explained by
the model (a partial view can reach 1.0); the pose is the inverse: ``X_cam = R @ X_obj + t``.

Open3D is a training-side extra (``pip install 'spacepose[baseline]'``); it is imported inside the
functions and a missing install raises :class:`~spacepose.errors.MissingExtraError`.
"""

from __future__ import annotations

import hashlib
import logging
import math
import time
from collections import OrderedDict
from dataclasses import dataclass, field

import cv2
import numpy as np

from spacepose.errors import MissingExtraError, ShapeError, check_finite, check_shape

log = logging.getLogger(__name__)

__all__ = ["ClassicalConfig", "ClassicalResult", "estimate_classical", "model_cloud", "register_clouds", "sgbm_disparity", "target_points"]


@dataclass(frozen=True)
class ClassicalConfig:
    """Parameters of the classical baseline (defaults tuned for the paper rig and the 5 m target).

    SGBM (OpenCV names; see REFERENCES.md "Classical baseline"):
        num_disparities: disparity search range in pixels, a multiple of 16; ``0`` = automatic,
            ``ceil16(fx·B / min_depth_m)`` at the frame's resolution (paper rig at 640x480:
            fx·B = 800 px·m, 160 px for 5 m, which covers the 80 px of the nearest 10 m pose and
            the near side of the target; at 1280x960 it becomes 320 px).
        block_size: odd matching block side (5: small enough for the thin solar-panel edges).
        p1_factor, p2_factor: P1 = p1_factor·cn·bs², P2 = p2_factor·cn·bs² (8 and 32 are the
            OpenCV-recommended smoothness penalties; cn = 1, grey images).
        uniqueness_ratio: % margin of the best cost over the second best (5–15 typical).
        speckle_window_size: largest speckle blob (pixels) removed as noise (50–200 typical).
        speckle_range: max disparity variation inside a connected component (px; OpenCV x16 inside).
        disp12_max_diff: left-right consistency tolerance in pixels.
        pre_filter_cap: clip of the x-derivative pre-filter.
        mode: ``cv2.STEREO_SGBM_MODE_*`` (3-way: 23 ms at 640x480 here, near full-8-path quality).

    Target points:
        min_intensity: grey level (0-255) below which a left pixel is black sky, not target (SGBM
            returns arbitrary disparities on the near-black, speckle-noised background; the
            rendered sky sits at 0-4 with stars as isolated points, lit target parts at >= 10).
        min_depth_m, max_depth_m: plausible target depth (the dataset's z is 10–50 m; the target's
            radius is 3 m).
        gate_radius_m: keep points within this distance of the largest blob's median 3D point
            (target bounding radius ~3 m + margin for depth noise).
        min_points: fewer valid target points (before down-sampling) -> invalid.

    Registration (Open3D):
        voxel_m: voxel of the down-sampling. 0.12 m for the 5 m target: tuned on 640x480 frames
            (SGBM depth noise ~0.2 px -> ~0.4 m at 40 m); 0.08 m gave fewer valid poses, more flips.
        normal_radius_m, feature_radius_m: normal estimation / FPFH radii (2.5x and ~6x the voxel).
        ransac_distance_m: max correspondence distance in RANSAC (~1.7x voxel).
        ransac_max_iterations, ransac_confidence: RANSAC stopping criteria.
        ransac_edge_length: CorrespondenceCheckerBasedOnEdgeLength similarity (0.9).
        icp_distance_m: max correspondence distance of point-to-plane ICP.
        icp_max_iterations: ICP iterations.
        min_fitness: ICP fitness (share of scene points within icp_distance_m of the model) a pose
            needs to be reported valid.
        model_points: model cloud size before voxel down-sampling (used by :func:`model_cloud`
            callers; the estimator takes whatever cloud it is given).
        seed: Open3D RANSAC seed (``o3d.utility.random.seed``).
    """

    num_disparities: int = 0
    block_size: int = 5
    p1_factor: int = 8
    p2_factor: int = 32
    uniqueness_ratio: int = 10
    speckle_window_size: int = 100
    speckle_range: int = 2
    disp12_max_diff: int = 1
    pre_filter_cap: int = 63
    mode: int = cv2.STEREO_SGBM_MODE_SGBM_3WAY
    min_intensity: int = 8
    min_depth_m: float = 5.0
    max_depth_m: float = 60.0
    gate_radius_m: float = 4.0
    min_points: int = 200
    voxel_m: float = 0.12
    normal_radius_m: float = 0.3
    feature_radius_m: float = 0.75
    ransac_distance_m: float = 0.2
    ransac_max_iterations: int = 100000
    ransac_confidence: float = 0.999
    ransac_edge_length: float = 0.9
    icp_distance_m: float = 0.25
    icp_max_iterations: int = 50
    min_fitness: float = 0.7
    model_points: int = 20000
    seed: int = 0

    def __post_init__(self) -> None:
        if self.num_disparities < 0 or self.num_disparities % 16:
            raise ValueError(f"num_disparities must be 0 (auto) or a positive multiple of 16, got {self.num_disparities}")
        if self.block_size < 1 or self.block_size % 2 == 0:
            raise ValueError(f"block_size must be odd and >= 1, got {self.block_size}")
        if not 0 < self.min_depth_m < self.max_depth_m:
            raise ValueError(f"need 0 < min_depth_m < max_depth_m, got {self.min_depth_m}, {self.max_depth_m}")
        for name in ("voxel_m", "normal_radius_m", "feature_radius_m", "ransac_distance_m", "icp_distance_m", "gate_radius_m"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if not 0 < self.ransac_confidence < 1:
            raise ValueError(f"ransac_confidence must be in (0, 1), got {self.ransac_confidence}")
        if not 0 <= self.min_fitness <= 1:
            raise ValueError(f"min_fitness must be in [0, 1], got {self.min_fitness}")

    def disparity_range(self, focal_px: float, baseline_m: float) -> int:
        """numDisparities used at this rig: the configured one, or ceil16(fx·B / min_depth_m)."""
        if self.num_disparities:
            return self.num_disparities
        return int(16 * math.ceil(focal_px * baseline_m / self.min_depth_m / 16))


@dataclass(frozen=True, eq=False)
class ClassicalResult:
    """Pose of the model in the left rectified camera (``X_cam = R @ X_obj + t``).

    Attributes:
        R: (3,3) float64 (identity when invalid and no registration ran).
        t: (3,) float64 metres (zeros when invalid and no registration ran).
        valid: enough target points and ICP fitness >= ``min_fitness``.
        fitness: ICP fitness in [0, 1] (share of scene points with a model point within
            ``icp_distance_m``); 0 when registration did not run.
        rmse: ICP inlier RMSE in metres (``inf`` when registration did not run).
        timings_ms: per stage (sgbm, points, features, ransac, icp, total; model when the model
            features were computed in this call).
        status: ``"ok"``, ``"too few target points"`` or ``"low fitness"``.
        n_points: target points before down-sampling.
    """

    R: np.ndarray
    t: np.ndarray
    valid: bool
    fitness: float
    rmse: float
    timings_ms: dict = field(default_factory=dict)
    status: str = "ok"
    n_points: int = 0


def _open3d():
    try:
        import open3d as o3d
    except ImportError as err:
        raise MissingExtraError("open3d", "baseline") from err
    return o3d


# ---------------------------------------------------------------------------------------------
# stereo -> points


def _grey_u8(image: np.ndarray, name: str) -> np.ndarray:
    if not isinstance(image, np.ndarray) or image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] not in (1, 3)):
        raise ShapeError(f"{name} must be an (H,W) or (H,W,3) image, got {getattr(image, 'shape', type(image))}")
    if image.shape[0] < 1 or image.shape[1] < 1:
        raise ShapeError(f"{name} is empty, shape {image.shape}")
    if image.ndim == 3:
        image = image[:, :, 0] if image.shape[2] == 1 else cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2GRAY)
    if image.dtype == np.uint16:
        return (image >> 8).astype(np.uint8)
    if image.dtype != np.uint8:
        raise ShapeError(f"{name} must be uint8 or uint16, got {image.dtype}")
    return np.ascontiguousarray(image)


def sgbm_disparity(left: np.ndarray, right: np.ndarray, num_disparities: int, config: ClassicalConfig = ClassicalConfig()) -> np.ndarray:
    """SGBM disparity (float32 (H,W), pixels, 0 where unknown) of the left rectified image.

    The pair is padded on the left by ``num_disparities`` black columns so that targets near the
    left border (x < numDisparities) still get a disparity.
    """
    gl, gr = _grey_u8(left, "left"), _grey_u8(right, "right")
    if gl.shape != gr.shape:
        raise ShapeError(f"left and right must have the same size, got {gl.shape} and {gr.shape}")
    cn, bs = 1, config.block_size
    matcher = cv2.StereoSGBM_create(
        minDisparity=0,
        numDisparities=num_disparities,
        blockSize=bs,
        P1=config.p1_factor * cn * bs * bs,
        P2=config.p2_factor * cn * bs * bs,
        disp12MaxDiff=config.disp12_max_diff,
        preFilterCap=config.pre_filter_cap,
        uniquenessRatio=config.uniqueness_ratio,
        speckleWindowSize=config.speckle_window_size,
        speckleRange=config.speckle_range,
        mode=config.mode,
    )
    pad = num_disparities
    gl = cv2.copyMakeBorder(gl, 0, 0, pad, 0, cv2.BORDER_CONSTANT, value=0)
    gr = cv2.copyMakeBorder(gr, 0, 0, pad, 0, cv2.BORDER_CONSTANT, value=0)
    raw = matcher.compute(gl, gr)[:, pad:]
    disparity = raw.astype(np.float32) / 16.0
    disparity[disparity <= 0] = 0.0
    return disparity


def target_points(
    disparity: np.ndarray, K: np.ndarray, baseline_m: float, config: ClassicalConfig = ClassicalConfig(), left: np.ndarray | None = None
) -> np.ndarray:
    """(N,3) float64 target points in the left camera frame from an SGBM disparity map.

    Intensity gate (``left`` grey >= ``min_intensity``, opened 3x3 to drop stars) and depth gate
    ``[min_depth_m, max_depth_m]`` -> largest 8-connected blob -> its median 3D point -> every
    gated point within ``gate_radius_m`` of that centre.
    """
    fx = float(K[0, 0])
    valid = disparity > 0
    if left is not None:
        lit = (_grey_u8(left, "left") >= config.min_intensity).astype(np.uint8)
        lit = cv2.morphologyEx(lit, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
        valid &= lit.astype(bool)
    depth = np.zeros_like(disparity)
    depth[valid] = fx * baseline_m / disparity[valid]
    mask = valid & (depth >= config.min_depth_m) & (depth <= config.max_depth_m)
    if not mask.any():
        return np.zeros((0, 3))
    n_labels, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    biggest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    v, u = np.nonzero(mask)
    z = depth[v, u].astype(np.float64)
    points = np.stack([(u - K[0, 2]) * z / fx, (v - K[1, 2]) * z / float(K[1, 1]), z], axis=1)
    in_blob = labels[v, u] == biggest
    centre = np.median(points[in_blob], axis=0)
    keep = np.linalg.norm(points - centre, axis=1) <= config.gate_radius_m
    return points[keep]


# ---------------------------------------------------------------------------------------------
# model


def model_cloud(target, n: int = 20000, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Area-uniform surface samples of the scaled target mesh and their face normals.

    Args:
        target: a :class:`spacepose.tools.targets.Target` (``load_target("tdrs")``).
        n: number of samples.
        seed: sampling seed (deterministic).

    Returns:
        points (n,3) float64 metres in the object frame, normals (n,3) float64 unit vectors (the
        mesh is not watertight: their sign is the face winding's, not "outward").
    """
    import trimesh

    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    points, face_index = trimesh.sample.sample_surface(target.mesh, int(n), seed=seed)
    normals = np.asarray(target.mesh.face_normals, dtype=np.float64)[face_index]
    return np.asarray(points, dtype=np.float64), normals


@dataclass(frozen=True, eq=False)
class _ModelFeatures:
    cloud: object  # o3d.geometry.PointCloud with normals
    fpfh: object


_MODEL_CACHE: OrderedDict = OrderedDict()
_MODEL_CACHE_SIZE = 4


def _model_features(model_points: np.ndarray, model_normals: np.ndarray, config: ClassicalConfig) -> tuple[_ModelFeatures, bool]:
    """Down-sampled model cloud + FPFH, cached on the cloud's bytes and the feature parameters."""
    o3d = _open3d()
    digest = hashlib.blake2b(model_points.tobytes() + model_normals.tobytes(), digest_size=16).hexdigest()
    key = (digest, config.voxel_m, config.normal_radius_m, config.feature_radius_m)
    if key in _MODEL_CACHE:
        _MODEL_CACHE.move_to_end(key)
        return _MODEL_CACHE[key], False
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(model_points))
    cloud.normals = o3d.utility.Vector3dVector(model_normals)
    cloud = cloud.voxel_down_sample(config.voxel_m)
    # averaged normals of thin two-sided parts can cancel: re-estimate where the average is weak
    normals = np.asarray(cloud.normals)
    norms = np.linalg.norm(normals, axis=1)
    if np.any(norms < 0.5):
        estimated = o3d.geometry.PointCloud(cloud.points)
        estimated.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=config.normal_radius_m, max_nn=30))
        est = np.asarray(estimated.normals)
        normals = np.where((norms < 0.5)[:, None], est, normals / np.maximum(norms, 1e-12)[:, None])
        cloud.normals = o3d.utility.Vector3dVector(normals)
    else:
        cloud.normalize_normals()
    fpfh = o3d.pipelines.registration.compute_fpfh_feature(
        cloud, o3d.geometry.KDTreeSearchParamHybrid(radius=config.feature_radius_m, max_nn=100)
    )
    features = _ModelFeatures(cloud=cloud, fpfh=fpfh)
    _MODEL_CACHE[key] = features
    while len(_MODEL_CACHE) > _MODEL_CACHE_SIZE:
        _MODEL_CACHE.popitem(last=False)
    return features, True


# ---------------------------------------------------------------------------------------------
# registration


def _check_model(model_points: object, model_normals: object) -> tuple[np.ndarray, np.ndarray]:
    check_shape(model_points, (None, 3), "model_points", dtypes=(np.floating,))
    check_shape(model_normals, (None, 3), "model_normals", dtypes=(np.floating,))
    check_finite(model_points, "model_points")
    check_finite(model_normals, "model_normals")
    if len(model_points) != len(model_normals) or len(model_points) < 3:
        raise ShapeError(f"model_points and model_normals must have the same length >= 3, got {len(model_points)} and {len(model_normals)}")
    return np.ascontiguousarray(model_points, dtype=np.float64), np.ascontiguousarray(model_normals, dtype=np.float64)


def register_clouds(
    scene_points: np.ndarray,
    model_points: np.ndarray,
    model_normals: np.ndarray,
    config: ClassicalConfig = ClassicalConfig(),
    viewpoint: np.ndarray | None = None,
) -> ClassicalResult:
    """FPFH + RANSAC + point-to-plane ICP of ``scene_points`` (camera frame) onto the model.

    Args:
        scene_points: (N,3) floating points of the target in the camera frame.
        model_points, model_normals: (M,3) model cloud in the object frame (:func:`model_cloud`).
        config: parameters.
        viewpoint: camera centre the scene normals are oriented towards (default the origin).

    Returns:
        :class:`ClassicalResult` with ``X_cam = R @ X_obj + t`` (timings: features, ransac, icp).
    """
    o3d = _open3d()
    reg = o3d.pipelines.registration
    check_shape(scene_points, (None, 3), "scene_points", dtypes=(np.floating,))
    model_points, model_normals = _check_model(model_points, model_normals)
    timings: dict[str, float] = {}
    if len(scene_points) < config.min_points:
        return ClassicalResult(np.eye(3), np.zeros(3), False, 0.0, math.inf, timings, "too few target points", len(scene_points))

    start = time.perf_counter()
    model, computed = _model_features(model_points, model_normals, config)
    if computed:
        timings["model"] = (time.perf_counter() - start) * 1e3

    start = time.perf_counter()
    scene = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(scene_points, dtype=np.float64)))
    scene = scene.voxel_down_sample(config.voxel_m)
    scene.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=config.normal_radius_m, max_nn=30))
    scene.orient_normals_towards_camera_location(np.zeros(3) if viewpoint is None else np.asarray(viewpoint, float))
    scene_fpfh = reg.compute_fpfh_feature(scene, o3d.geometry.KDTreeSearchParamHybrid(radius=config.feature_radius_m, max_nn=100))
    timings["features"] = (time.perf_counter() - start) * 1e3
    if len(scene.points) < 3:
        return ClassicalResult(np.eye(3), np.zeros(3), False, 0.0, math.inf, timings, "too few target points", len(scene_points))

    start = time.perf_counter()
    o3d.utility.random.seed(int(config.seed))
    ransac = reg.registration_ransac_based_on_feature_matching(
        scene,
        model.cloud,
        scene_fpfh,
        model.fpfh,
        False,  # mutual_filter
        config.ransac_distance_m,
        reg.TransformationEstimationPointToPoint(False),
        3,
        [
            reg.CorrespondenceCheckerBasedOnEdgeLength(config.ransac_edge_length),
            reg.CorrespondenceCheckerBasedOnDistance(config.ransac_distance_m),
        ],
        reg.RANSACConvergenceCriteria(config.ransac_max_iterations, config.ransac_confidence),
    )
    timings["ransac"] = (time.perf_counter() - start) * 1e3

    start = time.perf_counter()
    icp = reg.registration_icp(
        scene,
        model.cloud,
        config.icp_distance_m,
        ransac.transformation,
        reg.TransformationEstimationPointToPlane(),
        reg.ICPConvergenceCriteria(max_iteration=config.icp_max_iterations),
    )
    timings["icp"] = (time.perf_counter() - start) * 1e3

    T = np.asarray(icp.transformation, dtype=np.float64)  # X_obj = T_R X_cam + T_t
    R = T[:3, :3].T.copy()
    t = -R @ T[:3, 3]
    fitness, rmse = float(icp.fitness), float(icp.inlier_rmse)
    valid = bool(fitness >= config.min_fitness and np.all(np.isfinite(T)))
    status = "ok" if valid else "low fitness"
    log.debug("classical registration: %d scene pts, fitness %.3f, rmse %.3f m, %s", len(scene.points), fitness, rmse, status)
    return ClassicalResult(R, t, valid, fitness, rmse, timings, status, len(scene_points))


def estimate_classical(
    left_rect: np.ndarray,
    right_rect: np.ndarray,
    K: np.ndarray,
    baseline_m: float,
    model_points: np.ndarray,
    model_normals: np.ndarray,
    config: ClassicalConfig = ClassicalConfig(),
) -> ClassicalResult:
    """Pose of the target from a rectified stereo pair with the classical pipeline.

    Args:
        left_rect, right_rect: rectified (H,W) or (H,W,3) RGB images, uint8 or uint16.
        K: (3,3) rectified left intrinsics.
        baseline_m: stereo baseline in metres.
        model_points, model_normals: (M,3) model cloud (:func:`model_cloud`).
        config: parameters.

    Returns:
        :class:`ClassicalResult`; a frame without a usable target (black images, target out of the
        depth gate, registration that explains too few points) is ``valid=False`` with a status.

    Raises:
        ShapeError: bad image, intrinsics or model shapes.
        MissingExtraError: Open3D is not installed (``spacepose[baseline]``).
    """
    _open3d()
    K = np.asarray(check_shape(K, (3, 3), "K", dtypes=(np.floating,)), dtype=np.float64)
    check_finite(K, "K")
    if not (isinstance(baseline_m, (int, float, np.floating)) and math.isfinite(baseline_m) and baseline_m > 0):
        raise ShapeError(f"baseline_m must be a positive finite number, got {baseline_m!r}")
    model_points, model_normals = _check_model(model_points, model_normals)
    total = time.perf_counter()

    start = time.perf_counter()
    num_disparities = config.disparity_range(float(K[0, 0]), float(baseline_m))
    disparity = sgbm_disparity(left_rect, right_rect, num_disparities, config)
    sgbm_ms = (time.perf_counter() - start) * 1e3

    start = time.perf_counter()
    points = target_points(disparity, K, float(baseline_m), config, left=left_rect)
    points_ms = (time.perf_counter() - start) * 1e3

    result = register_clouds(points, model_points, model_normals, config)
    timings = {"sgbm": sgbm_ms, "points": points_ms, **result.timings_ms, "total": (time.perf_counter() - total) * 1e3}
    return ClassicalResult(result.R, result.t, result.valid, result.fitness, result.rmse, timings, result.status, len(points))
