"""Export the outline refiner to ONNX: ``spacepose export-outline CKPT --out BUNDLE/outline.onnx [--force]``.

* legacy TorchScript exporter, opset 17, one file; input ``planes`` (1, 3, H, W) float32 with H and W free
  (multiples of 4), output ``logit`` (1, 1, H, W);
* metadata under ``"spacepose"``: kind ``outline``, planes, multiple, target, the net config and the training
  provenance; :mod:`spacepose.outline_refiner` checks it;
* parity torch eager vs onnxruntime on random planes of three sizes (< 1e-3 on the logit);
* the ``outline_refiner`` section of ``bundle.json`` (file) is written, ``grow_px`` kept when there.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
from pathlib import Path
from typing import Any

import numpy as np

HELP = "export an outline-refiner checkpoint to ONNX with its metadata contract and a parity check"

log = logging.getLogger(__name__)

__all__ = ["export_outline", "example_planes", "parity_check"]

PARITY_TOLERANCE = 1e-3
KIND = "outline"


def example_planes(side: int, seed: int = 0) -> np.ndarray:
    """(1, 3, side, side) float32: a random grey plane, a disc outline and a disparity ratio plane."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:side, 0:side] / side
    disc = ((xx - 0.5) ** 2 + (yy - 0.5) ** 2 < 0.1).astype(np.float32)
    planes = np.stack([rng.uniform(0.0, 2.0, (side, side)), disc, disc * rng.uniform(1.0, 3.0, (side, side))])
    return planes[None].astype(np.float32)


def parity_check(model: Any, path: str | Path) -> float:
    """Largest |logit| difference between ``model`` (torch, eval mode) and the graph at ``path`` (onnxruntime)."""
    import torch

    from spacepose.export.onnx_common import max_abs_diff
    from spacepose.onnx_session import make_session

    session = make_session(Path(path), threads=1)
    diff = 0.0
    for k, side in enumerate((32, 100, 192)):
        p = example_planes(side, seed=k)
        with torch.no_grad():
            ref = model(torch.from_numpy(p)).numpy()
        diff = max(diff, max_abs_diff("logit", session.run(["logit"], {"planes": p})[0], ref))
    return diff


def export_outline(checkpoint: str | Path, out: str | Path, *, force: bool = False, target: str = "tdrs",
                   update_manifest: bool = True) -> dict[str, Any]:
    """Export ``checkpoint`` (``spacepose train-outline``'s ``last.pt``) to ``out``; -> path, parity, metadata."""
    import torch

    from spacepose.export.metadata import SCHEMA_VERSION, provenance, with_extra
    from spacepose.export.onnx_common import check_overwrite, enforce_parity, export_onnx_file
    from spacepose.export.onnx_common import update_manifest as update
    from spacepose.models.outline_refiner import OutlineRefinerConfig, OutlineRefinerNet
    from spacepose.outline_refiner import MULTIPLE, PLANES
    from spacepose.tools.training_common import load_checkpoint

    path = check_overwrite(out, force)
    ckpt = load_checkpoint(checkpoint, kind=KIND)
    config = OutlineRefinerConfig(**dict(ckpt["net_config"]))
    model = OutlineRefinerNet(config)
    model.load_state_dict(ckpt["model"])
    model.eval()
    meta = with_extra({"schema": SCHEMA_VERSION, "kind": KIND, "target": str(target), "planes": PLANES,
                       "multiple": MULTIPLE, "inputs": {"planes": [1, PLANES, "H", "W"]},
                       "outputs": {"logit": [1, 1, "H", "W"]}, "config": dataclasses.asdict(config),
                       "output_meaning": "per pixel, the logit that the target covers it", **provenance()},
                      {"steps": int(ckpt.get("step", 0)), "samples": int(ckpt.get("samples", 0))})
    export_onnx_file(model, (torch.from_numpy(example_planes(64)),), path, input_names=["planes"],
                     output_names=["logit"], metadata=meta, graph_name="outline graph",
                     dynamic_axes={"planes": {2: "H", 3: "W"}, "logit": {2: "H", 3: "W"}})
    diff = parity_check(model, path)
    enforce_parity(path, diff, PARITY_TOLERANCE)
    manifest = None
    if update_manifest:
        def section(data: dict[str, Any]) -> None:
            data["outline_refiner"] = {**dict(data.get("outline_refiner") or {}), "file": path.name}
        manifest = update(path.parent, section)
    log.info("exported %s, parity %.2e", path, diff)
    return {"path": path, "parity": diff, "metadata": meta, "manifest": manifest}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("checkpoint", type=Path, help="train-outline checkpoint (last.pt)")
    parser.add_argument("--out", type=Path, required=True, help="output .onnx (inside a bundle folder)")
    parser.add_argument("--no-manifest", action="store_true",
                        help="do not write OUT_DIR/bundle.json's outline_refiner section")
    parser.add_argument("--force", action="store_true", help="overwrite an existing file")


def run(args: argparse.Namespace) -> int:
    from spacepose.export.cli_common import require_export_extras

    require_export_extras()
    result = export_outline(args.checkpoint, args.out, force=args.force, update_manifest=not args.no_manifest)
    print(f"wrote {result['path']}; parity torch vs onnxruntime: max |diff| = {result['parity']:.2e} "
          f"(limit {PARITY_TOLERANCE:g})")
    if result["manifest"]:
        print(f"updated the outline_refiner section of {result['manifest']}")
    return 0
