"""Synthetic stereo frames of a target spacecraft: scene sampling, embree ray casting, shading.

One frame = one :class:`Scene` (pose, illumination regime, sun, Earth, materials, exposure) drawn
from a per-frame random generator, rendered from the left and the right camera of an ideal
parallel rig (:class:`StereoCamera`). Both views are ray cast (embree through ``embreex``) against
the same object-frame BVH: the ray origins and directions are moved into the object frame, so the
BVH is built once per target and process.

Shading (linear radiance, then one exposure for both views):

- sun: a directional light (angular radius 0.27 deg) with hard shadows (one occlusion ray per
  pixel); in the ``penumbra`` regime a dimmed, reddened, partially occluded sun whose larger
  apparent size gives soft shadows (4 stratified occlusion rays per pixel, same offsets in both
  views, so the penumbra is view independent);
- Earth albedo: a large spherical area light (Earth's angular radius from orbit altitude) as a
  wrapped-Lambert diffuse term plus a widened specular lobe, softly occluded by one ray toward
  the Earth's centre;
- BRDF: Lambert diffuse + Cook-Torrance specular (GGX distribution, Smith-Schlick geometry,
  Schlick Fresnel with a per-material F0 = specular tint), two sided (no back-face culling);
- MLI foil: normals perturbed per object-space cell (crinkles, identical in both views);
  solar cells: an object-space cell grid with metallic interconnect gaps;
- background: black space, optional faint stars, the Earth disc/limb (day/night terminator,
  procedural oceans/land/clouds, atmospheric rim) at infinity, so identical in both views
  (zero disparity);
- exposure: auto-exposure on a random percentile of the target's luminance mapped to a random
  level (highlights saturate, shadows stay deep), then an sRGB-like tone curve.

Everything random comes from the generator passed in, so a frame is a pure function of
(seed, index) whatever shard or process renders it.
"""

from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass, field

import numpy as np

from spacepose.errors import DatasetError

from .materials import MLI, SOLAR, SOLAR_BACK, MaterialSet, assign_materials, sample_materials

log = logging.getLogger(__name__)

__all__ = [
    "REGIMES",
    "StereoCamera",
    "PoseSampler",
    "Scene",
    "StereoRender",
    "sample_scene",
    "render_stereo",
    "rotation_to_quaternion",
    "embree_scene",
]

REGIMES = ("sun", "albedo", "penumbra", "mixed")
SUN_ANGULAR_RADIUS = math.radians(0.267)
_EARTH_RADIUS_KM = 6371.0
_SHADOW_OFFSET = 2e-3
_FILL_COLOR = np.array([0.85, 0.92, 1.0])


# ---------------------------------------------------------------------------------------------
# cameras and pose sampling


@dataclass(frozen=True, eq=False)
class StereoCamera:
    """An ideal parallel stereo pair: identical pinhole cameras, right centre at (+B, 0, 0).

    Attributes:
        K: (3,3) intrinsics of both cameras.
        size: (width, height) in pixels.
        baseline_m: B in metres.
    """

    K: np.ndarray
    size: tuple[int, int]
    baseline_m: float

    @property
    def fx(self) -> float:
        return float(self.K[0, 0])

    @classmethod
    def from_rig(cls, rig) -> "StereoCamera":
        """Build from a :class:`spacepose.calibration.rig.StereoRig`; the rig must be ideal.

        Raises:
            DatasetError: the rig has distortion, rotated cameras, different intrinsics or a
                baseline not along -x of T (the renderer's disparity is exact only for ideal rigs).
        """
        M1, M2 = np.asarray(rig.M1, float), np.asarray(rig.M2, float)
        T = np.asarray(rig.T, float).reshape(3)
        problems = []
        if np.any(np.abs(np.asarray(rig.D1, float)) > 1e-12) or np.any(np.abs(np.asarray(rig.D2, float)) > 1e-12):
            problems.append("non-zero distortion")
        if not np.allclose(np.asarray(rig.R, float), np.eye(3), atol=1e-9):
            problems.append("R is not the identity")
        if not np.allclose(M1, M2, atol=1e-9):
            problems.append("M1 != M2")
        if not (T[0] < 0 and abs(T[1]) < 1e-9 and abs(T[2]) < 1e-9):
            problems.append("T is not (-B, 0, 0)")
        if abs(M1[0, 0] - M1[1, 1]) > 1e-9 * M1[0, 0] or abs(M1[0, 1]) > 1e-12:
            problems.append("fx != fy or skew")
        if problems:
            raise DatasetError("the renderer needs an ideal parallel rig: " + "; ".join(problems))
        return cls(K=M1.copy(), size=(int(rig.image_size[0]), int(rig.image_size[1])), baseline_m=float(-T[0]))


