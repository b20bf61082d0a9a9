"""Global outline search: candidate orientations from the observed silhouette alone (numpy + OpenCV).

The outline refinement (:mod:`spacepose.silhouette`) is local: started 20° or more from the truth,
it settles in another pose, and registration to noisy far stereo points often starts it there. Yet
the truth fits the outline better than what the refinement reaches on most such frames (session 12,
400 train frames with the gates open: on 50 of 58 wrong poses and 68 of 94 flips the refined true pose
had the lower chamfer; ``python -m spacepose.tools.outline_oracle``). So the outline is searched
globally for more starts. (Measured on this target, the search also finds wrong poses that fit better
than the truth; the shipped bundle does not enable it: see its model card.)

*Templates* (:class:`OutlineTemplates`, built once from the bundle's silhouette samples): the
target seen orthographically along ``views`` directions spread over the sphere, each a
``grid`` x ``grid`` mask in metres centred on the silhouette's own centroid, blurred by a cell and
normalised. A view's rotation about the line of sight is not stored: the observed mask is turned
instead.

*Search* (:func:`search_outline`): a virtual camera looks along the ray through the observed mask's
centroid; the observed mask is resampled into its image plane at the target's range, on the same
metric grid, at ``angles`` rotations about that ray (one homography each, exact for a plane at that
range), and every rotation is scored against every view by cosine similarity (one matrix product).
The best-scoring orientations at least ``min_separation_deg`` apart become candidates, with the
translation that puts the template's centroid on the observed one. They are coarse (the grid's
spacing, weak perspective): the outline refinement takes them from there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from .errors import check_shape
from .registration import rotation_angle_deg

__all__ = ["OutlineTemplates", "OutlineCandidate", "sphere_directions", "view_rotation", "ray_rotation",
           "grid_homography", "search_outline"]


def sphere_directions(n: int) -> np.ndarray:
    """(n, 3) unit vectors on a Fibonacci spiral: nearly uniform over the sphere, deterministic."""
    if n < 1:
        raise ValueError(f"need at least one direction, got {n}")
    k = np.arange(n, dtype=np.float64) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = math.pi * (1.0 + math.sqrt(5.0)) * k
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def view_rotation(w: np.ndarray) -> np.ndarray:
    """(3, 3) rotation whose third row is the unit vector ``w`` (3,): it takes ``w`` to +z, the
    viewing direction of a camera looking along ``w``. The other two rows are a fixed choice."""
    check_shape(w, (3,), "w")
    w = np.asarray(w, dtype=np.float64) / np.linalg.norm(w)
    helper = np.array([1.0, 0.0, 0.0]) if abs(w[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    a = np.cross(helper, w)
    a /= np.linalg.norm(a)
    b = np.cross(w, a)
    return np.stack([a, b, w])


def ray_rotation(ray: np.ndarray) -> np.ndarray:
    """(3, 3) rotation from a virtual camera looking along the unit ``ray`` (3,, camera frame) to the
    camera: its third column is ``ray``."""
    return view_rotation(ray).T


@dataclass(frozen=True, eq=False)
class OutlineCandidate:
    """One search result: pose ``R`` (3, 3), ``t`` (3,) (camera from object) and its cosine ``score``."""

    R: np.ndarray
    t: np.ndarray
    score: float


class OutlineTemplates:
    """Orthographic silhouettes of the object-frame ``points`` (Q, 3) seen along ``views``
    directions (module docstring).

    Attributes: ``rotations`` (V, 3, 3) object -> view frame; ``centroids`` (V, 2) each silhouette's
    centroid in the view frame (metres); ``cell_m`` the grid's cell; ``half_m`` its half-width;
    ``vectors`` (V, grid*grid) float32, blurred and of unit norm.
    """

    def __init__(self, points: np.ndarray, centre: np.ndarray, radius: float, *, views: int = 1000,
                 grid: int = 32, max_points: int = 8000) -> None:
        check_shape(points, (None, 3), "points")
        check_shape(centre, (3,), "centre")
        if grid < 8 or views < 1 or not radius > 0 or len(points) < 100:
            raise ValueError(f"outline templates need grid >= 8, views >= 1, radius > 0 and 100 points; got "
                             f"grid {grid}, views {views}, radius {radius}, {len(points)} points")
        P = np.asarray(points, dtype=np.float64)
        if len(P) > max_points:   # evenly strided: the samples are area-uniform in any order
            P = P[np.linspace(0, len(P) - 1, max_points).astype(np.int64)]
        self.grid = int(grid)
        self.half_m = 1.3 * float(radius)
        self.cell_m = 2.0 * self.half_m / self.grid
        dirs = sphere_directions(views)
        self.rotations = np.stack([view_rotation(w) for w in dirs])
        self.centroids = np.zeros((views, 2))
        self.vectors = np.zeros((views, self.grid * self.grid), np.float32)
        c = np.asarray(centre, dtype=np.float64)
        for i, R in enumerate(self.rotations):
            p = (P - c) @ R[:2].T                                   # (Q, 2) metres about the centre
            mask = self._raster(p, np.zeros(2))
            ys, xs = np.nonzero(mask)
            if len(xs) == 0:
                continue
            cen = (np.stack([xs.mean(), ys.mean()]) + 0.5) * self.cell_m - self.half_m
            mask = self._raster(p, cen)                             # again, about the silhouette's centroid
            self.centroids[i] = cen + c @ R[:2].T                   # in the view frame of the object origin
            self.vectors[i] = _unit(_soft(mask))

    def _raster(self, p: np.ndarray, origin: np.ndarray) -> np.ndarray:
        ij = np.floor((p - origin + self.half_m) / self.cell_m).astype(np.int64)
        ok = np.all((ij >= 0) & (ij < self.grid), axis=1)
        mask = np.zeros((self.grid, self.grid), np.uint8)
        mask[ij[ok, 1], ij[ok, 0]] = 1
        return cv2.morphologyEx(mask, cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8))


def _soft(mask: np.ndarray) -> np.ndarray:
    return cv2.GaussianBlur(mask.astype(np.float32), (0, 0), 0.8, borderType=cv2.BORDER_CONSTANT)


def _unit(v: np.ndarray) -> np.ndarray:
    v = v.reshape(-1).astype(np.float32)
    n = float(np.linalg.norm(v))
    return v / n if n > 0 else v


def _rot2(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s], [s, c]])


def grid_homography(K: np.ndarray, R_ray: np.ndarray, angle: float, distance: float, cell_m: float,
                    half_m: float) -> np.ndarray:
    """(3, 3) map from a template grid pixel (column, row) to the image pixel of ``K`` (3, 3): the
    grid's metric point, turned by ``angle`` about the virtual camera's axis, on the plane at
    ``distance`` along it; the virtual camera turned into the real one by ``R_ray`` (3, 3)."""
    A = np.array([[cell_m, 0.0, 0.5 * cell_m - half_m], [0.0, cell_m, 0.5 * cell_m - half_m], [0.0, 0.0, 1.0]])
    M = np.eye(3)
    M[:2, :2] = _rot2(angle)
    M[2, 2] = distance
    return K @ R_ray @ M @ A


def search_outline(templates: OutlineTemplates, observed: np.ndarray, K: np.ndarray, distance: float, *,
                   angles: int = 36, candidates: int = 2, min_separation_deg: float = 30.0
                   ) -> list[OutlineCandidate]:
    """Best ``candidates`` poses for the ``observed`` (n, n) mask of a camera ``K`` (3, 3) (the
    silhouette frame's) with the target's origin ``distance`` metres away (module docstring).

    Sorted by score, each at least ``min_separation_deg`` from those before it; empty when the mask
    is empty or ``distance`` is not a positive number.
    """
    check_shape(observed, (None, None), "observed")
    check_shape(K, (3, 3), "K")
    if angles < 1 or candidates < 0:
        raise ValueError(f"angles must be >= 1 and candidates >= 0, got {angles}, {candidates}")
    ys, xs = np.nonzero(observed)
    if candidates == 0 or len(xs) == 0 or not (math.isfinite(distance) and distance > 0):
        return []
    ray = np.linalg.solve(K, np.array([xs.mean(), ys.mean(), 1.0]))
    ray /= np.linalg.norm(ray)
    R_ray = ray_rotation(ray)
    cell_px = templates.cell_m * float(K[0, 0]) / distance
    src = observed.astype(np.float32)
    if cell_px > 2.0:     # anti-alias: the grid samples the frame every cell_px pixels
        src = cv2.GaussianBlur(src, (0, 0), 0.5 * cell_px)
    g = templates.grid
    thetas = 2.0 * math.pi * np.arange(angles) / angles
    obs = np.empty((angles, g * g), np.float32)
    for a, th in enumerate(thetas):
        H = grid_homography(K, R_ray, float(th), distance, templates.cell_m, templates.half_m)
        warped = cv2.warpPerspective(src, H, (g, g), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                     borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        obs[a] = _unit(_soft(warped))
    scores = obs @ templates.vectors.T                              # (angles, views)
    order = np.argsort(scores, axis=None)[::-1]
    out: list[OutlineCandidate] = []
    for flat in order[:4096]:   # the best few thousand hold every distinct peak worth a refinement
        a, v = divmod(int(flat), scores.shape[1])
        Rz = np.eye(3)
        Rz[:2, :2] = _rot2(float(thetas[a]))
        R = R_ray @ Rz @ templates.rotations[v]
        if any(rotation_angle_deg(R, c.R) < min_separation_deg for c in out):
            continue
        t_virtual = np.append(-(Rz[:2, :2] @ templates.centroids[v]), distance)
        out.append(OutlineCandidate(R=R, t=R_ray @ t_virtual, score=float(scores[a, v])))
        if len(out) == candidates:
            break
    return out
