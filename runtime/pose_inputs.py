"""Inputs of the pose graph, built in numpy (flight runtime and training use this same code).

The pose network (``spacepose.models.pose_net``) only *gathers*: every neighbour, subsampling,
upsampling and pixel↔point index is computed here, outside the graph, so the graph exports
with standard ONNX ops (there is no kNN / FPS op in ONNX).

Graph inputs (all with a leading batch axis of 1; ``L`` = ``spec.n_levels``)::

    rgb        float32 (1, 3, Hc, Wc)  RGB crop in [0, 255] (normalised inside the graph)
    points     float32 (1, N, C)       [(xyz - xyz_mean) / xyz_scale, rgb / 255 (, normals)]
    choose     int64   (1, N)          v * Wc + u: each point's pixel in the flattened crop
    nbr_l      int64   (1, N_l, K)     K nearest level-l points of each level-l point (self first)
    sub_l      int64   (1, N_{l+1})    which level-l points form level l+1 (N_{l+1} = N_l // ratio)
    up_l       int64   (1, N_l)        nearest level-(l+1) point of each level-l point
    pix2pt_l   int64   (1, Hf_l * Wf_l) nearest level-l point (in the image) of each pixel of the
                                       fusion feature map at stride ``4 * 2**l``

Point normalisation: ``xyz_mean`` is the mean of the N sampled camera-frame points; the graph
sees ``(xyz - xyz_mean) / xyz_scale``. The graph outputs offsets in METRES (it multiplies by
``xyz_scale`` itself), with the convention ``offset = keypoint - point``; a vote is therefore
``xyz_cam + offset`` in the camera frame (the mean cancels, nothing needs adding back).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import ShapeError, check_finite, check_shape

__all__ = [
    "PoseInputSpec",
    "pose_input_names",
    "knn_indices",
    "farthest_point_sampling",
    "random_subsampling",
    "build_point_indices",
    "choose_from_pixels",
    "pix2pt_indices",
    "estimate_normals",
    "build_pose_inputs",
]

_SAMPLINGS = ("fps", "random")
_FLOAT, _INT = (np.floating,), (np.integer,)  # check_shape dtypes


@dataclass(frozen=True)
class PoseInputSpec:
    """What the pose graph expects; written into bundle.json / ONNX metadata.

    ``crop_size`` is (width, height) like OpenCV. Fusion feature maps sit at strides
    ``4 * 2**l`` for ``l < n_levels``, so both crop sides must be divisible by ``4 * 2**n_levels``.
    """

    n_points: int = 1024
    k: int = 16
    n_levels: int = 3
    ratio: int = 4
    crop_size: tuple[int, int] = (128, 128)
    xyz_scale: float = 2.5
    use_normals: bool = False
    sampling: str = "fps"
    seed: int = 0

    def __post_init__(self) -> None:
        if self.sampling not in _SAMPLINGS:
            raise ValueError(f"sampling must be one of {_SAMPLINGS}, got {self.sampling!r}")
        if self.k < 1 or self.n_levels < 1 or self.ratio < 1:
            raise ValueError("k, n_levels and ratio must be >= 1")
        if self.n_points // self.ratio**self.n_levels < 1:
            raise ValueError(f"n_points={self.n_points} too small for {self.n_levels} levels of ratio {self.ratio}")
        div = 4 * 2**self.n_levels
        if self.crop_size[0] % div or self.crop_size[1] % div:
            raise ValueError(f"crop_size {self.crop_size} must be divisible by {div}")
        if not self.xyz_scale > 0:
            raise ValueError("xyz_scale must be > 0")

    @property
    def point_channels(self) -> int:
        return 9 if self.use_normals else 6

    @property
    def level_sizes(self) -> tuple[int, ...]:
        """Point counts N_0 .. N_L (N_0 = n_points)."""
        sizes = [self.n_points]
        for _ in range(self.n_levels):
            sizes.append(sizes[-1] // self.ratio)
        return tuple(sizes)

    @property
    def fusion_strides(self) -> tuple[int, ...]:
        return tuple(4 * 2**level for level in range(self.n_levels))


def pose_input_names(n_levels: int) -> list[str]:
    """Graph input names in positional order: rgb, points, choose, nbr_*, sub_*, up_*, pix2pt_*."""
    names = ["rgb", "points", "choose"]
    for stem in ("nbr", "sub", "up", "pix2pt"):
        names += [f"{stem}_{level}" for level in range(n_levels)]
    return names


def knn_indices(query: np.ndarray, ref: np.ndarray, k: int, chunk: int = 512) -> np.ndarray:
    """Indices (M, k) int64 of the k nearest ``ref`` points of each ``query`` point, nearest first.

    Brute force in float64, ``chunk`` query rows at a time (memory ``chunk * len(ref)``). Ties are
    broken by the lower index, so the result is deterministic. If ``ref`` has fewer than ``k``
    points, the farthest found neighbour is repeated to fill the row.
    """
    check_shape(query, (None, None), "query", dtypes=_FLOAT)
    check_shape(ref, (None, query.shape[1]), "ref", dtypes=_FLOAT)
    if len(ref) == 0:
        raise ShapeError("ref must hold at least one point")
    if k < 1:
        raise ValueError(f"k must be >= 1, got {k}")
    q = query.astype(np.float64)
    r = np.ascontiguousarray(ref, dtype=np.float64)
    r2 = np.einsum("ij,ij->i", r, r)
    kk = min(k, len(r))
    out = np.empty((len(q), kk), dtype=np.int64)
    for start in range(0, len(q), chunk):
        qc = q[start:start + chunk]
        d2 = np.einsum("ij,ij->i", qc, qc)[:, None] + r2[None, :] - 2.0 * qc @ r.T
        np.maximum(d2, 0.0, out=d2)
        if kk == 1:  # argmin: fast, and ties go to the first (lowest) index
            out[start:start + chunk, 0] = np.argmin(d2, axis=1)
            continue
        if kk < len(r):
            part = np.argpartition(d2, kk - 1, axis=1)[:, :kk]
        else:
            part = np.broadcast_to(np.arange(len(r)), (len(qc), len(r)))
        pd = np.take_along_axis(d2, part, axis=1)
        order = np.lexsort((part, pd), axis=1)  # by distance, then index
        out[start:start + chunk] = np.take_along_axis(part, order, axis=1)
    if kk < k:
        out = np.concatenate([out, np.repeat(out[:, -1:], k - kk, axis=1)], axis=1)
    return out


def farthest_point_sampling(xyz: np.ndarray, n_out: int, start: int = 0) -> np.ndarray:
    """Deterministic farthest point sampling: (n_out,) int64 indices into ``xyz`` (N, 3)."""
    check_shape(xyz, (None, None), "xyz", dtypes=_FLOAT)
    n = len(xyz)
    if not 1 <= n_out <= n:
        raise ValueError(f"n_out must be in [1, {n}], got {n_out}")
    cols = [np.ascontiguousarray(xyz[:, j], dtype=np.float64) for j in range(xyz.shape[1])]
    idx = np.empty(n_out, dtype=np.int64)
    idx[0] = start
    dist = np.full(n, np.inf)
    d2, tmp = np.empty(n), np.empty(n)
    for i in range(1, n_out):
        # squared distance to the last chosen point, summed per axis in place (no temporaries)
        last = idx[i - 1]
        np.subtract(cols[0], cols[0][last], out=d2)
        np.multiply(d2, d2, out=d2)
        for col in cols[1:]:
            np.subtract(col, col[last], out=tmp)
            np.multiply(tmp, tmp, out=tmp)
            np.add(d2, tmp, out=d2)
        np.minimum(dist, d2, out=dist)
        idx[i] = int(np.argmax(dist))
    return idx


def random_subsampling(n: int, n_out: int, seed: int) -> np.ndarray:
    """Seeded random subset (n_out,) int64 of range(n), sorted (RandLA-Net style)."""
    if not 1 <= n_out <= n:
        raise ValueError(f"n_out must be in [1, {n}], got {n_out}")
    return np.sort(np.random.default_rng(seed).choice(n, size=n_out, replace=False)).astype(np.int64)


def build_point_indices(xyz: np.ndarray, spec: PoseInputSpec) -> dict[str, list[np.ndarray]]:
    """Neighbour / subsampling / upsampling indices of every point-net level (no batch axis).

    Returns ``{"nbr": [(N_l, K)], "sub": [(N_{l+1},)], "up": [(N_l,)], "level_ids": [(N_l,)]}``
    where ``level_ids[l]`` maps level-l points back to rows of ``xyz`` (level_ids[0] = arange).
    """
    check_shape(xyz, (spec.n_points, 3), "xyz", dtypes=_FLOAT)
    check_finite(xyz, "xyz")
    sizes = spec.level_sizes
    level_xyz = xyz.astype(np.float64)
    level_ids = np.arange(len(xyz), dtype=np.int64)
    out: dict[str, list[np.ndarray]] = {"nbr": [], "sub": [], "up": [], "level_ids": [level_ids]}
    for level in range(spec.n_levels):
        out["nbr"].append(knn_indices(level_xyz, level_xyz, spec.k))
        if spec.sampling == "fps":
            sub = farthest_point_sampling(level_xyz, sizes[level + 1])
        else:
            sub = random_subsampling(len(level_xyz), sizes[level + 1], spec.seed + level)
        next_xyz = level_xyz[sub]
        out["sub"].append(sub)
        out["up"].append(knn_indices(level_xyz, next_xyz, 1)[:, 0])
        level_xyz = next_xyz
        level_ids = level_ids[sub]
        out["level_ids"].append(level_ids)
    return out


def choose_from_pixels(pixels: np.ndarray, crop_size: tuple[int, int]) -> np.ndarray:
    """(N,) int64 flat index ``v * W + u`` of integer crop pixels (N, 2) given as (u=x, v=y)."""
    check_shape(pixels, (None, 2), "pixels", dtypes=_INT)
    w, h = crop_size
    u, v = pixels[:, 0].astype(np.int64), pixels[:, 1].astype(np.int64)
    if np.any((u < 0) | (u >= w) | (v < 0) | (v >= h)):
        raise ShapeError(f"pixels must lie inside the {w}x{h} crop")
    return v * w + u


def pix2pt_indices(pixels: np.ndarray, crop_size: tuple[int, int], stride: int, chunk: int = 512) -> np.ndarray:
    """(Hf*Wf,) int64: for each pixel of the stride-``stride`` feature map, the nearest point in the image.

    ``pixels`` (N, 2) are the crop coordinates (u, v) of the points of one level; feature-map pixel
    (i, j) sits at crop coordinate ((j + 0.5) * stride - 0.5, (i + 0.5) * stride - 0.5). Ties go to
    the lower point index.
    """
    check_shape(pixels, (None, 2), "pixels", dtypes=_INT + _FLOAT)
    w, h = crop_size
    if w % stride or h % stride:
        raise ValueError(f"crop_size {crop_size} not divisible by stride {stride}")
    wf, hf = w // stride, h // stride
    jj, ii = np.meshgrid(np.arange(wf), np.arange(hf))
    centres = np.stack([(jj.ravel() + 0.5) * stride - 0.5, (ii.ravel() + 0.5) * stride - 0.5], axis=1)
    return knn_indices(centres, pixels.astype(np.float64), 1, chunk=chunk)[:, 0]


def estimate_normals(xyz: np.ndarray, nbr: np.ndarray) -> np.ndarray:
    """Unit normals (N, 3) float32 by PCA of each point's neighbours, oriented towards the camera."""
    pts = xyz.astype(np.float64)
    nb = pts[nbr]  # (N, K, 3)
    centred = nb - nb.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", centred, centred)
    _, vecs = np.linalg.eigh(cov)
    normals = vecs[:, :, 0]
    flip = np.einsum("ni,ni->n", normals, pts) > 0  # camera at the origin: n . (0 - p) >= 0
    normals[flip] *= -1.0
    return normals.astype(np.float32)


