"""Export TSCA-Stereo to one self-describing ONNX file with a fixed input size and iteration count.

* legacy TorchScript exporter (``dynamo=False``), opset 17, a single file (no external data);
* the iteration loop is unrolled, so the iteration count is frozen into the graph;
* the graph must contain no ``GridSample`` and no ``ScatterND`` (slow or unsupported on small
  runtimes) — export fails otherwise;
* Conv3d layers wider than 1x1x1 with at least 8 outputs are exported in the exact 2-D form of
  :mod:`spacepose.export.conv3d_as_2d` (``rewrite_convs``, default on; onnxruntime runs depthwise ones
  several times faster, dense ones 1.2-1.6x), recorded as ``metadata["export"]["conv3d_as_2d"]``; the
  ConvTranspose3d upsamplers likewise (``rewrite_transposed``, default on; about 2x faster in
  onnxruntime), recorded as ``metadata["export"]["conv_transpose3d_as_2d"]``; and the narrow
  classifier as one 2-D convolution with its depth taps stacked (``rewrite_narrow``, default on),
  recorded as ``metadata["export"]["narrow_conv3d_as_2d"]``; and the dense 3x3x3 ones with depth stride 1
  with Winograd F(4, 3) along depth (``rewrite_winograd``, default on; 6 instead of 12 2-D
  convolutions per 4 output slices), recorded as ``metadata["export"]["conv3d_depth_winograd"]``; and the
  ConvTranspose3d upsamplers instead as one 2-D convolution over windows of depth slices plus a pixel
  shuffle (``rewrite_polyphase``, default on; 2.4-3x faster than the per-tap form), recorded as
  ``metadata["export"]["conv_transpose3d_polyphase"]``;
* the metadata contract (:mod:`spacepose.export.metadata`) is stored under ``"spacepose"``;
* parity: torch eager vs onnxruntime on a textured stereo pair, max |Δ| in pixels.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import torch
from torch import nn

from spacepose.errors import SpaceposeError
from spacepose.export.conv3d_as_2d import rewrite_conv3d
from spacepose.export.metadata import stereo_metadata
from spacepose.export.onnx_common import (FORBIDDEN_OPS, OPSET, check_overwrite, enforce_parity, export_onnx_file,
                                          forbidden_ops, max_abs_diff, merge_manifest_section, update_manifest)
from spacepose.models.stereo_config import StereoConfig
from spacepose.onnx_session import make_session

log = logging.getLogger(__name__)

__all__ = ["FORBIDDEN_OPS", "StereoExportWrapper", "export_stereo", "forbidden_ops", "parity_check",
           "parity_inputs", "export_checkpoint", "export_random_stereo"]


class StereoExportWrapper(nn.Module):
    """``(left, right) -> disparity`` with the iteration count fixed (test mode)."""

    def __init__(self, model: nn.Module, iters: int) -> None:
        super().__init__()
        self.model = model
        self.iters = int(iters)

    def forward(self, left: torch.Tensor, right: torch.Tensor) -> torch.Tensor:
        return self.model(left, right, iters=self.iters, test_mode=True)


def parity_inputs(size: tuple[int, int], seed: int = 0, disparity: float = 12.0) -> tuple[np.ndarray, np.ndarray]:
    """A textured (1, 3, H, W) float32 pair in [0, 255]: right = left shifted by ``disparity`` px."""
    w, h = size
    rng = np.random.default_rng(seed)
    pad = int(np.ceil(disparity)) + 2
    tex = rng.uniform(0, 255, size=(h // 4 + 1, (w + pad) // 4 + 1, 3)).astype(np.float32)
    import cv2

    tex = cv2.resize(tex, ((w + pad), h), interpolation=cv2.INTER_CUBIC)
    left = tex[:, :w]
    shift = int(round(disparity))
    right = tex[:, shift:shift + w]
    to = lambda a: np.ascontiguousarray(np.clip(a, 0, 255).transpose(2, 0, 1)[None], dtype=np.float32)  # noqa: E731
    return to(left), to(right)


def export_stereo(model: nn.Module, path: str | os.PathLike, *, size: tuple[int, int], iters: int,
                  metadata: Mapping[str, Any], force: bool = False, opset: int = OPSET,
                  rewrite_convs: bool = True, rewrite_transposed: bool | None = None,
                  rewrite_narrow: bool | None = None, rewrite_winograd: bool | None = None,
                  rewrite_polyphase: bool | None = None) -> Path:
    """Export ``model`` at ``size`` (W, H) and ``iters`` into one ONNX file carrying ``metadata``
    (plus ``metadata["export"]`` ``"conv3d_as_2d" = rewrite_convs``, ``"conv_transpose3d_as_2d" =
    rewrite_transposed``, ``"narrow_conv3d_as_2d" = rewrite_narrow``, ``"conv3d_depth_winograd" =
    rewrite_winograd`` and ``"conv_transpose3d_polyphase" = rewrite_polyphase``, the middle three defaulting
    to ``rewrite_convs`` and the last to ``rewrite_transposed``: the polyphase form, where it applies, takes
    the place of the per-tap form of the transposed convolutions; ``model`` itself is not changed).

    Raises:
        SpaceposeError: ``path`` exists and ``force`` is False, or the graph holds a forbidden op.
    """
    out = check_overwrite(path, force)
    w, h = (int(v) for v in size)
    if w % 32 or h % 32:
        raise SpaceposeError(f"export size must be multiples of 32, got {w}x{h}")
    model = model.eval()
    flags = {"conv3d_as_2d": bool(rewrite_convs),
             "conv_transpose3d_as_2d": bool(rewrite_convs if rewrite_transposed is None else rewrite_transposed),
             "narrow_conv3d_as_2d": bool(rewrite_convs if rewrite_narrow is None else rewrite_narrow),
             "conv3d_depth_winograd": bool(rewrite_convs if rewrite_winograd is None else rewrite_winograd),
             "conv_transpose3d_polyphase": None}
    flags["conv_transpose3d_polyphase"] = bool(flags["conv_transpose3d_as_2d"] if rewrite_polyphase is None
                                               else rewrite_polyphase)
    rewritten = (rewrite_conv3d(model, convs=flags["conv3d_as_2d"], transposed=flags["conv_transpose3d_as_2d"],
                                narrow=flags["narrow_conv3d_as_2d"], winograd=flags["conv3d_depth_winograd"],
                                polyphase=flags["conv_transpose3d_polyphase"])
                 if any(flags.values()) else model)
    wrapper = StereoExportWrapper(rewritten, iters).eval()
    metadata = {**metadata, "export": {**dict(metadata.get("export") or {}), **flags}}
    left, right = (torch.from_numpy(a) for a in parity_inputs((w, h)))
    proto = export_onnx_file(wrapper, (left, right), out, input_names=["left", "right"], output_names=["disparity"],
                             metadata=metadata, opset=opset, graph_name="graph")
    log.info("exported %s (%dx%d, %d iters, %d nodes)", out, w, h, iters, len(proto.graph.node))
    return out


def parity_check(model: nn.Module, onnx_path: str | os.PathLike, *, size: tuple[int, int], iters: int,
                 seed: int = 0, threads: int = 2) -> float:
    """max |torch eager - onnxruntime| (pixels) on a textured pair at ``size`` and ``iters``."""
    left, right = parity_inputs(size, seed)
    with torch.no_grad():
        ref = model.eval()(torch.from_numpy(left), torch.from_numpy(right), iters=iters, test_mode=True).numpy()
    session = make_session(onnx_path, threads=threads)
    (got,) = session.run(["disparity"], {"left": left, "right": right})
    return max_abs_diff("output", got, ref)


def export_checkpoint(ckpt_path: str | os.PathLike, out: str | os.PathLike, *, iters: int, size: tuple[int, int],
                      force: bool = False, metrics: Mapping[str, Any] | None = None, parity: bool = True,
                      tolerance: float = 1e-3) -> dict[str, Any]:
    """Export a training checkpoint; returns ``{"path", "parity_max_abs_px", "metadata"}``.

    Raises:
        SpaceposeError: parity worse than ``tolerance`` (the file is removed again).
    """
    from spacepose.tools.train_stereo import load_checkpoint, model_from_checkpoint

    ckpt = load_checkpoint(ckpt_path)
    model, config = model_from_checkpoint(ckpt)
    train_cfg = ckpt.get("train_config", {})
    dataset = dict(ckpt.get("dataset", {}))
    if "seed" not in dataset:   # a checkpoint from before session 20 names no data seed: say which seed it has
        dataset["training_seed"] = train_cfg.get("seed")
    meta = stereo_metadata(input_size=size, iters=iters, stereo_config=config.to_dict(), dataset=dataset,
                           training_commit=ckpt.get("commit"), metrics=metrics,
                           extra={"training": {"step": ckpt.get("step"), "train_iters": train_cfg.get("iters"),
                                               "lr": train_cfg.get("lr"), "batch": train_cfg.get("batch")}})
    path = export_stereo(model, out, size=size, iters=iters, metadata=meta, force=force)
    result: dict[str, Any] = {"path": str(path), "metadata": meta, "parity_max_abs_px": None}
    if parity:
        diff = parity_check(model, path, size=size, iters=iters)
        result["parity_max_abs_px"] = diff
        enforce_parity(path, diff, tolerance, unit=" px")
    return result


def export_random_stereo(path: str | os.PathLike, *, size: tuple[int, int] = (64, 64), iters: int = 2,
                         config: StereoConfig | None = None, seed: int = 0, force: bool = True) -> tuple[Path, nn.Module]:
    """Export a randomly initialised model (tests, benchmarks of graph cost) -> (path, model)."""
    torch.manual_seed(seed)
    from spacepose.models.tsca_stereo import TSCAStereo

    cfg = config or StereoConfig.cpu()
    model = TSCAStereo(cfg).eval()
    meta = stereo_metadata(input_size=size, iters=iters, stereo_config=cfg.to_dict(),
                           dataset={"note": "random init, untrained"}, training_commit=None)
    meta["training_commit"] = None
    return export_stereo(model, path, size=size, iters=iters, metadata=meta, force=force), model


def write_stereo_manifest(bundle_dir: str | os.PathLike, *, input_size: tuple[int, int], iters: int, max_disp: float,
                          rig_path: str | os.PathLike, stereo_file: str = "stereo.onnx",
                          window_margin: float | None = None, dataset: Mapping[str, Any] | None = None,
                          metrics: Mapping[str, Any] | None = None) -> Path:
    """Write the stereo side of ``bundle_dir/bundle.json`` (atomic; other sections are kept).

    Sets ``stereo`` (file, input size, iterations, normalisation, max_disp[, window_margin]) and
    ``rig`` — the image size, rectified focal length and baseline of the rig the graph was trained
    on, read from ``rig_path`` (the dataset's ``rig.yaml``), which :meth:`ModelBundle.check_fits`
    compares a flight calibration against — and, when given, ``dataset`` and ``metrics.stereo``.
    """
    from spacepose.calibration.rectify import rectify
    from spacepose.calibration.rig import load_rig

    from .metadata import STEREO_NORMALISATION

    def update(data: dict[str, Any]) -> None:
        stereo = {"file": stereo_file, "input_size": [int(input_size[0]), int(input_size[1])], "iters": int(iters),
                  "normalisation": STEREO_NORMALISATION, "max_disp": float(max_disp)}
        if window_margin is not None:
            stereo["window_margin"] = float(window_margin)
        data["stereo"] = stereo
        rect = rectify(load_rig(rig_path))
        data["rig"] = {"image_size": [int(v) for v in rect.image_size], "focal_px": float(rect.focal_px),
                       "baseline_m": float(rect.baseline_m)}
        merge_manifest_section(data, "dataset", dataset)
        merge_manifest_section(data, "metrics", metrics, sub="stereo")

    return update_manifest(bundle_dir, update)
