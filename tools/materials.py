"""Materials: the documented part -> material-class rule and per-frame randomised parameters.

The rule (applied to every target, shipped or not, using only geometry; ``R`` = bounding radius,
``a`` = part area / total area, ``s1 >= s2 >= s3`` = standard deviations of the part's vertices
along its principal axes, ``c`` = its area-weighted centroid):

1. **MLI** (multi-layer insulation foil, the bus): ``|c| < 0.2 R`` and ``a >= 0.5 %`` (big parts
   in the bus core), or box-like big parts ``s3 / s1 > 0.5`` with ``a >= 2 %``.
2. **SOLAR** (solar cells): flat rectangular plates outside the bus core: ``s3 / s2 < 0.08``,
   2-D convex hull area / minimum-area bounding rectangle ``>= 0.82`` (a disc has 0.785), ``a >= 0.5 %``.
   Faces of such a part whose normal points against the part's normal axis (sign fixed by a
   constant generic direction, see :data:`_SIDE_REFERENCE`) are **SOLAR_BACK** (panel back side).
3. **DISH** (painted antenna reflectors): round shells or discs ``s2 / s1 > 0.6``, ``s3 / s2 < 0.5``,
   ``a >= 0.5 %`` (that are not SOLAR).
4. **STRUCTURE** (booms, struts, instruments): everything else; each such part is bare metal or
   painted, decided per frame.

Per frame, :func:`sample_materials` draws each class's parameters (albedo, roughness, specular
tint F0, metallic, foil colour, crinkle and cell sizes) from wide ranges and jitters them per part,
so no two frames share a look.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

__all__ = [
    "MLI",
    "SOLAR",
    "SOLAR_BACK",
    "DISH",
    "STRUCTURE",
    "CLASS_NAMES",
    "PartMaterialMap",
    "MaterialSet",
    "assign_materials",
    "sample_materials",
]

MLI, SOLAR, SOLAR_BACK, DISH, STRUCTURE = 0, 1, 2, 3, 4
CLASS_NAMES = ("mli", "solar", "solar_back", "dish", "structure")
_SIDE_REFERENCE = np.array([0.31, 0.52, 0.79]) / np.linalg.norm([0.31, 0.52, 0.79])


@dataclass(frozen=True, eq=False)
class PartMaterialMap:
    """Static result of the rule for one target.

    Attributes:
        part_class: (P,) int8 class of each part (SOLAR parts keep SOLAR here).
        face_class: (F,) int8 class of each face (SOLAR_BACK appears only here).
        part_axes: (P, 3, 3) float32 axes of each part (rows: major, minor, normal; for flat parts the
            first two follow the minimum-area bounding rectangle's edges).
    """

    part_class: np.ndarray
    face_class: np.ndarray
    part_axes: np.ndarray


@dataclass(frozen=True, eq=False)
class MaterialSet:
    """Per-part shading parameters of one frame (linear RGB).

    Attributes:
        albedo: (P, 3) diffuse albedo.
        f0: (P, 3) specular reflectance at normal incidence (the specular tint).
        roughness: (P,) GGX roughness (alpha = roughness**2).
        crinkle: (P,) normal-perturbation amplitude (radians; MLI foil only, else 0).
        crinkle_cell: scalar cell size (m) of the foil crinkle pattern.
        cell_size: scalar solar-cell pitch (m); grid_albedo: (3,) colour of the cell gaps.
        summary: JSON-able description recorded in the labels.
    """

    albedo: np.ndarray
    f0: np.ndarray
    roughness: np.ndarray
    crinkle: np.ndarray
    crinkle_cell: float
    cell_size: float
    grid_albedo: np.ndarray
    summary: dict


def assign_materials(target) -> PartMaterialMap:
    """Apply the documented rule to ``target`` (a :class:`spacepose.tools.targets.Target`); cached."""
    return _assign_cached(target)


@functools.lru_cache(maxsize=8)
def _assign_cached(target) -> PartMaterialMap:
    mesh = target.mesh
    labels = target.part_labels
    n_parts = target.n_parts
    radius = target.bounding_radius
    areas = np.asarray(mesh.area_faces, dtype=np.float64)
    total = float(areas.sum()) or 1.0
    tris = np.asarray(mesh.triangles, dtype=np.float64)
    normals = np.asarray(mesh.face_normals, dtype=np.float64)
    part_class = np.full(n_parts, STRUCTURE, dtype=np.int8)
    part_axes = np.tile(np.eye(3, dtype=np.float32), (n_parts, 1, 1))
    face_class = np.full(len(labels), STRUCTURE, dtype=np.int8)
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], np.arange(n_parts + 1))
    for part in range(n_parts):
        faces = order[bounds[part] : bounds[part + 1]]
        area = float(areas[faces].sum())
        frac = area / total
        pts = tris[faces].reshape(-1, 3)
        weights = np.repeat(areas[faces], 3) + 1e-15
        centroid = (pts * weights[:, None]).sum(0) / weights.sum()
        cov = np.cov((pts - centroid).T, aweights=weights) if len(pts) > 3 else np.eye(3) * 1e-12
        evals, evecs = np.linalg.eigh(cov + 1e-15 * np.eye(3))
        s3, s2, s1 = np.sqrt(np.maximum(evals, 0.0))  # ascending eigenvalues
        axes = evecs[:, ::-1].T  # rows: major, minor, normal
        if axes[2] @ _SIDE_REFERENCE < 0:
            axes[2] = -axes[2]
        part_axes[part] = axes
        core = np.linalg.norm(centroid) < 0.2 * radius
        flat = s3 / max(s2, 1e-12)
        rect = 0.0
        if flat < 0.08:
            rect, edges = _rectangularity(pts - centroid, axes[:2])
            axes[:2] = edges  # solar-cell grids follow the plate's edges
        if (core and frac >= 0.005) or (s3 / max(s1, 1e-12) > 0.5 and frac >= 0.02):
            cls = MLI
        elif flat < 0.08 and rect >= 0.82 and frac >= 0.005:
            cls = SOLAR
        elif s2 / max(s1, 1e-12) > 0.6 and flat < 0.5 and frac >= 0.005:
            cls = DISH
        else:
            cls = STRUCTURE
        part_class[part] = cls
        if cls == SOLAR:
            back = normals[faces] @ axes[2] < 0
            face_class[faces] = np.where(back, SOLAR_BACK, SOLAR)
        else:
            face_class[faces] = cls
    return PartMaterialMap(part_class=part_class, face_class=face_class, part_axes=part_axes)


def _rectangularity(points: np.ndarray, axes: np.ndarray) -> tuple[float, np.ndarray]:
    """Fill of a flat part's minimum-area bounding rectangle by its 2-D convex hull, and that
    rectangle's edge directions (2, 3) in object space (rectangle 1.0, disc 0.785)."""
    import cv2
    from scipy.spatial import ConvexHull, QhullError

    uv = points @ axes.T
    if len(uv) < 3:
        return 0.0, axes
    try:
        hull_area = float(ConvexHull(uv).volume)
    except QhullError:
        return 0.0, axes
    (_, _), (w, h), angle = cv2.minAreaRect(uv.astype(np.float32))
    if w * h <= 0:
        return 0.0, axes
    a = np.deg2rad(angle)
    e1 = np.cos(a) * axes[0] + np.sin(a) * axes[1]
    e2 = -np.sin(a) * axes[0] + np.cos(a) * axes[1]
    return hull_area / float(w * h), np.stack([e1, e2])


_FOILS = {  # name: (F0 tint, probability)
    "gold": ((1.0, 0.74, 0.32), 0.45),
    "silver": ((0.92, 0.92, 0.9), 0.25),
    "copper_kapton": ((0.95, 0.55, 0.3), 0.15),
    "black": ((0.06, 0.06, 0.06), 0.15),
}


def sample_materials(pmap: PartMaterialMap, rng: np.random.Generator) -> MaterialSet:
    """Draw one frame's per-part material parameters from wide, physically plausible ranges."""
    n_parts = len(pmap.part_class)
    albedo = np.zeros((n_parts, 3))
    f0 = np.zeros((n_parts, 3))
    rough = np.zeros(n_parts)
    crinkle = np.zeros(n_parts)
    jitter = rng.uniform(0.85, 1.15, size=(n_parts, 1)) * rng.uniform(0.95, 1.05, size=(n_parts, 3))
    summary: dict = {}

    names = list(_FOILS)
    probs = np.array([_FOILS[n][1] for n in names])
    foil = names[rng.choice(len(names), p=probs / probs.sum())]
    foil_tint = np.array(_FOILS[foil][0]) * rng.uniform(0.7, 1.0)
    mli_rough = rng.uniform(0.12, 0.45)
    mli_crinkle = rng.uniform(0.08, 0.35)
    mli_diffuse = rng.uniform(0.0, 0.08)
    summary["mli"] = {"foil": foil, "roughness": round(mli_rough, 3), "crinkle_rad": round(mli_crinkle, 3)}

    cell_color = np.array([rng.uniform(0.01, 0.05), rng.uniform(0.02, 0.07), rng.uniform(0.06, 0.2)])
    solar_f0 = rng.uniform(0.03, 0.08)
    solar_rough = rng.uniform(0.05, 0.3)
    back_alb = rng.uniform(0.3, 0.8)
    summary["solar"] = {"albedo": np.round(cell_color, 3).tolist(), "f0": round(solar_f0, 3), "roughness": round(solar_rough, 3)}

    dish_alb = rng.uniform(0.55, 0.9) * np.array([1.0, rng.uniform(0.93, 1.0), rng.uniform(0.85, 1.0)])
    dish_rough = rng.uniform(0.3, 0.85)
    summary["dish"] = {"albedo": np.round(dish_alb, 3).tolist(), "roughness": round(dish_rough, 3)}

    metal_share = rng.uniform(0.3, 0.9)
    summary["structure"] = {"metal_share": round(metal_share, 3)}

    for part in range(n_parts):
        cls = pmap.part_class[part]
        if cls == MLI:
            albedo[part] = mli_diffuse
            f0[part] = foil_tint
            rough[part] = mli_rough
            crinkle[part] = mli_crinkle
        elif cls == SOLAR:
            albedo[part] = cell_color
            f0[part] = solar_f0
            rough[part] = solar_rough
        elif cls == DISH:
            albedo[part] = dish_alb
            f0[part] = 0.04
            rough[part] = dish_rough
        else:
            if rng.random() < metal_share:
                albedo[part] = 0.02
                f0[part] = rng.uniform(0.55, 0.95) * np.array([1.0, 1.0, rng.uniform(0.92, 1.02)])
                rough[part] = rng.uniform(0.15, 0.6)
            else:
                albedo[part] = rng.uniform(0.08, 0.85)
                f0[part] = 0.04
                rough[part] = rng.uniform(0.4, 0.95)
    albedo = np.clip(albedo * jitter, 0.0, 0.95)
    f0 = np.clip(f0 * np.sqrt(jitter), 0.0, 1.0)
    rough = np.clip(rough * jitter[:, 0], 0.04, 1.0)
    return MaterialSet(
        albedo=albedo.astype(np.float32),
        f0=f0.astype(np.float32),
        roughness=rough.astype(np.float32),
        crinkle=crinkle.astype(np.float32),
        crinkle_cell=float(rng.uniform(0.08, 0.25)),
        cell_size=float(rng.uniform(0.06, 0.16)),
        grid_albedo=np.full(3, back_alb, dtype=np.float32) * np.array([1.0, 1.0, 0.97], dtype=np.float32),
        summary=summary,
    )
