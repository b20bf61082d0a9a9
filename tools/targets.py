"""Target spacecraft meshes: load, scale to the 5.0 m rule, label parts.

The shipped targets live in ``tools/meshes/<name>/`` (NASA 3D Resources; credit and terms in
``tools/meshes/LICENSE_NASA.txt``, provenance in each ``SOURCE.txt``). Every target, shipped or
given by path, is scaled uniformly so that its longest axis-aligned bounding-box extent is exactly
:data:`LONGEST_EXTENT_M` metres; the object origin and axes are the mesh file's own.

Parts are the mesh's connected components (faces sharing an edge after vertex merging). They are
the unit the material rule (:mod:`spacepose.tools.materials`) assigns materials to.
"""

from __future__ import annotations

import functools
import hashlib
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from spacepose._optional import import_optional
from spacepose.errors import DatasetError

log = logging.getLogger(__name__)

__all__ = ["LONGEST_EXTENT_M", "MESH_DIR", "SHIPPED_TARGETS", "Target", "TargetError", "load_target", "target_path"]

#: every target is scaled so that its longest bounding-box extent is this many metres
LONGEST_EXTENT_M = 5.0
#: folder of the shipped meshes
MESH_DIR = Path(__file__).resolve().parent / "meshes"
#: shipped target name -> mesh file relative to MESH_DIR
SHIPPED_TARGETS: dict[str, str] = {"tdrs": "tdrs/tdrs.stl", "mro": "mro/MRO_13.stl"}


class TargetError(DatasetError):
    """A target mesh is unknown, missing, unreadable or degenerate."""


@dataclass(frozen=True, eq=False)
class Target:
    """A target spacecraft ready for rendering.

    Attributes:
        name: shipped name (``tdrs``, ``mro``) or the mesh file's stem.
        path: the mesh file.
        sha256: hex digest of the mesh file's bytes (identifies the target in dataset manifests).
        mesh: ``trimesh.Trimesh`` in metres (already scaled), object frame = the file's frame.
        scale: metres per mesh-file unit.
        part_labels: (F,) int32, connected-component index of every face.
        n_parts: number of parts.
        bounding_radius: radius (m) of the sphere centred on the object origin that holds every vertex.
    """

    name: str
    path: Path
    sha256: str
    mesh: object
    scale: float
    part_labels: np.ndarray
    n_parts: int
    bounding_radius: float


def target_path(name_or_path: str | Path) -> Path:
    """Resolve a shipped target name or a mesh path; raise :class:`TargetError` if it does not exist."""
    key = str(name_or_path)
    if key in SHIPPED_TARGETS:
        path = MESH_DIR / SHIPPED_TARGETS[key]
    else:
        path = Path(key).expanduser()
        if path.suffix == "" and not path.exists():
            raise TargetError(f"unknown target {key!r}: use one of {sorted(SHIPPED_TARGETS)} or a mesh file path")
    if not path.is_file():
        raise TargetError(f"target mesh not found: {path}")
    return path.resolve()


def load_target(name_or_path: str | Path) -> Target:
    """Load a target by shipped name (``tdrs``, ``mro``) or mesh path (STL/OBJ/PLY...).

    Results are cached per resolved path (a process loads each mesh once).

    Raises:
        TargetError: unknown name, missing file, unreadable/corrupt file, or a mesh without
            usable triangles.
    """
    return _load_cached(str(target_path(name_or_path)), str(name_or_path))


@functools.lru_cache(maxsize=8)
def _load_cached(path_str: str, requested: str) -> Target:
    trimesh = import_optional("trimesh")
    path = Path(path_str)
    data = path.read_bytes()
    try:
        loaded = trimesh.load(path, force="mesh", process=True)
    except Exception as err:  # trimesh raises many types on corrupt input
        raise TargetError(f"cannot read target mesh {path}: {err}") from err
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise TargetError(f"target mesh {path} holds no triangles")
    vertices = np.asarray(loaded.vertices, dtype=np.float64)
    if not np.all(np.isfinite(vertices)):
        raise TargetError(f"target mesh {path} has non-finite vertices")
    longest = float(np.max(loaded.extents))
    if not longest > 0:
        raise TargetError(f"target mesh {path} is degenerate (zero extent)")
    scale = LONGEST_EXTENT_M / longest
    mesh = trimesh.Trimesh(vertices=vertices * scale, faces=np.asarray(loaded.faces), process=False)
    labels = trimesh.graph.connected_component_labels(mesh.face_adjacency, node_count=len(mesh.faces))
    labels = np.asarray(labels, dtype=np.int32)
    radius = float(np.max(np.linalg.norm(mesh.vertices, axis=1)))
    name = requested if requested in SHIPPED_TARGETS else path.stem
    log.debug("loaded target %s: %d faces, %d parts, scale %.6g, radius %.3f m", name, len(mesh.faces), labels.max() + 1, scale, radius)
    return Target(
        name=name,
        path=path,
        sha256=hashlib.sha256(data).hexdigest(),
        mesh=mesh,
        scale=scale,
        part_labels=labels,
        n_parts=int(labels.max()) + 1,
        bounding_radius=radius,
    )
