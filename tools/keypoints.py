"""SIFT-FPS keypoint selection for a target (FFB6D-style, paper §3.3.2).

SIFT runs on Lambertian views of the target rendered from ``n_views`` directions spread evenly on a
sphere (Fibonacci lattice); every detection is lifted to 3-D through the ray-cast hit point of its
pixel; farthest-point sampling over those salient surface points, started from the object centre,
picks ``n_keypoints`` keypoints. The centre is the bounding-box centre of the (scaled) mesh. Per-part
albedo (hashed from the part index) gives SIFT the part boundaries a real camera sees. The result is
deterministic for a given target, view count, image size and seed.
"""

from __future__ import annotations

import json
import logging
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from spacepose.errors import DatasetError

log = logging.getLogger(__name__)

__all__ = ["KeypointConfig", "KeypointSet", "select_keypoints", "farthest_point_sampling", "save_keypoints",
           "load_keypoints", "fibonacci_directions"]


@dataclass(frozen=True)
class KeypointConfig:
    """How keypoints are selected (stored next to them)."""

    n_keypoints: int = 8
    n_views: int = 32
    image_size: int = 384  # square views, pixels
    sift_features: int = 400  # per view
    seed: int = 0


@dataclass(frozen=True)
class KeypointSet:
    """Object-frame keypoints (M,3) and centre (3,) in metres, with the config that made them."""

    target: str
    keypoints: np.ndarray
    centre: np.ndarray
    config: KeypointConfig
    n_candidates: int

    def to_json(self) -> dict:
        return {
            "target": self.target,
            "keypoints": np.round(self.keypoints, 6).tolist(),
            "centre": np.round(self.centre, 6).tolist(),
            "config": asdict(self.config),
            "n_candidates": self.n_candidates,
            "method": "SIFT on Lambertian ray-cast views lifted to 3-D, farthest-point sampling from the centre",
        }


def fibonacci_directions(n: int) -> np.ndarray:
    """(n,3) unit vectors spread evenly over the sphere."""
    i = np.arange(n) + 0.5
    phi = np.arccos(1.0 - 2.0 * i / n)
    theta = np.pi * (1.0 + 5.0**0.5) * i
    return np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], axis=1)


def farthest_point_sampling(points: np.ndarray, n: int, start: np.ndarray) -> np.ndarray:
    """Pick ``n`` rows of ``points`` (N,3) greedily, each farthest from ``start`` and those chosen.

    Returns (n,3). Raises ValueError when fewer than ``n`` distinct points exist.
    """
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {points.shape}")
    if len(np.unique(points.round(9), axis=0)) < n:
        raise ValueError(f"need at least {n} distinct candidate points, got {len(points)}")
    dist = np.linalg.norm(points - np.asarray(start, dtype=np.float64), axis=1)
    chosen = []
    for _ in range(n):
        idx = int(np.argmax(dist))
        chosen.append(points[idx])
        dist = np.minimum(dist, np.linalg.norm(points - points[idx], axis=1))
    return np.array(chosen)


def _look_at(direction: np.ndarray) -> np.ndarray:
    """Rows = camera axes (x right, y down, z forward) for a camera looking along -direction at the origin."""
    z = -direction / np.linalg.norm(direction)
    up = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z])


