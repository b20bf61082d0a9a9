"""Plumbing shared by the stereo and pose ONNX exporters (:mod:`~spacepose.export.onnx_stereo`,
:mod:`~spacepose.export.onnx_pose`): one-file export with the forbidden-op check and the metadata
contract, parity bookkeeping, and the atomic read-merge-write of ``bundle.json``.
"""

from __future__ import annotations

import json
import logging
import os
import tempfile
import warnings
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np
import torch
from torch import nn

from spacepose.errors import BundleError, SpaceposeError
from spacepose.onnx_session import write_metadata

log = logging.getLogger(__name__)

__all__ = ["OPSET", "FORBIDDEN_OPS", "BUNDLE_SCHEMA", "forbidden_ops", "check_overwrite", "export_onnx_file",
           "max_abs_diff", "enforce_parity", "update_manifest", "merge_manifest_section"]

OPSET = 17
FORBIDDEN_OPS = frozenset({"GridSample", "ScatterND"})
BUNDLE_SCHEMA = "spacepose.bundle/1"


def forbidden_ops(model_proto) -> set[str]:
    """Op types of ``FORBIDDEN_OPS`` found anywhere in the graph (subgraphs included)."""
    found: set[str] = set()

    def visit(graph) -> None:
        for node in graph.node:
            if node.op_type in FORBIDDEN_OPS:
                found.add(node.op_type)
            for attr in node.attribute:
                if attr.g is not None and len(attr.g.node):
                    visit(attr.g)
                for g in attr.graphs:
                    visit(g)

    visit(model_proto.graph)
    return found


def check_overwrite(path: str | os.PathLike, force: bool) -> Path:
    """``path`` as a Path; SpaceposeError when it exists and ``force`` is False."""
    out = Path(path)
    if out.exists() and not force:
        raise SpaceposeError(f"{out} exists; pass --force to overwrite")
    return out


def export_onnx_file(module: nn.Module, args: tuple[torch.Tensor, ...], out: Path, *, input_names: Sequence[str],
                     output_names: Sequence[str], metadata: Mapping[str, Any], opset: int = OPSET,
                     graph_name: str = "graph", dynamic_axes: Mapping[str, Mapping[int, str]] | None = None):
    """Trace ``module(*args)`` (legacy exporter, no external data) into ``out`` with ``metadata``; -> the proto.
    ``dynamic_axes``: torch.onnx's, for graphs with a free batch axis.

    The file appears atomically, and only when the graph holds none of ``FORBIDDEN_OPS`` and passes
    the ONNX checker (SpaceposeError names the forbidden ops otherwise).
    """
    import onnx

    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=out.parent) as tmp:
        raw = Path(tmp) / "raw.onnx"
        with torch.no_grad(), warnings.catch_warnings():
            warnings.simplefilter("ignore")  # tracer/constant-folding chatter; parity is checked instead
            torch.onnx.export(module, args, str(raw), input_names=list(input_names),
                              output_names=list(output_names), opset_version=opset, dynamo=False,
                              do_constant_folding=True, external_data=False,
                              dynamic_axes=None if dynamic_axes is None else {k: dict(v) for k, v in dynamic_axes.items()})
        proto = onnx.load(str(raw))
        bad = forbidden_ops(proto)
        if bad:
            raise SpaceposeError(f"exported {graph_name} contains forbidden ops {sorted(bad)}")
        write_metadata(proto, dict(metadata))
        onnx.checker.check_model(proto)
        final_tmp = Path(tmp) / "final.onnx"
        onnx.save(proto, str(final_tmp))
        os.replace(final_tmp, out)
    return proto


def max_abs_diff(name: str, got: np.ndarray, ref: np.ndarray) -> float:
    """max |got - ref| in float64; BundleError naming ``name`` when the shapes differ."""
    if tuple(got.shape) != tuple(ref.shape):
        raise BundleError(f"onnxruntime {name} shape {got.shape} != torch {tuple(ref.shape)}")
    return float(np.max(np.abs(got.astype(np.float64) - ref.astype(np.float64))))


def enforce_parity(path: Path, diff: float, tolerance: float, unit: str = "") -> None:
    """Remove ``path`` and raise SpaceposeError unless ``diff < tolerance``."""
    if not diff < tolerance:
        path.unlink(missing_ok=True)
        raise SpaceposeError(f"parity check failed: max |torch - onnxruntime| = {diff:.3g}{unit} >= {tolerance}")


def merge_manifest_section(data: dict[str, Any], key: str, values: Mapping[str, Any] | None,
                           sub: str | None = None) -> None:
    """Merge ``values`` into ``data[key]`` (or set ``data[key][sub]``); nothing when ``values`` is None."""
    if values is None:
        return
    if sub is None:
        data[key] = {**dict(data.get(key) or {}), **dict(values)}
    else:
        data[key] = {**dict(data.get(key) or {}), sub: dict(values)}


def update_manifest(bundle_dir: str | os.PathLike, update: Callable[[dict[str, Any]], None]) -> Path:
    """Read ``bundle_dir/bundle.json`` (``{}`` if absent), let ``update`` change it, write it back atomically."""
    folder = Path(bundle_dir)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "bundle.json"
    data: dict[str, Any] = {}
    if path.is_file():
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError) as err:
            raise BundleError(f"{path} is unreadable: {err}") from err
    data["schema"] = BUNDLE_SCHEMA
    update(data)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    os.replace(tmp, path)
    return path
