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

import cv2
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


#: extra float32 candidates per row that are re-ranked in float64 (see :func:`knn_indices`)
_KNN_MARGIN = 4
#: float32 squared distances of a query point q closer than this times (2 |q| + distance)**2 (centred
#: coordinates) may be misordered, and such rows are searched again in float64. The float32 error of
#: ``|q|^2 + |r|^2 - 2 q.r`` with |r| <= |q| + distance is below about 4 eps (2 |q| + distance)**2.
_KNN_TOL = 8 * float(np.finfo(np.float32).eps)


def _squared_distances32(query: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """(M, N) float32 squared distances ``|q|^2 + |r|^2 - 2 q.r`` (one matrix product; inputs centred)."""
    d2 = query @ (-2.0 * ref.T)
    d2 += np.einsum("ij,ij->i", query, query)[:, None]
    d2 += np.einsum("ij,ij->i", ref, ref)[None, :]
    return d2


def _tolerance(q_norm: np.ndarray, d2: np.ndarray) -> np.ndarray:
    """Per-row float32 error bound of squared distances up to ``d2`` from points of norm ``q_norm``."""
    return (_KNN_TOL * (2.0 * q_norm + np.sqrt(np.maximum(d2, 0.0))) ** 2).astype(np.float32)


def _rank_exact(q: np.ndarray, r: np.ndarray, cand: np.ndarray, kk: int) -> np.ndarray:
    """The ``kk`` of candidate indices ``cand`` (M, C) nearest to ``q`` (M, D) in float64, ties by index."""
    diff = r[cand] - q[:, None, :]
    exact = np.einsum("mcd,mcd->mc", diff, diff)
    order = np.lexsort((cand, exact), axis=1)[:, :kk]  # by distance, then index
    return np.take_along_axis(cand, order, axis=1)


def _search64(q: np.ndarray, r: np.ndarray, kk: int) -> np.ndarray:
    """(M, kk) nearest ``r`` rows of each ``q`` row from float64 distances to all of ``r``."""
    diff = r[None, :, :] - q[:, None, :]
    d2 = np.einsum("mnd,mnd->mn", diff, diff)
    if kk == 1:
        return np.argmin(d2, axis=1)[:, None]  # first minimum: the lowest index
    part = np.argpartition(d2, kk - 1, axis=1)[:, :kk] if kk < len(r) else np.broadcast_to(
        np.arange(len(r)), d2.shape)
    order = np.lexsort((part, np.take_along_axis(d2, part, axis=1)), axis=1)
    return np.take_along_axis(part, order, axis=1)


def _nearest32(query32: np.ndarray, ref32: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``n`` nearest ``ref32`` rows of each ``query32`` row by float32 squared distance, nearest
    first: ``(distances (M, n) float32, indices (M, n) int64)`` (OpenCV's brute-force
    ``batchDistance``, sums of squared differences: within the bound of :data:`_KNN_TOL`)."""
    d2, idx = cv2.batchDistance(query32, ref32, cv2.CV_32F, normType=cv2.NORM_L2SQR, K=n)
    return d2, idx.astype(np.int64)


def knn_indices(query: np.ndarray, ref: np.ndarray, k: int, chunk: int = 1024) -> np.ndarray:
    """Indices (M, k) int64 of the k nearest ``ref`` points of each ``query`` point, nearest first.

    Brute force, ``chunk`` query rows at a time, giving the answer of a float64 search with ties
    broken by the lower index. Candidates come from float32 distances of coordinates centred on
    ``ref``'s mean (``k + 4`` per row, and the nearest point after them: OpenCV's ``batchDistance``
    for finite points of at most 4 coordinates, else one float32 matrix product and a partition) and
    are ranked in float64; a row whose float32 distances cannot tell its k-th neighbour from the first
    excluded point is searched again in float64 over all of ``ref``. Exactly tied points at the k-th
    place (duplicates) are interchangeable: which one is kept is deterministic but not necessarily the
    lowest index. If ``ref`` has fewer than ``k`` points, the farthest found neighbour is repeated to
    fill the row.
    """
    check_shape(query, (None, None), "query", dtypes=_FLOAT)
    check_shape(ref, (None, query.shape[1]), "ref", dtypes=_FLOAT)
    if len(ref) == 0:
        raise ShapeError("ref must hold at least one point")
    if k < 1:
        raise ValueError(f"k must be >= 1, got {k}")
    centre = np.asarray(ref, dtype=np.float64).mean(axis=0)
    q = np.asarray(query, dtype=np.float64) - centre
    r = np.asarray(ref, dtype=np.float64) - centre
    q32, r32 = q.astype(np.float32), r.astype(np.float32)
    q_norm = np.sqrt(np.einsum("ij,ij->i", q, q))
    kk = min(k, len(r))
    n_cand = min(kk + _KNN_MARGIN, len(r))
    # OpenCV's search reads float32 rows of up to 4 coordinates here (and nothing non-finite: its order
    # of NaN distances is its own); the matrix product and partition cover the rest
    opencv = q.shape[1] <= 4 and bool(np.isfinite(q32).all() and np.isfinite(r32).all())
    out = np.empty((len(q), kk), dtype=np.int64)
    for start in range(0, len(q), chunk):
        stop = min(start + chunk, len(q))
        qc = q[start:stop]
        if n_cand == len(r):  # few points: rank them all
            out[start:stop] = _rank_exact(qc, r, np.broadcast_to(np.arange(len(r)), (stop - start, len(r))), kk)
            continue
        q_tol = q_norm[start:stop]
        if opencv:
            near, near_i = _nearest32(q32[start:stop], r32, n_cand + 1)   # sorted: candidates, then the next
            if kk == 1:  # the nearest is found unless the second is as near within the float32 error
                found = near_i[:, :1]
                redo = np.flatnonzero(near[:, 1] <= near[:, 0] + _tolerance(q_tol, near[:, 0]))
            else:
                found = _rank_exact(qc, r, near_i[:, :n_cand], kk)
                redo = np.flatnonzero(near[:, n_cand] - near[:, kk - 1] <= _tolerance(q_tol, near[:, n_cand]))
        else:
            d2 = _squared_distances32(q32[start:stop], r32)
            rows = np.arange(len(d2))
            if kk == 1:  # argmin: first minimum = lowest index; re-check rows with a near tie
                found = np.argmin(d2, axis=1)[:, None]
                best = d2[rows, found[:, 0]]
                redo = np.flatnonzero(np.count_nonzero(d2 <= (best + _tolerance(q_tol, best))[:, None], axis=1) > 1)
            else:
                part = np.argpartition(d2, n_cand, axis=1)  # [:n_cand] candidates, [n_cand] the nearest other
                cand = part[:, :n_cand]
                kth = np.partition(np.take_along_axis(d2, cand, axis=1), kk - 1, axis=1)[:, kk - 1]
                other = d2[rows, part[:, n_cand]]
                found = _rank_exact(qc, r, cand, kk)
                redo = np.flatnonzero(other - kth <= _tolerance(q_tol, other))
        if redo.size:
            found = found.copy()
            found[redo] = _search64(qc[redo], r, kk)
        out[start:stop] = found
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


def pix2pt_indices(pixels: np.ndarray, crop_size: tuple[int, int], stride: int, chunk: int = 1024) -> np.ndarray:
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
    if max(w, h) > 512 or np.any(np.abs(pixels) > 512) or np.any(pixels != np.round(pixels)):
        return knn_indices(centres, pixels.astype(np.float64), 1, chunk=chunk)[:, 0]
    # integer pixels and centres on a quarter-pixel grid, all within 512 px: the float32 squared
    # distances (< 2**21, multiples of 1/16) are exact, and argmin's first minimum is the lowest
    # index, so this is the float64 search's answer
    out = np.empty(len(centres), dtype=np.int64)
    ref = pixels.astype(np.float32)
    for start in range(0, len(centres), chunk):
        out[start:start + chunk] = np.argmin(_squared_distances32(centres[start:start + chunk].astype(np.float32), ref),
                                             axis=1)
    return out


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
