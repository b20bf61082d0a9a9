"""onnxruntime sessions and the JSON metadata contract carried inside every exported graph.

Every graph of a model bundle stores one JSON object under the ONNX ``metadata_props`` key
``"spacepose"`` (onnxruntime exposes it as ``custom_metadata_map["spacepose"]``). The exporter writes
it (``spacepose.export.metadata``); the runtime reads it back here and refuses graphs without it.
"""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path
from typing import Any

from .errors import BundleError

log = logging.getLogger(__name__)

__all__ = ["METADATA_KEY", "make_session", "read_metadata", "session_metadata", "write_metadata", "input_shapes"]

#: the ``metadata_props`` key that holds the JSON contract
METADATA_KEY = "spacepose"


def make_session(path: str | os.PathLike, *, threads: int = 2, mem_arena: bool = False, optimize: bool = True,
                 spinning: bool = False):
    """An onnxruntime CPU ``InferenceSession`` for ``path``.

    Args:
        threads: intra-op threads (inter-op is 1: the graph runs sequentially).
        mem_arena: onnxruntime's CPU memory arena: faster for a graph of fixed input size called
            again and again (the estimator turns it on for both its graphs; see
            :class:`spacepose.stereo_stage.StereoMatcher`), at the cost of the memory it keeps; off by default.
        optimize: full graph optimisations (``ORT_ENABLE_ALL``) when True, basic otherwise.
        spinning: let idle intra-op workers spin instead of sleeping (see the comment below).

    Raises:
        BundleError: the file is missing or onnxruntime cannot load it.
    """
    import onnxruntime as ort  # flight dependency, imported lazily to keep `spacepose --help` fast

    p = Path(path)
    if not p.is_file():
        raise BundleError(f"ONNX graph not found: {p}")
    if int(threads) < 1:
        raise ValueError(f"threads must be >= 1, got {threads}")
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = int(threads)
    opts.inter_op_num_threads = 1
    opts.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    opts.enable_cpu_mem_arena = bool(mem_arena)
    opts.graph_optimization_level = (
        ort.GraphOptimizationLevel.ORT_ENABLE_ALL if optimize else ort.GraphOptimizationLevel.ORT_ENABLE_BASIC
    )
    opts.log_severity_level = 3
    # by default worker threads sleep between runs instead of spinning: the pipeline's numpy/OpenCV
    # work runs between graph calls on the same cores, and spinning workers starve it (session 3: kNN
    # and voting took twice as long with every session spinning). The stereo stage turns it on for
    # its own session only (spacepose.stereo_stage.StereoMatcher documents the measurement).
    opts.add_session_config_entry("session.intra_op.allow_spinning", "1" if spinning else "0")
    if spinning:
        # spin between the graph's operators only: when run() returns, the workers stop spinning at
        # once instead of competing with the numpy stage that follows for the same cores
        opts.add_session_config_entry("session.force_spinning_stop", "1")
    try:
        return ort.InferenceSession(str(p), sess_options=opts, providers=["CPUExecutionProvider"])
    except Exception as err:  # onnxruntime raises its own Fail/InvalidGraph/... types
        raise BundleError(f"cannot load ONNX graph {p}: {err}") from err


def session_metadata(session) -> dict[str, Any]:
    """The JSON contract of a loaded session (BundleError when absent or not a JSON object)."""
    meta = session.get_modelmeta().custom_metadata_map
    return _parse(meta.get(METADATA_KEY), "session")


def checked_session(path: str | os.PathLike, expect: dict[str, Any], what: str, *, threads: int = 1):
    """``(session, metadata)`` of the bundle graph at ``path`` (memory arena on), whose metadata must hold every
    ``expect`` key with that value; BundleError naming ``what`` graph, the file, the key and both values otherwise
    (and when the file is missing or unloadable)."""
    session = make_session(path, threads=threads, mem_arena=True)
    meta = session_metadata(session)
    for key, value in expect.items():
        if key not in meta or meta[key] != value:
            raise BundleError(f"{what} graph {Path(path).name}: metadata {key}={meta.get(key)!r}, "
                              f"bundle expects {value!r}")
    return session, meta


def read_metadata(path: str | os.PathLike) -> dict[str, Any]:
    """The JSON contract of the graph at ``path``, read with onnxruntime (no session kept)."""
    session = make_session(path, threads=1, optimize=False)
    try:
        return session_metadata(session)
    except BundleError as err:
        raise BundleError(f"{path}: {err}") from err


def _parse(text: str | None, where: str) -> dict[str, Any]:
    if text is None:
        raise BundleError(f"graph has no {METADATA_KEY!r} metadata ({where}); was it exported by spacepose?")
    try:
        value = json.loads(text)
    except json.JSONDecodeError as err:
        raise BundleError(f"graph metadata {METADATA_KEY!r} is not valid JSON: {err}") from err
    if not isinstance(value, dict):
        raise BundleError(f"graph metadata {METADATA_KEY!r} must be a JSON object, got {type(value).__name__}")
    return value


def write_metadata(model_proto, metadata: dict[str, Any]) -> None:
    """Store ``metadata`` as JSON under ``"spacepose"`` in an ``onnx.ModelProto`` (replacing any old one).

    Export-side helper; it only touches the protobuf object handed in, so it needs no onnx import.
    """
    text = json.dumps(metadata, sort_keys=True)
    for prop in list(model_proto.metadata_props):
        if prop.key == METADATA_KEY:
            model_proto.metadata_props.remove(prop)
    entry = model_proto.metadata_props.add()
    entry.key = METADATA_KEY
    entry.value = text


def input_shapes(session) -> dict[str, list]:
    """``{input name: shape list}`` of a session (symbolic dims are strings or None)."""
    return {i.name: list(i.shape) for i in session.get_inputs()}