def build_pose_inputs(rgb_crop: np.ndarray, xyz: np.ndarray, pixels: np.ndarray,
                      spec: PoseInputSpec) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """All graph inputs for one sample (batch axis 1) and the xyz mean that was subtracted.

    Args:
        rgb_crop: (Hc, Wc, 3) uint8 RGB crop, Hc, Wc = spec.crop_size[::-1].
        xyz: (N, 3) camera-frame points in metres, N = spec.n_points (already sampled).
        pixels: (N, 2) integer (u, v) pixel of each point in the crop.
    Returns:
        (inputs keyed by :func:`pose_input_names`, xyz_mean (3,) float64).
    """
    w, h = spec.crop_size
    check_shape(rgb_crop, (h, w, 3), "rgb_crop", dtypes=(np.unsignedinteger,))
    if rgb_crop.dtype != np.uint8:
        raise ShapeError(f"rgb_crop must be uint8, got {rgb_crop.dtype}")
    check_shape(xyz, (spec.n_points, 3), "xyz", dtypes=_FLOAT)
    check_finite(xyz, "xyz")
    check_shape(pixels, (spec.n_points, 2), "pixels", dtypes=_INT)
    choose = choose_from_pixels(pixels, spec.crop_size)
    idx = build_point_indices(xyz, spec)
    xyz_mean = xyz.astype(np.float64).mean(axis=0)
    colours = rgb_crop.reshape(-1, 3)[choose].astype(np.float32) / 255.0
    feats = [((xyz - xyz_mean) / spec.xyz_scale).astype(np.float32), colours]
    if spec.use_normals:
        feats.append(estimate_normals(xyz, idx["nbr"][0]))
    inputs = {
        "rgb": np.ascontiguousarray(rgb_crop.transpose(2, 0, 1)[None], dtype=np.float32),
        "points": np.concatenate(feats, axis=1)[None],
        "choose": choose[None],
    }
    for level in range(spec.n_levels):
        inputs[f"nbr_{level}"] = idx["nbr"][level][None]
        inputs[f"sub_{level}"] = idx["sub"][level][None]
        inputs[f"up_{level}"] = idx["up"][level][None]
        level_pixels = pixels[idx["level_ids"][level]]
        inputs[f"pix2pt_{level}"] = pix2pt_indices(level_pixels, spec.crop_size, spec.fusion_strides[level])[None]
    return {name: inputs[name] for name in pose_input_names(spec.n_levels)}, xyz_mean
