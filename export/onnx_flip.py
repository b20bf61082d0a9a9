"""Export the flip classifier to ONNX: ``spacepose export-flip CKPT --out BUNDLE/flip.onnx [--force]``.

* legacy TorchScript exporter, opset 17, one file; input ``views`` (B, 3, S, S) float32 with a dynamic
  batch, output ``logit`` (B,) (the logit that outline A is the right pose; antisymmetric in A and B);
* metadata under ``"spacepose"``: kind ``flip``, size, channels, the flip axis, target, the net config
  and the training provenance; :mod:`spacepose.flip_classifier` checks it against ``bundle.json``;
* parity torch eager vs onnxruntime on views built from random poses (< 1e-4 on the logit);
* the ``flip_classifier`` section of ``bundle.json`` (file, size, axis) is written, the decision
  thresholds already there kept (they are chosen on train frames, not by the exporter).
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
from pathlib import Path
from typing import Any, Mapping

import numpy as np

HELP = "export a flip-classifier checkpoint to ONNX with its metadata contract and a parity check"

log = logging.getLogger(__name__)

__all__ = ["flip_metadata", "export_flip", "example_views", "write_flip_graph", "parity_check"]

PARITY_TOLERANCE = 1e-4


def flip_metadata(config: Any, *, target: str, axis: str, extra: Mapping[str, Any] | None = None) -> dict[str, Any]:
    from spacepose.export.metadata import SCHEMA_VERSION, provenance, with_extra
    from spacepose.flip_views import CHANNELS

    meta = {"schema": SCHEMA_VERSION, "kind": "flip", "target": str(target), "size": int(config.size),
            "channels": CHANNELS, "axis": str(axis), "inputs": {"views": ["B", CHANNELS, config.size, config.size]},
            "outputs": {"logit": ["B"]}, "config": json_safe(dataclasses.asdict(config)),
            "output_meaning": "logit that outline A (plane 1) is the right pose; logit(A, B) = -logit(B, A)",
            **provenance()}
    return with_extra(meta, extra)


def json_safe(value: Any) -> Any:
    return [json_safe(v) for v in value] if isinstance(value, (list, tuple)) else value


def example_views(size: int, n: int = 4, seed: int = 0) -> np.ndarray:
    """(n, 3, size, size) float32: a random grey plane and two random blob outlines."""
    rng = np.random.default_rng(seed)
    views = np.zeros((n, 3, size, size), np.float32)
    views[:, 0] = rng.uniform(0.0, 2.0, size=(n, size, size))
    yy, xx = np.mgrid[0:size, 0:size] / size
    for k in range(n):
        for c in (1, 2):
            cx, cy, r = rng.uniform(0.3, 0.7), rng.uniform(0.3, 0.7), rng.uniform(0.1, 0.3)
            views[k, c] = ((xx - cx) ** 2 + (yy - cy) ** 2 < r * r).astype(np.float32)
    return views


def write_flip_graph(model: Any, path: str | Path, metadata: Mapping[str, Any]) -> None:
    """Write the (eval-mode) FlipNet ``model`` to ``path`` as the flip graph (batch axis free), with ``metadata``."""
    import torch

    from spacepose.export.onnx_common import export_onnx_file

    views = example_views(model.config.size)
    export_onnx_file(model, (torch.from_numpy(views),), Path(path), input_names=["views"], output_names=["logit"],
                     metadata=dict(metadata), graph_name="flip graph",
                     dynamic_axes={"views": {0: "B"}, "logit": {0: "B"}})


def parity_check(model: Any, path: str | Path) -> float:
    """Largest |logit| difference between the FlipNet ``model`` (torch, eval mode) and the graph at ``path``
    (onnxruntime) on :func:`example_views` batches of 1, 2 and 5."""
    import torch

    from spacepose.export.onnx_common import max_abs_diff
    from spacepose.onnx_session import make_session

    session = make_session(Path(path), threads=1)
    diff = 0.0
    for n in (1, 2, 5):
        v = example_views(model.config.size, n=n, seed=n)
        with torch.no_grad():
            ref = model(torch.from_numpy(v)).numpy()
        diff = max(diff, max_abs_diff("logit", session.run(["logit"], {"views": v})[0], ref))
    return diff


def export_flip(checkpoint: str | Path, out: str | Path, *, force: bool = False, target: str = "tdrs", axis: str = "z",
                update_manifest: bool = True) -> dict[str, Any]:
    """Export ``checkpoint`` (``spacepose train-flip``'s ``last.pt``) to ``out``; -> path, parity, metadata."""
    from spacepose.export.onnx_common import check_overwrite, enforce_parity, update_manifest as update
    from spacepose.models.flip_net import FlipNet, FlipNetConfig
    from spacepose.tools.training_common import load_checkpoint

    path = check_overwrite(out, force)
    ckpt = load_checkpoint(checkpoint, kind="flip")
    raw = dict(ckpt["net_config"])
    config = FlipNetConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in raw.items()})
    model = FlipNet(config)
    model.load_state_dict(ckpt["model"])
    model.eval()
    meta = flip_metadata(config, target=target, axis=axis, extra={"steps": int(ckpt.get("step", 0)),
                                                                 "samples": int(ckpt.get("samples", 0))})
    write_flip_graph(model, path, meta)
    diff = parity_check(model, path)
    enforce_parity(path, diff, PARITY_TOLERANCE)
    manifest = None
    if update_manifest:
        def section(data: dict[str, Any]) -> None:
            data["flip_classifier"] = {**dict(data.get("flip_classifier") or {}), "file": path.name,
                                       "size": int(config.size), "axis": axis}
        manifest = update(path.parent, section)
    log.info("exported %s, parity %.2e", path, diff)
    return {"path": path, "parity": diff, "metadata": meta, "manifest": manifest}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("checkpoint", type=Path, help="train-flip checkpoint (last.pt)")
    parser.add_argument("--out", type=Path, required=True, help="output .onnx (inside a bundle folder)")
    parser.add_argument("--no-manifest", action="store_true", help="do not write OUT_DIR/bundle.json's flip_classifier")
    parser.add_argument("--force", action="store_true", help="overwrite an existing file")


def run(args: argparse.Namespace) -> int:
    from spacepose.export.cli_common import require_export_extras

    require_export_extras()
    result = export_flip(args.checkpoint, args.out, force=args.force, update_manifest=not args.no_manifest)
    print(f"wrote {result['path']} (size {result['metadata']['size']}); parity torch vs onnxruntime: "
          f"max |diff| = {result['parity']:.2e} (limit {PARITY_TOLERANCE:g})")
    if result["manifest"]:
        print(f"updated the flip_classifier section of {result['manifest']}")
    return 0