@dataclass(frozen=True)
class PoseSampler:
    """Pose distribution of paper §4 for one camera pair and target radius.

    ``t_z`` uniform in ``depth_range``; the projected object origin uniform over the image region
    that keeps the whole bounding sphere (centre = object origin, radius = ``radius``) inside BOTH
    the left and the right image at that depth; R uniform on SO(3).
    """

    camera: StereoCamera
    radius: float
    depth_range: tuple[float, float] = (10.0, 50.0)

    def __post_init__(self) -> None:
        z0, z1 = (float(v) for v in self.depth_range)
        if not (np.isfinite(z0) and np.isfinite(z1) and 0 < z0 <= z1):
            raise DatasetError(f"depth range must satisfy 0 < min <= max, got {self.depth_range}")
        need = self.min_depth()
        if z0 < need:
            raise DatasetError(
                f"depth range {z0:g}-{z1:g} m cannot fit the target (bounding radius {self.radius:.2f} m) "
                f"in both views at {self.camera.size[0]}x{self.camera.size[1]}: the nearest depth that fits is {need:.2f} m"
            )

    def _frustum(self):
        w, h = self.camera.size
        K = self.camera.K
        a = ((-0.5 - K[0, 2]) / K[0, 0], (w - 0.5 - K[0, 2]) / K[0, 0])
        b = ((-0.5 - K[1, 2]) / K[1, 1], (h - 0.5 - K[1, 2]) / K[1, 1])
        return a, b

    def min_depth(self) -> float:
        """Smallest z at which the bounding sphere fits in both views."""
        (a0, a1), (b0, b1) = self._frustum()
        r, B = self.radius, self.camera.baseline_m
        kx = math.sqrt(1 + a0 * a0) + math.sqrt(1 + a1 * a1)
        ky = math.sqrt(1 + b0 * b0) + math.sqrt(1 + b1 * b1)
        return max((B + r * kx) / (a1 - a0), r * ky / (b1 - b0))

    def position_bounds(self, z: float) -> tuple[tuple[float, float], tuple[float, float]]:
        """((x_min, x_max), (y_min, y_max)) of the object origin at depth z (metres, left frame)."""
        (a0, a1), (b0, b1) = self._frustum()
        r, B = self.radius, self.camera.baseline_m
        x_lo = B + a0 * z + r * math.sqrt(1 + a0 * a0)
        x_hi = a1 * z - r * math.sqrt(1 + a1 * a1)
        y_lo = b0 * z + r * math.sqrt(1 + b0 * b0)
        y_hi = b1 * z - r * math.sqrt(1 + b1 * b1)
        return (x_lo, max(x_lo, x_hi)), (y_lo, max(y_lo, y_hi))

    def sample(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """Draw (R (3,3), t (3,))."""
        z = rng.uniform(*self.depth_range)
        (x0, x1), (y0, y1) = self.position_bounds(z)
        # uniform in x <=> uniform in the projected u at fixed z
        t = np.array([rng.uniform(x0, x1), rng.uniform(y0, y1), z])
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        return quaternion_to_rotation(q), t


def quaternion_to_rotation(q: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion [w, x, y, z]."""
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def rotation_to_quaternion(R: np.ndarray) -> np.ndarray:
    """Scalar-first unit quaternion [w, x, y, z] of R with w >= 0 (Shepperd's method)."""
    R = np.asarray(R, dtype=np.float64)
    tr = np.trace(R)
    cands = np.array([tr, R[0, 0], R[1, 1], R[2, 2]])
    i = int(np.argmax(cands))
    if i == 0:
        s = 2 * math.sqrt(max(1 + tr, 1e-300))
        q = [s / 4, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    elif i == 1:
        s = 2 * math.sqrt(max(1 + R[0, 0] - R[1, 1] - R[2, 2], 1e-300))
        q = [(R[2, 1] - R[1, 2]) / s, s / 4, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s]
    elif i == 2:
        s = 2 * math.sqrt(max(1 + R[1, 1] - R[0, 0] - R[2, 2], 1e-300))
        q = [(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, s / 4, (R[1, 2] + R[2, 1]) / s]
    else:
        s = 2 * math.sqrt(max(1 + R[2, 2] - R[0, 0] - R[1, 1], 1e-300))
        q = [(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, s / 4]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return -q if q[0] < 0 else q


# ---------------------------------------------------------------------------------------------
# scene


@dataclass(frozen=True, eq=False)
class Scene:
    """Everything random about one frame (vectors in the left camera frame, unit length).

    ``sun_dir`` / ``earth_dir`` point from the target toward the sun / the Earth's centre.
    Irradiances are relative to the nominal solar irradiance (1.0).
    """

    R: np.ndarray
    t: np.ndarray
    regime: str
    sun_dir: np.ndarray
    sun_irradiance: float
    sun_color: np.ndarray
    sun_angular_radius: float
    earth_dir: np.ndarray
    earth_angular_radius: float
    earth_fill: float
    earth_visible: bool
    earth_rotation: np.ndarray
    exposure_percentile: float
    exposure_level: float
    star_count: int
    star_seed: int
    materials: MaterialSet = field(repr=False)

    def to_json(self) -> dict:
        """The labels' description of the illumination (pose is written separately)."""
        return {
            "regime": self.regime,
            "sun_dir": _round(self.sun_dir),
            "sun_irradiance": round(float(self.sun_irradiance), 4),
            "sun_color": _round(self.sun_color),
            "sun_angular_radius_deg": round(math.degrees(self.sun_angular_radius), 4),
            "earth_dir": _round(self.earth_dir),
            "earth_angular_radius_deg": round(math.degrees(self.earth_angular_radius), 3),
            "earth_fill": round(float(self.earth_fill), 4),
            "earth_in_view": bool(self.earth_visible),
            "exposure": {"percentile": round(self.exposure_percentile, 2), "level": round(self.exposure_level, 3)},
            "stars": int(self.star_count),
            "materials": self.materials.summary,
        }


def _round(v, nd: int = 6) -> list:
    return [round(float(x), nd) for x in np.asarray(v).ravel()]


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _random_unit(rng: np.random.Generator) -> np.ndarray:
    return _unit(rng.normal(size=3))


def _cone_dir(rng: np.random.Generator, axis: np.ndarray, max_angle: float) -> np.ndarray:
    """Uniform direction within ``max_angle`` of ``axis``."""
    cos_t = rng.uniform(math.cos(max_angle), 1.0)
    sin_t = math.sqrt(max(0.0, 1 - cos_t * cos_t))
    phi = rng.uniform(0, 2 * math.pi)
    helper = np.array([1.0, 0, 0]) if abs(axis[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = _unit(np.cross(axis, helper))
    e2 = np.cross(axis, e1)
    return _unit(cos_t * axis + sin_t * (math.cos(phi) * e1 + math.sin(phi) * e2))


def _earth_limb_in_view(rng: np.random.Generator, camera: StereoCamera, rho: float) -> np.ndarray:
    """An Earth-centre direction whose limb passes through a random point of the image."""
    w, h = camera.size
    K = camera.K
    u, v = rng.uniform(0, w - 1), rng.uniform(0, h - 1)
    p = _unit(np.array([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], 1.0]))
    for _ in range(8):
        perp = np.cross(p, _random_unit(rng))
        if np.linalg.norm(perp) > 1e-3:
            break
    perp = _unit(perp)
    # the centre is rho away from p, on the side that keeps most of the disc off-axis half the time
    centre = math.cos(rho) * p + math.sin(rho) * perp
    return _unit(centre)


def sample_scene(target, camera: StereoCamera, rng: np.random.Generator, regime: str, pose_sampler: PoseSampler) -> Scene:
    """Draw one frame's scene for ``regime`` (one of :data:`REGIMES`)."""
    if regime not in REGIMES:
        raise DatasetError(f"unknown regime {regime!r}; use one of {REGIMES}")
    R, t = pose_sampler.sample(rng)
    view_back = np.array([0.0, 0.0, -1.0])  # from the target toward the camera (approximately)
    altitude_km = math.exp(rng.uniform(math.log(400.0), math.log(36000.0)))
    rho = math.asin(_EARTH_RADIUS_KM / (_EARTH_RADIUS_KM + altitude_km))
    sun_color = np.ones(3)
    sun_ang = SUN_ANGULAR_RADIUS
    if regime == "sun":
        sun_dir = _cone_dir(rng, view_back, math.radians(110))
        sun_irr = rng.uniform(0.7, 1.3)
        earth_dir = _random_unit(rng)  # black sky: keep the Earth out of view
        for _ in range(32):
            if not _earth_in_view(camera, earth_dir, rho):
                break
            earth_dir = _random_unit(rng)
        else:
            earth_dir = view_back.copy()
        earth_fill = rng.uniform(0.0, 0.03)
    elif regime == "albedo":
        if rng.random() < 0.5:
            sun_dir = _cone_dir(rng, -view_back, math.radians(75))  # behind the target
            sun_irr = rng.uniform(0.6, 1.2)
        else:
            sun_dir = _random_unit(rng)  # eclipsed
            sun_irr = 0.0
        earth_dir = _cone_dir(rng, view_back, math.radians(80))
        earth_fill = rng.uniform(0.12, 0.45)
    elif regime == "penumbra":
        sun_dir = _cone_dir(rng, view_back, math.radians(110))
        sun_irr = rng.uniform(0.04, 0.35)
        sun_color = np.array([1.0, rng.uniform(0.55, 0.9), rng.uniform(0.3, 0.7)])
        sun_ang = math.radians(rng.uniform(0.8, 3.0))
        earth_dir = _cone_dir(rng, view_back, math.radians(150))
        earth_fill = rng.uniform(0.0, 0.12)
    else:  # mixed
        sun_dir = _cone_dir(rng, view_back, math.radians(120))
        sun_irr = rng.uniform(0.5, 1.2)
        if rng.random() < 0.7:
            earth_dir = _earth_limb_in_view(rng, camera, rho)
        else:
            earth_dir = _random_unit(rng)
        phase = 0.5 * (1.0 + float(np.dot(sun_dir, earth_dir)) * -1.0)  # lit fraction seen from the target
        earth_fill = rng.uniform(0.1, 0.4) * (0.2 + 0.8 * phase)
    earth_visible = _earth_in_view(camera, earth_dir, rho)
    materials = sample_materials(assign_materials(target), rng)
    q_earth = rng.normal(size=4)
    return Scene(
        R=R,
        t=t,
        regime=regime,
        sun_dir=sun_dir,
        sun_irradiance=float(sun_irr),
        sun_color=sun_color,
        sun_angular_radius=float(sun_ang),
        earth_dir=earth_dir,
        earth_angular_radius=float(rho),
        earth_fill=float(earth_fill),
        earth_visible=bool(earth_visible),
        earth_rotation=quaternion_to_rotation(q_earth / np.linalg.norm(q_earth)),
        exposure_percentile=float(rng.uniform(80.0, 99.5)),
        exposure_level=float(rng.uniform(0.55, 1.35)),
        star_count=int(rng.integers(0, 400)) if rng.random() < 0.5 else 0,
        star_seed=int(rng.integers(0, 2**31 - 1)),
        materials=materials,
    )


def _angle_to_axis(d: np.ndarray) -> float:
    return math.acos(float(np.clip(d[2], -1, 1)))


def _earth_in_view(camera: StereoCamera, earth_dir: np.ndarray, rho: float) -> bool:
    w, h = camera.size
    K = camera.K
    half_diag = math.atan(math.hypot(max(K[0, 2], w - K[0, 2]) / K[0, 0], max(K[1, 2], h - K[1, 2]) / K[1, 1]))
    return _angle_to_axis(earth_dir) < rho + half_diag


# ---------------------------------------------------------------------------------------------
# ray casting


@functools.lru_cache(maxsize=4)
def embree_scene(target):
    """The embree (embreex) scene of ``target``'s mesh in object coordinates; one per process."""
    from spacepose._optional import import_optional

    rtcore_scene = import_optional("embreex.rtcore_scene")
    mesh_construction = import_optional("embreex.mesh_construction")
    scene = rtcore_scene.EmbreeScene()
    mesh_construction.TriangleMesh(
        scene=scene,
        vertices=np.ascontiguousarray(target.mesh.vertices, dtype=np.float32),
        indices=np.ascontiguousarray(target.mesh.faces, dtype=np.int32),
    )
    return scene


@dataclass(frozen=True, eq=False)
class _Static:
    """Per-target arrays used by the shader."""

    face_normals: np.ndarray  # (F,3) float32
    face_part: np.ndarray  # (F,) int32
    face_class: np.ndarray  # (F,) int8
    part_axes: np.ndarray  # (P,3,3) float32


@functools.lru_cache(maxsize=4)
def _static(target) -> _Static:
    pmap = assign_materials(target)
    return _Static(
        face_normals=np.asarray(target.mesh.face_normals, dtype=np.float32),
        face_part=target.part_labels.astype(np.int32),
        face_class=pmap.face_class,
        part_axes=pmap.part_axes,
    )


def _roi(camera: StereoCamera, center_cam: np.ndarray, radius: float) -> tuple[int, int, int, int]:
    """Pixel box (x0, y0, x1, y1), exclusive ends, that holds the projected bounding sphere."""
    w, h = camera.size
    K = camera.K
    X, Y, Z = center_cam
    if Z - radius <= 1e-6:
        return 0, 0, w, h
    u, v = K[0, 0] * X / Z + K[0, 2], K[1, 1] * Y / Z + K[1, 2]
    half = max(K[0, 0], K[1, 1]) * radius / math.sqrt(max(Z * Z - radius * radius, 1e-12)) * 1.02 + 2
    x0, x1 = int(max(0, math.floor(u - half))), int(min(w, math.ceil(u + half) + 1))
    y0, y1 = int(max(0, math.floor(v - half))), int(min(h, math.ceil(v + half) + 1))
    return x0, y0, max(x0, x1), max(y0, y1)


@dataclass(frozen=True, eq=False)
class _Hits:
    """Primary-ray hits of one view, restricted to its ROI."""

    box: tuple[int, int, int, int]
    pix: np.ndarray  # (N,) flat pixel indices into the full image of the hit pixels
    depth: np.ndarray  # (N,) Z along the optical axis (m)
    face: np.ndarray  # (N,) face index
    point: np.ndarray  # (N,3) object-frame hit points
    view: np.ndarray  # (N,3) object-frame unit vectors toward the camera


def _cast_primary(scene, camera: StereoCamera, R: np.ndarray, t: np.ndarray, centre_x: float, radius: float) -> _Hits:
    w, h = camera.size
    K = camera.K
    cam_origin = np.array([centre_x, 0.0, 0.0])
    box = _roi(camera, t - cam_origin, radius)
    x0, y0, x1, y1 = box
    if x1 <= x0 or y1 <= y0:
        empty = np.zeros(0)
        return _Hits(box, empty.astype(np.int64), empty.astype(np.float32), empty.astype(np.int64), np.zeros((0, 3)), np.zeros((0, 3)))
    xs = (np.arange(x0, x1) - K[0, 2]) / K[0, 0]
    ys = (np.arange(y0, y1) - K[1, 2]) / K[1, 1]
    gx, gy = np.meshgrid(xs, ys)
    dirs_cam = np.stack([gx.ravel(), gy.ravel(), np.ones(gx.size)], axis=1)  # z = 1: t_hit = Z
    dirs_obj = dirs_cam @ R  # R^T d for row vectors
    origin_obj = R.T @ (cam_origin - t)
    origins = np.broadcast_to(origin_obj.astype(np.float32), dirs_obj.shape)
    res = scene.run(np.ascontiguousarray(origins), dirs_obj.astype(np.float32), output=1)
    prim = res["primID"]
    hit = prim >= 0
    tfar = res["tfar"][hit]
    d_hit = dirs_obj[hit]
    point = origin_obj[None, :] + tfar[:, None].astype(np.float64) * d_hit
    view = -d_hit / np.linalg.norm(d_hit, axis=1, keepdims=True)
    iy, ix = np.divmod(np.flatnonzero(hit), x1 - x0)
    pix = (iy + y0) * w + (ix + x0)
    return _Hits(box, pix.astype(np.int64), tfar.astype(np.float32), prim[hit].astype(np.int64), point, view)


def _occluded(scene, points: np.ndarray, normals: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """(N,) bool: does the mesh block the ray from each point (offset along its normal) along direction."""
    if len(points) == 0:
        return np.zeros(0, dtype=bool)
    origins = (points + normals * _SHADOW_OFFSET + direction * 1e-3).astype(np.float32)
    dirs = np.broadcast_to(direction.astype(np.float32), origins.shape) if direction.ndim == 1 else direction.astype(np.float32)
    res = scene.run(origins, np.ascontiguousarray(dirs), query="OCCLUDED")
    return np.asarray(res) != -1


# ---------------------------------------------------------------------------------------------
# shading


def _hash3(cells: np.ndarray, salt: int) -> np.ndarray:
    """(N,3) int64 cells -> (N,3) floats in [0,1), a cheap integer hash (stable across views)."""
    c = cells.astype(np.uint64)
    h = c[:, 0] * np.uint64(73856093) ^ c[:, 1] * np.uint64(19349663) ^ c[:, 2] * np.uint64(83492791) ^ np.uint64(salt)
    out = np.empty((len(c), 3))
    for k in range(3):
        h = (h ^ (h >> np.uint64(13))) * np.uint64(0x5BD1E995) + np.uint64(k + 1)
        h = h ^ (h >> np.uint64(15))
        out[:, k] = (h & np.uint64(0xFFFFFF)).astype(np.float64) / float(0x1000000)
    return out


def _value_noise3(x: np.ndarray, salt: int) -> np.ndarray:
    """(N,3) smooth vector noise in [-1, 1]: trilinear interpolation of hashed lattice vectors."""
    base = np.floor(x)
    f = x - base
    f = f * f * (3.0 - 2.0 * f)  # smoothstep: continuous normals, no facet edges
    cells = base.astype(np.int64)
    out = np.zeros_like(x)
    for corner in range(8):
        off = np.array([(corner >> 0) & 1, (corner >> 1) & 1, (corner >> 2) & 1])
        w = np.prod(np.where(off[None, :] == 1, f, 1.0 - f), axis=1)
        out += w[:, None] * (_hash3(cells + off[None, :], salt) * 2.0 - 1.0)
    return out


def _line_coverage(x: np.ndarray, width: float, footprint: np.ndarray) -> np.ndarray:
    """Fraction of a pixel footprint (in period units) covered by lines of ``width`` centred on integers."""

    def integral(y):  # integral of the periodic indicator of [0, width)
        fl = np.floor(y)
        return fl * width + np.minimum(y - fl, width)

    h = np.maximum(footprint, 1e-4) * 0.5
    y = x + width * 0.5
    return np.clip((integral(y + h) - integral(y - h)) / (2 * h), 0.0, 1.0)


def _ggx_specular(n, v, l, nl, nv, alpha, f0):
    hvec = v + l
    hvec /= np.maximum(np.linalg.norm(hvec, axis=1, keepdims=True), 1e-9)
    nh = np.clip(np.einsum("ij,ij->i", n, hvec), 0.0, 1.0)
    vh = np.clip(np.einsum("ij,ij->i", v, hvec), 0.0, 1.0)
    a2 = alpha * alpha
    denom = nh * nh * (a2 - 1.0) + 1.0
    D = a2 / (np.pi * denom * denom + 1e-12)
    k = alpha * 0.5
    G = (nl / (nl * (1 - k) + k + 1e-9)) * (nv / (nv * (1 - k) + k + 1e-9))
    fres = f0 + (1.0 - f0) * ((1.0 - vh) ** 5)[:, None]
    return fres * (D * G / (4.0 * nl * nv + 1e-6))[:, None]


def _shade(scene_bvh, target, frame: Scene, hits: _Hits, fx: float) -> np.ndarray:
    """(N,3) linear radiance of the hit points."""
    n_hits = len(hits.face)
    if n_hits == 0:
        return np.zeros((0, 3), dtype=np.float32)
    st = _static(target)
    mats = frame.materials
    R = frame.R
    part = st.face_part[hits.face]
    fclass = st.face_class[hits.face]
    n = st.face_normals[hits.face].astype(np.float64)
    v = hits.view
    flip = np.einsum("ij,ij->i", n, v) < 0
    n[flip] *= -1.0  # two sided: the side facing the camera
    geo_n = n.copy()

    albedo = mats.albedo[part].astype(np.float64)
    f0 = mats.f0[part].astype(np.float64)
    rough = mats.roughness[part].astype(np.float64)

    # MLI crinkles: per object-space cell normal tilt (same cells in both views)
    crinkle = mats.crinkle[part]
    is_mli = (fclass == MLI) & (crinkle > 0)
    if np.any(is_mli):
        p_mli = hits.point[is_mli]
        tilt = _value_noise3(p_mli / mats.crinkle_cell, 17) + 0.5 * _value_noise3(p_mli / (0.37 * mats.crinkle_cell), 29)
        nm = n[is_mli] + tilt * crinkle[is_mli, None]
        nm /= np.linalg.norm(nm, axis=1, keepdims=True)
        n[is_mli] = nm
    # solar cells: grid of cells with metallic interconnect gaps in the part's own plane
    is_cell = fclass == SOLAR
    if np.any(is_cell):
        axes = st.part_axes[part[is_cell]]
        p = hits.point[is_cell]
        # pixel footprint on the surface (m), to box-filter the sub-pixel gap lines (no aliasing)
        footprint = hits.depth[is_cell].astype(np.float64) / fx
        cu = np.einsum("ij,ij->i", p, axes[:, 0]) / mats.cell_size
        cv = np.einsum("ij,ij->i", p, axes[:, 1]) / (mats.cell_size * 0.7)
        gu = _line_coverage(cu, 0.08, footprint / mats.cell_size)
        gv = _line_coverage(cv, 0.1, footprint / (mats.cell_size * 0.7))
        gap = (1.0 - (1.0 - gu) * (1.0 - gv))[:, None]
        idx = np.flatnonzero(is_cell)
        albedo[idx] = albedo[idx] * (1 - gap) + mats.grid_albedo * 0.6 * gap
        f0[idx] = f0[idx] * (1 - gap) + 0.6 * gap
        rough[idx] = rough[idx] * (1 - gap[:, 0]) + 0.35 * gap[:, 0]
    is_back = fclass == SOLAR_BACK
    if np.any(is_back):
        albedo[is_back] = mats.grid_albedo
        f0[is_back] = 0.04
        rough[is_back] = 0.8
    alpha = np.clip(rough * rough, 0.002, 1.0)

    nv = np.clip(np.einsum("ij,ij->i", n, v), 1e-4, 1.0)
    radiance = np.zeros((n_hits, 3))

    # direct sun
    if frame.sun_irradiance > 0:
        l_sun = R.T @ frame.sun_dir
        nl_geo = geo_n @ l_sun
        nl = np.clip(n @ l_sun, 0.0, 1.0)
        lit = np.flatnonzero((nl_geo > 0) & (nl > 0))
        if len(lit):
            if frame.sun_angular_radius > 2 * SUN_ANGULAR_RADIUS:
                vis = np.zeros(len(lit))
                for offset in _disc_offsets(l_sun, frame.sun_angular_radius):
                    vis += ~_occluded(scene_bvh, hits.point[lit], geo_n[lit], _unit(l_sun + offset))
                vis /= 4.0
            else:
                vis = (~_occluded(scene_bvh, hits.point[lit], geo_n[lit], l_sun)).astype(np.float64)
            nl_l = nl[lit]
            spec = _ggx_specular(n[lit], v[lit], l_sun[None, :], nl_l, nv[lit], alpha[lit], f0[lit])
            diffuse = albedo[lit] / np.pi
            e = frame.sun_irradiance * vis * nl_l
            radiance[lit] += (diffuse + spec) * e[:, None] * frame.sun_color[None, :]

    # Earth albedo fill: a large spherical light of angular radius rho
    if frame.earth_fill > 0:
        l_e = R.T @ frame.earth_dir
        sr = math.sin(frame.earth_angular_radius)
        cos_e = n @ l_e
        wrap = np.clip((cos_e + sr) / (1.0 + sr), 0.0, 1.0) ** 2
        lit = np.flatnonzero(wrap > 1e-4)
        if len(lit):
            vis = 0.4 + 0.6 * (~_occluded(scene_bvh, hits.point[lit], geo_n[lit], l_e))
            alpha_e = np.clip(alpha[lit] + sr, 0.0, 1.0)
            nl_l = np.clip(cos_e[lit], 0.05, 1.0)
            spec = _ggx_specular(n[lit], v[lit], l_e[None, :], nl_l, nv[lit], alpha_e, f0[lit])
            e = frame.earth_fill * vis * wrap[lit]
            radiance[lit] += (albedo[lit] / np.pi + spec) * e[:, None] * _FILL_COLOR[None, :]
    return radiance.astype(np.float32)


def _disc_offsets(axis: np.ndarray, radius: float) -> list[np.ndarray]:
    helper = np.array([1.0, 0, 0]) if abs(axis[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = _unit(np.cross(axis, helper))
    e2 = np.cross(axis, e1)
    s = math.tan(radius) * 0.7
    return [s * e1, -s * e1, s * e2, -s * e2]


# ---------------------------------------------------------------------------------------------
# background


def _background(camera: StereoCamera, frame: Scene) -> np.ndarray:
    """(H,W,3) linear radiance of the sky at infinity: Earth disc/limb; identical in both views."""
    w, h = camera.size
    out = np.zeros((h * w, 3), dtype=np.float32)
    if not frame.earth_visible:
        return out.reshape(h, w, 3)
    d = _pixel_directions(camera)
    e = frame.earth_dir.astype(np.float32)
    rho = frame.earth_angular_radius
    cos_ang = d @ e
    glow_ang = rho + math.radians(1.2) * max(rho / 0.5, 0.3)
    near = np.flatnonzero(cos_ang > math.cos(min(glow_ang, math.pi)))
    if len(near) == 0:
        return out.reshape(h, w, 3)
    dn = d[near]
    c = cos_ang[near]
    dist = 1.0 / math.sin(rho)  # Earth radius = 1
    disc = c > math.cos(rho)
    s_dir = frame.sun_dir
    sun = frame.sun_irradiance * frame.sun_color
    # ground
    idx = np.flatnonzero(disc)
    if len(idx):
        b = dist * c[idx]
        tt = b - np.sqrt(np.maximum(b * b - dist * dist + 1.0, 0.0))
        p = tt[:, None] * dn[idx]
        normal = p - dist * e[None, :]
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        mu_s = normal @ s_dir
        mu_v = np.clip(-np.einsum("ij,ij->i", normal, dn[idx]), 0.0, 1.0)
        # procedural continents and cloud bands: sums of plane waves on the unit sphere
        local = (normal @ (frame.earth_rotation.T * _WAVES_SCALE)).astype(np.float32)  # (N,3) scaled
        land = (np.sin(local @ _LAND_WAVES[0]) + np.sin(local @ _LAND_WAVES[1]) * 0.7 + np.sin(local @ _LAND_WAVES[2]) * 0.4) > 0.6
        cloud = np.sin(local @ _CLOUD_WAVES[0] + 2.0 * np.sin(local @ _CLOUD_WAVES[1])) * np.sin(local @ _CLOUD_WAVES[2])
        cloud = np.clip((cloud - 0.1) * 2.0, 0, 1) * 0.85
        base = np.where(land[:, None], np.array([0.16, 0.14, 0.08]), np.array([0.02, 0.05, 0.11]))
        alb = base * (1 - cloud[:, None]) + 0.75 * cloud[:, None]
        day = np.clip(mu_s, 0.0, 1.0)
        haze = (1.0 - mu_v) ** 3 * np.clip(mu_s + 0.15, 0.0, 1.0)
        rad = alb * day[:, None] / np.pi * sun[None, :] + 0.12 * haze[:, None] * np.array([0.35, 0.55, 1.0]) * sun[None, :]
        out[near[idx]] = rad
    # thin atmosphere glow just outside the limb
    idx = np.flatnonzero(~disc)
    if len(idx):
        ang = np.arccos(np.clip(c[idx], -1, 1)) - rho
        width = glow_ang - rho
        g = np.exp(-ang / (0.3 * width))
        perp = dn[idx] - c[idx, None] * e[None, :]
        perp /= np.maximum(np.linalg.norm(perp, axis=1, keepdims=True), 1e-9)
        sunlit = np.clip(perp @ s_dir + 0.2, 0.0, 1.0)
        out[near[idx]] = (0.05 * g * sunlit)[:, None] * np.array([0.35, 0.55, 1.0])[None, :] * sun[None, :]
    return out.reshape(h, w, 3)


_WAVES_SCALE = 1.0
_LAND_WAVES = (np.array([2.1, 1.3, -1.7], np.float32), np.array([-3.9, 4.4, 2.2], np.float32), np.array([6.5, -2.8, 7.9], np.float32))
_CLOUD_WAVES = (np.array([1.5, 13.0, 3.0], np.float32), np.array([9.0, -2.0, 5.5], np.float32), np.array([-11.0, 4.0, 15.0], np.float32))


@functools.lru_cache(maxsize=8)
def _pixel_directions_cached(K_bytes: bytes, w: int, h: int) -> np.ndarray:
    K = np.frombuffer(K_bytes, dtype=np.float64).reshape(3, 3)
    xs = ((np.arange(w) - K[0, 2]) / K[0, 0]).astype(np.float32)
    ys = ((np.arange(h) - K[1, 2]) / K[1, 1]).astype(np.float32)
    gx, gy = np.meshgrid(xs, ys)
    d = np.stack([gx.ravel(), gy.ravel(), np.ones(gx.size, np.float32)], axis=1)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d.setflags(write=False)
    return d


def _pixel_directions(camera: StereoCamera) -> np.ndarray:
    """(H*W, 3) float32 unit ray directions of the pixel centres (cached per camera)."""
    return _pixel_directions_cached(np.ascontiguousarray(camera.K, dtype=np.float64).tobytes(), *camera.size)


def _stars(camera: StereoCamera, frame: Scene) -> np.ndarray:
    """(H,W) display-space star intensities (faint points at infinity; same pixels in both views)."""
    w, h = camera.size
    img = np.zeros((h, w), dtype=np.float32)
    if frame.star_count == 0:
        return img
    rng = np.random.default_rng(frame.star_seed)
    n = int(frame.star_count * w * h / (640 * 480))
    x = rng.integers(0, w, n)
    y = rng.integers(0, h, n)
    img[y, x] = rng.pareto(2.5, n).astype(np.float32) * 0.04 + 0.01
    return np.minimum(img, 0.5)


# ---------------------------------------------------------------------------------------------
# stereo frame


@dataclass(frozen=True, eq=False)
class StereoRender:
    """A clean (not yet degraded) stereo frame and its exact ground truth.

    Attributes:
        left, right: (H,W,3) float32 display values in [0,1] (tone mapped, before degradations).
        disparity: (H,W) float32, fx*B/Z on left target pixels, 0 elsewhere.
        depth: (H,W) float32 left depth Z (m) on target pixels, 0 elsewhere.
        mask, mask_right: (H,W) bool target pixels of the left / right image.
        exposure: the linear radiance -> display scale used for both views.
    """

    left: np.ndarray
    right: np.ndarray
    disparity: np.ndarray
    depth: np.ndarray
    mask: np.ndarray
    mask_right: np.ndarray
    depth_right: np.ndarray
    exposure: float


@functools.lru_cache(maxsize=1)
def _tone_lut() -> np.ndarray:
    x = np.linspace(0.0, 1.0, _TONE_STEPS + 1)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055).astype(np.float32)


_TONE_STEPS = 1 << 15


def _tone(linear: np.ndarray) -> np.ndarray:
    """sRGB transfer curve of linear values clipped to [0, 1] (sensor saturation), via a 2^15 LUT."""
    idx = np.clip(linear * _TONE_STEPS + 0.5, 0, _TONE_STEPS).astype(np.int32)
    return _tone_lut()[idx]


def render_stereo(target, camera: StereoCamera, frame: Scene) -> StereoRender:
    """Ray cast and shade both views of ``frame``; return display images and ground truth."""
    w, h = camera.size
    bvh = embree_scene(target)
    radius = target.bounding_radius
    views = []
    for centre_x in (0.0, camera.baseline_m):
        hits = _cast_primary(bvh, camera, frame.R, frame.t, centre_x, radius)
        views.append((hits, _shade(bvh, target, frame, hits, camera.fx)))
    (hl, rad_l), (hr, rad_r) = views

    # auto exposure on the left target's luminance
    lum = rad_l @ np.array([0.2126, 0.7152, 0.0722], dtype=np.float32) if len(rad_l) else np.zeros(0)
    total_light = frame.sun_irradiance * float(np.mean(frame.sun_color)) + frame.earth_fill
    floor_exposure = 0.25 / max(total_light, 0.02)
    if len(lum) and np.any(lum > 0):
        key = float(np.percentile(lum, frame.exposure_percentile))
        exposure = frame.exposure_level / max(key, 1e-6)
    else:
        exposure = floor_exposure
    exposure = float(np.clip(exposure, 0.5 * floor_exposure, 60.0 * floor_exposure))

    background = _background(camera, frame) * exposure
    stars = _stars(camera, frame)
    background += stars[:, :, None]
    images = []
    depths = []
    masks = []
    for hits, rad in ((hl, rad_l), (hr, rad_r)):
        img = background.reshape(-1, 3).copy()
        img[hits.pix] = rad * exposure
        images.append(_tone(img).reshape(h, w, 3))
        depth = np.zeros(h * w, dtype=np.float32)
        depth[hits.pix] = hits.depth
        depths.append(depth.reshape(h, w))
        mask = np.zeros(h * w, dtype=bool)
        mask[hits.pix] = True
        masks.append(mask.reshape(h, w))
    disparity = np.zeros((h, w), dtype=np.float32)
    m = masks[0]
    disparity[m] = (camera.fx * camera.baseline_m / depths[0][m].astype(np.float64)).astype(np.float32)
    return StereoRender(
        left=images[0],
        right=images[1],
        disparity=disparity,
        depth=depths[0],
        mask=masks[0],
        mask_right=masks[1],
        depth_right=depths[1],
        exposure=exposure,
    )