def _render_view(mesh, albedo: np.ndarray, direction: np.ndarray, radius: float, size: int):
    """Ray-cast one Lambertian view. Returns (grey uint8 (S,S), hit points (S,S,3) NaN where sky)."""
    axes = _look_at(direction)
    distance = 3.0 * radius
    origin = direction / np.linalg.norm(direction) * distance
    f = size / 2.0 / (radius / distance) * 0.95  # the bounding sphere fills the view
    u, v = np.meshgrid(np.arange(size) - (size - 1) / 2.0, np.arange(size) - (size - 1) / 2.0)
    rays_cam = np.stack([u / f, v / f, np.ones_like(u)], axis=-1).reshape(-1, 3)
    rays = rays_cam @ axes
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    origins = np.broadcast_to(origin, rays.shape).copy()
    tri = mesh.ray.intersects_first(ray_origins=origins, ray_directions=rays)
    hit = tri >= 0
    points = np.full((size * size, 3), np.nan)
    grey = np.zeros(size * size)
    if hit.any():
        n = mesh.face_normals[tri[hit]]
        o = origins[hit]
        plane_pt = mesh.triangles[tri[hit], 0]
        d = rays[hit]
        depth = np.einsum("ij,ij->i", plane_pt - o, n) / np.einsum("ij,ij->i", d, n)
        points[hit] = o + depth[:, None] * d
        light = _look_at(direction)[0] * 0.5 - _look_at(direction)[2]  # over the shoulder
        light /= np.linalg.norm(light)
        grey[hit] = albedo[tri[hit]] * (0.15 + 0.85 * np.abs(n @ light))  # no back-face culling
    image = np.clip(grey * 255.0, 0, 255).astype(np.uint8).reshape(size, size)
    return image, points.reshape(size, size, 3)


def select_keypoints(target, config: KeypointConfig = KeypointConfig()) -> KeypointSet:
    """Select keypoints for a :class:`spacepose.tools.targets.Target` (scaled mesh, part labels)."""
    import cv2

    if config.n_keypoints < 1 or config.n_views < 1:
        raise ValueError("n_keypoints and n_views must be positive")
    mesh = target.mesh
    centre = np.asarray(mesh.bounds, dtype=np.float64).mean(axis=0)
    rng = np.random.default_rng(config.seed)
    part_albedo = rng.uniform(0.25, 1.0, size=int(target.n_parts))
    albedo = part_albedo[np.asarray(target.part_labels)]
    sift = cv2.SIFT_create(nfeatures=config.sift_features)
    candidates = []
    for direction in fibonacci_directions(config.n_views):
        image, points = _render_view(mesh, albedo, direction, float(target.bounding_radius), config.image_size)
        for kp in sift.detect(image, None):
            x, y = int(round(kp.pt[0])), int(round(kp.pt[1]))
            # SIFT fires on edges: take the nearest surface pixel in a 5x5 window
            win = points[max(y - 2, 0):y + 3, max(x - 2, 0):x + 3].reshape(-1, 3)
            win = win[np.isfinite(win[:, 0])]
            if len(win):
                candidates.append(win[len(win) // 2])
    if len(candidates) < config.n_keypoints:
        raise DatasetError(f"only {len(candidates)} SIFT points lifted to 3-D on target {target.name!r}")
    candidates = np.array(candidates)
    keypoints = farthest_point_sampling(candidates, config.n_keypoints, start=centre)
    log.info("keypoints for %s from %d SIFT candidates", target.name, len(candidates))
    return KeypointSet(target.name, keypoints, centre, config, len(candidates))


def save_keypoints(kps: KeypointSet, path: Path, overwrite: bool = False) -> None:
    """Write :meth:`KeypointSet.to_json` to ``path`` (refuses to overwrite unless asked)."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists (pass overwrite=True / --force)")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(kps.to_json(), indent=2) + "\n")


def load_keypoints(path: Path) -> KeypointSet:
    """Read a keypoints JSON written by :func:`save_keypoints`."""
    try:
        rec = json.loads(Path(path).read_text())
        return KeypointSet(
            target=rec["target"],
            keypoints=np.asarray(rec["keypoints"], dtype=np.float64).reshape(-1, 3),
            centre=np.asarray(rec["centre"], dtype=np.float64).reshape(3),
            config=KeypointConfig(**rec["config"]),
            n_candidates=int(rec["n_candidates"]),
        )
    except (OSError, KeyError, ValueError, TypeError) as err:
        raise DatasetError(f"cannot read keypoints from {path}: {err}") from err
