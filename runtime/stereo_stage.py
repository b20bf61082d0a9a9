"""The stereo stage of the flight pipeline: TSCA-Stereo ONNX graph, coarse pass -> ROI -> fine pass.

Per frame (the stereo pipeline design of the project contract):

1. *coarse pass* — the whole rectified frame letterboxed into the graph's fixed input size (or, for a
   rig whose disparities would be too small there, into ``n`` times that size and matched as ``n x n``
   overlapping tiles of the graph's size: ``coarse_tiles``); target
   pixels are those above ``coarse_threshold`` net pixels of disparity (Earth and stars sit at ~0);
   their box and disparity range give the ROI. Pixels that the images themselves place at infinity
   (they match better unshifted than at the predicted disparity: :mod:`spacepose.infinity`) are
   not target, however much disparity the graph gave them. A caller that already knows where the target is
   (e.g. from the previous pose) passes a :class:`RoiHint` and the coarse pass is skipped.
2. *fine pass* — one square window, the same pixel window in left and right and zero padded beyond
   the image, that holds the target in the left image and its copy shifted by ``-d`` in the right
   image, resized to the graph input; ``disparity_full = disparity_crop / s``.

The result is a full-resolution float32 disparity of the left rectified image, 0 where unknown
(outside the window).
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from . import roi
from .errors import BundleError, ShapeError
from .infinity import infinity_regions
from .onnx_session import make_session, session_metadata

log = logging.getLogger(__name__)

__all__ = ["RoiHint", "StereoResult", "StereoMatcher", "validate_stereo_metadata", "to_net_input"]

#: ``infer(left, right)`` with (1, 3, h, w) float32 inputs in [0, 255] -> (h, w) float32 disparity
InferFn = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class RoiHint:
    """Where the target is expected: left-image box (full-frame pixels) and disparity range."""

    bbox: tuple[int, int, int, int]
    d_min: float
    d_max: float


@dataclass
class StereoResult:
    """Disparity of one frame.

    Attributes:
        disparity: (H, W) float32 full-resolution disparity of the left rectified image, 0 where unknown.
        window: the fine-pass window (full-frame pixels), ``None`` when no target was found.
        scale: disparity scale of the pass that produced ``disparity`` (net px per full-frame px).
        coarse_bbox: target box found by the coarse pass (``None`` if skipped or nothing found).
        status: ``"fine"`` (ROI pass ran) or ``"no_target"`` (only the coarse disparity is returned).
        timings_ms: per-step wall time (``net_ms``: the graph calls alone, both passes).
    """

    disparity: np.ndarray
    window: roi.Window | None
    scale: float
    coarse_bbox: tuple[int, int, int, int] | None
    status: str = "fine"
    timings_ms: dict[str, float] = field(default_factory=dict)


def validate_stereo_metadata(meta: dict[str, Any], input_shapes: dict[str, list] | None = None) -> tuple[tuple[int, int], int, float]:
    """Check the stereo graph contract -> ((width, height), iters, max_disp). Raises BundleError."""
    if meta.get("kind") != "stereo":
        raise BundleError(f"graph metadata kind must be 'stereo', got {meta.get('kind')!r}")
    try:
        w, h = (int(v) for v in meta["input_size"])
        iters = int(meta["iters"])
        max_disp = float(meta.get("max_disp", 192))
    except (KeyError, TypeError, ValueError) as err:
        raise BundleError(f"stereo graph metadata lacks a valid input_size/iters: {err}") from err
    if w < 8 or h < 8 or iters < 1 or max_disp <= 0:
        raise BundleError(f"stereo graph metadata out of range: input_size={w}x{h}, iters={iters}, max_disp={max_disp}")
    if input_shapes is not None:
        for name in ("left", "right"):
            if name not in input_shapes:
                raise BundleError(f"stereo graph has no input {name!r} (inputs: {sorted(input_shapes)})")
            shape = input_shapes[name]
            if len(shape) != 4 or list(shape[1:]) != [3, h, w]:
                raise BundleError(f"stereo graph input {name!r} has shape {shape}, metadata says (1, 3, {h}, {w})")
    return (w, h), iters, max_disp


def to_net_input(image: np.ndarray) -> np.ndarray:
    """(H, W[, 3]) uint8/uint16/float RGB or grey -> (1, 3, H, W) float32 in [0, 255] (grey replicated)."""
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[..., 0]
    if image.dtype == np.uint16:
        x = image.astype(np.float32) * (255.0 / 65535.0)
    else:
        x = image.astype(np.float32, copy=False)
    if x.ndim == 2:
        x = np.repeat(x[None], 3, axis=0)
    else:
        x = np.ascontiguousarray(x.transpose(2, 0, 1))
    return x[None]


def _check_pair(left: object, right: object) -> tuple[np.ndarray, np.ndarray]:
    for name, img in (("left", left), ("right", right)):
        if not isinstance(img, np.ndarray):
            raise ShapeError(f"{name} must be a numpy array, got {type(img).__name__}")
        if img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] not in (1, 3)):
            raise ShapeError(f"{name} must be (H, W), (H, W, 1) or (H, W, 3), got {img.shape}")
        if not (img.dtype in (np.uint8, np.uint16) or np.issubdtype(img.dtype, np.floating)):
            raise ShapeError(f"{name} must be uint8, uint16 or float, got {img.dtype}")
        if img.shape[0] < 8 or img.shape[1] < 8:
            raise ShapeError(f"{name} is too small: {img.shape}")
    if left.shape != right.shape:
        raise ShapeError(f"left and right must have the same shape, got {left.shape} and {right.shape}")
    return left, right


class StereoMatcher:
    """Coarse letterboxed pass -> square ROI -> fine pass with a fixed-size stereo ONNX graph.

    Args:
        onnx_path: the stereo graph (its metadata must follow the contract; see
            :func:`validate_stereo_metadata`).
        threads: onnxruntime intra-op threads.
        coarse_threshold: disparity (net pixels of the coarse view) above which a pixel is target.
        margin: window side = margin * longest side of the target box ∪ its right-image copy.
        min_side: smallest window side in full-frame pixels.
        coarse_tiles: ``n`` >= 1. The coarse pass letterboxes the frame into a view ``n`` graph inputs
            wide less ``(n - 1) * tile_overlap`` and runs the graph on its ``n x n`` tiles, so disparities
            are ``n`` times larger there than in one letterboxed input (a short baseline, a small focal
            length: :meth:`~spacepose.bundle.ModelBundle.coarse_tiles_for`), at ``n**2`` graph runs.
            A tile's first ``tile_overlap`` columns, whose right-image matches lie left of it, are taken
            from its left neighbour; rows are split in the middle of the overlap. 1: one letterboxed run.
        tile_overlap: overlap of neighbouring coarse tiles in graph pixels (``coarse_tiles`` > 1).
        mem_arena: onnxruntime's CPU memory arena. On (the default since session 12): the graph's
            fixed input size makes the arena's blocks reusable from call to call; without it
            onnxruntime allocates and frees every intermediate tensor on every call. Session 12,
            ``spacepose profile`` at 1280x960 on 2 threads, the same frames: stereo stage p50 329 / 302
            ms without, 186 / 204 ms with it, peak RSS 349 / 351 -> 388 / 394 MiB
            (``reports/profile1280_s12_*.json``), results bit-identical.
        infinity_check: drop coarse-pass pixels that match better at zero disparity (:mod:`spacepose.infinity`).
        spinning: onnxruntime workers spin between the graph's operators instead of sleeping. The
            stereo graph has about 2,000 small nodes, and waking a sleeping worker for each costs more
            than it saves (session 5, ``spacepose profile`` at 1280x960 on 2 threads: stereo stage p50
            511 ms with spinning, 645 ms without). The workers stop spinning as soon as ``run()``
            returns (``session.force_spinning_stop``), so they do not slow the numpy stage after the
            graph. Session 6, same command, two runs each: with the stop, ``pose_inputs`` p50 29 / 31 ms
            and 10.2 / 10.1 % of the time outside the graphs; without it, 41 / 43 ms and 12.0 / 11.3 %
            (``reports/profile1280_s6_*.json``). The pose session keeps its workers sleeping.
    """

    def __init__(self, onnx_path: str | os.PathLike, threads: int = 2, *, coarse_threshold: float = 2.0,
                 margin: float = 1.25, min_side: int = 32, mem_arena: bool = True, infinity_check: bool = True,
                 spinning: bool = True, coarse_tiles: int = 1, tile_overlap: int = roi.COARSE_TILE_OVERLAP_PX) -> None:
        session = make_session(onnx_path, threads=threads, mem_arena=mem_arena, spinning=spinning)
        meta = session_metadata(session)
        shapes = {i.name: list(i.shape) for i in session.get_inputs()}
        outputs = [o.name for o in session.get_outputs()]
        if "disparity" not in outputs:
            raise BundleError(f"stereo graph has no output 'disparity' (outputs: {outputs})")
        size, iters, max_disp = validate_stereo_metadata(meta, shapes)

        def infer(left: np.ndarray, right: np.ndarray) -> np.ndarray:
            (out,) = session.run(["disparity"], {"left": left, "right": right})
            return out[0, 0]

        self._setup(infer, size, iters, max_disp, meta, coarse_threshold, margin, min_side, infinity_check,
                    coarse_tiles, tile_overlap)
        self.session = session
        self.path = str(onnx_path)

    @classmethod
    def from_callable(cls, infer: InferFn, input_size: tuple[int, int], *, iters: int, max_disp: float = 192.0,
                      metadata: dict[str, Any] | None = None, coarse_threshold: float = 2.0, margin: float = 1.25,
                      min_side: int = 32, infinity_check: bool = True, coarse_tiles: int = 1,
                      tile_overlap: int = roi.COARSE_TILE_OVERLAP_PX) -> "StereoMatcher":
        """A matcher around any ``infer(left, right) -> (h, w)`` (e.g. a torch model for benchmarks)."""
        self = cls.__new__(cls)
        meta = dict(metadata or {"kind": "stereo", "input_size": list(input_size), "iters": iters, "max_disp": max_disp})
        self._setup(infer, (int(input_size[0]), int(input_size[1])), int(iters), float(max_disp), meta,
                    coarse_threshold, margin, min_side, infinity_check, coarse_tiles, tile_overlap)
        self.session = None
        self.path = None
        return self

    def _setup(self, infer: InferFn, size: tuple[int, int], iters: int, max_disp: float, meta: dict[str, Any],
               coarse_threshold: float, margin: float, min_side: int, infinity_check: bool = True,
               coarse_tiles: int = 1, tile_overlap: int = roi.COARSE_TILE_OVERLAP_PX) -> None:
        if margin < 1.0:
            raise ValueError(f"margin must be >= 1, got {margin}")
        if int(coarse_tiles) != coarse_tiles or coarse_tiles < 1:
            raise ValueError(f"coarse_tiles must be an integer >= 1, got {coarse_tiles}")
        if coarse_tiles > 1 and not 0 <= tile_overlap < min(size) // 2:
            raise ValueError(f"tile_overlap must be in [0, {min(size) // 2}), got {tile_overlap}")
        self.coarse_tiles = int(coarse_tiles)
        self.tile_overlap = int(tile_overlap) if coarse_tiles > 1 else 0
        self._infer = infer
        self.input_size = size
        self.iters = iters
        self.max_disp = max_disp
        self.metadata = meta
        self.coarse_threshold = float(coarse_threshold)
        self.margin = float(margin)
        self.infinity_check = bool(infinity_check)
        self.min_side = int(min_side)

    # ---------------------------------------------------------------- passes
    def _run(self, left_view: np.ndarray, right_view: np.ndarray, timings: dict[str, float] | None = None) -> np.ndarray:
        left_in, right_in = to_net_input(left_view), to_net_input(right_view)
        t0 = time.perf_counter()
        out = self._infer(left_in, right_in)
        if timings is not None:  # graph time alone, for the network / non-network split of a profile
            timings["net_ms"] = timings.get("net_ms", 0.0) + (time.perf_counter() - t0) * 1e3
        return np.asarray(out, dtype=np.float32).reshape(self.input_size[1], self.input_size[0])

    def coarse(self, left: np.ndarray, right: np.ndarray, timings: dict[str, float] | None = None
               ) -> tuple[np.ndarray, roi.CropTransform]:
        """Letterboxed pass -> (view disparity with padding zeroed, transform); the view is the graph's
        input size, or the tiled view of ``coarse_tiles`` (class docstring)."""
        view_size = self.coarse_view_size
        lv, t = roi.letterbox(left, view_size)
        rv, _ = roi.letterbox(right, view_size)
        disp = self._run(lv, rv, timings) if self.coarse_tiles == 1 else self._run_tiled(lv, rv, timings)
        # zero the letterbox padding so it can never become "target"
        h, w = left.shape[:2]
        (u0, v0), (u1, v1) = t.to_net(np.array([[-0.5, -0.5], [w - 0.5, h - 0.5]]))
        inside = np.zeros_like(disp, dtype=bool)
        inside[max(0, int(np.ceil(v0))):int(np.floor(v1)) + 1, max(0, int(np.ceil(u0))):int(np.floor(u1)) + 1] = True
        disp = np.where(inside, disp, 0.0).astype(np.float32)
        if self.infinity_check:
            disp[infinity_regions(lv, rv, disp, min_disparity=self.coarse_threshold)] = 0.0
        return disp, t

    @property
    def coarse_view_size(self) -> tuple[int, int]:
        """(width, height) of the coarse pass's view: ``n`` graph inputs less ``n - 1`` overlaps."""
        n, o = self.coarse_tiles, self.tile_overlap
        return (n * self.input_size[0] - (n - 1) * o, n * self.input_size[1] - (n - 1) * o)

    def _run_tiled(self, left_view: np.ndarray, right_view: np.ndarray, timings: dict[str, float] | None
                   ) -> np.ndarray:
        """Disparity of the whole coarse view from its ``n x n`` overlapping tiles (class docstring)."""
        n, o = self.coarse_tiles, self.tile_overlap
        w_in, h_in = self.input_size
        vw, vh = self.coarse_view_size
        disp = np.zeros((vh, vw), dtype=np.float32)
        for j in range(n):
            y0 = j * (h_in - o)
            r0 = 0 if j == 0 else o // 2                 # rows: the seam in the middle of the overlap
            r1 = h_in if j == n - 1 else h_in - (o - o // 2)
            for i in range(n):
                x0 = i * (w_in - o)
                c0 = 0 if i == 0 else o                  # columns: the left neighbour's where they overlap
                tile = self._run(left_view[y0:y0 + h_in, x0:x0 + w_in], right_view[y0:y0 + h_in, x0:x0 + w_in],
                                 timings)
                disp[y0 + r0:y0 + r1, x0 + c0:x0 + w_in] = tile[r0:r1, c0:]
        return disp

    def roi_from_coarse(self, coarse_disp: np.ndarray, t: roi.CropTransform, image_size: tuple[int, int]) -> RoiHint | None:
        """Target box and disparity range (full-frame) from a coarse disparity, or None."""
        bbox_net = roi.bbox_from_disparity(coarse_disp, self.coarse_threshold)
        if bbox_net is None:
            return None
        x0, y0, x1, y1 = bbox_net
        region = np.zeros(coarse_disp.shape, dtype=bool)
        region[y0:y1, x0:x1] = True
        rng = roi.disparity_range(coarse_disp, region, self.coarse_threshold)
        if rng is None:
            return None
        bbox = t.net_bbox_to_full(bbox_net, image_size)
        if bbox[2] <= bbox[0] or bbox[3] <= bbox[1]:
            return None
        lo, hi = rng[0] / t.scale, rng[1] / t.scale
        # slack for the coarse pass's low resolution
        return RoiHint(bbox, max(0.0, 0.8 * lo - 1.0 / t.scale), 1.2 * hi + 1.0 / t.scale)

    def window_for(self, hint: RoiHint) -> roi.Window:
        return roi.square_window(hint.bbox, hint.d_min, hint.d_max, self.margin, min_side=self.min_side,
                                 out_side=self.input_size[0], max_disp=self.max_disp)

    def match(self, left_rect: np.ndarray, right_rect: np.ndarray, roi_hint: RoiHint | None = None) -> StereoResult:
        """Disparity of the left rectified image (full resolution, 0 where unknown)."""
        t_start = time.perf_counter()
        left, right = _check_pair(left_rect, right_rect)
        h, w = left.shape[:2]
        timings: dict[str, float] = {}
        coarse_bbox = None
        hint = roi_hint
        if hint is None:
            t0 = time.perf_counter()
            coarse_disp, ct = self.coarse(left, right, timings)
            timings["coarse_ms"] = (time.perf_counter() - t0) * 1e3
            hint = self.roi_from_coarse(coarse_disp, ct, (w, h))
            if hint is None:
                disp = roi.warp_to_full(coarse_disp, ct, (w, h)) / ct.scale
                disp = np.maximum(disp, 0.0).astype(np.float32)
                timings["total_ms"] = (time.perf_counter() - t_start) * 1e3
                return StereoResult(disp, None, ct.scale, None, "no_target", timings)
            coarse_bbox = hint.bbox
        t0 = time.perf_counter()
        window = self.window_for(hint)
        lv, ft = roi.crop_resize(left, window, self.input_size)
        rv, _ = roi.crop_resize(right, window, self.input_size)
        timings["crop_ms"] = (time.perf_counter() - t0) * 1e3
        t0 = time.perf_counter()
        fine = self._run(lv, rv, timings)
        timings["fine_ms"] = (time.perf_counter() - t0) * 1e3
        t0 = time.perf_counter()
        disp = roi.warp_to_full(fine, ft, (w, h))  # float32, a new array: scaled in place
        np.divide(disp, np.float32(ft.scale), out=disp)
        np.maximum(disp, np.float32(0.0), out=disp)
        timings["uncrop_ms"] = (time.perf_counter() - t0) * 1e3
        timings["total_ms"] = (time.perf_counter() - t_start) * 1e3
        return StereoResult(disp, window, ft.scale, coarse_bbox, "fine", timings)
