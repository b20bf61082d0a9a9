"""Re-export a shipped graph with the current exporter: same weights, same metadata, new graph form.

The exporter improves (session 13: the stereo regulariser's ConvTranspose3d layers as 2-D ones) after
a graph has shipped. :func:`reexport_graph` rebuilds the trained model from the graph itself
(:func:`spacepose.export.recover.checkpoint_from_graph`), exports it again with the exporter's current
options and the graph's own metadata (its training, data and test metrics stay true: the function is
unchanged; ``exported_utc`` is the new export's, ``reexported`` says from what). It checks three
ways: the recovered model against the old graph (inside the recovery), the recovered model against
the new graph (torch vs onnxruntime), and the old graph against the new one (onnxruntime vs
onnxruntime). The new file is removed again when a check fails.
"""

from __future__ import annotations

import datetime as _dt
import logging
import os
from pathlib import Path
from typing import Any

import numpy as np

from spacepose.errors import SpaceposeError
from spacepose.export.onnx_common import check_overwrite, enforce_parity, max_abs_diff
from spacepose.onnx_session import make_session, read_metadata

log = logging.getLogger(__name__)

__all__ = ["reexport_graph", "TOLERANCE"]

#: the exporters' parity limit (pixels of disparity for stereo graphs, output units for pose graphs)
TOLERANCE = 1e-3


def _graph_outputs(path: Path, feeds: dict[str, np.ndarray]) -> list[np.ndarray]:
    session = make_session(path, threads=2)
    return session.run(None, feeds)


def reexport_graph(graph: str | os.PathLike, out: str | os.PathLike, *, force: bool = False) -> dict[str, Any]:
    """Write ``graph``'s model, exported by the current code, to ``out``.

    Returns ``{"path", "kind", "recovery_parity", "torch_parity", "graph_parity", "export"}``: max
    |differences| (see the module doc) and the new graph's ``export`` flags.

    Raises:
        SpaceposeError: ``out`` is ``graph`` itself, ``out`` exists without ``force``, the graph is not
            one this project exported, or a check exceeds :data:`TOLERANCE`.
    """
    from spacepose.export import onnx_pose, onnx_stereo
    from spacepose.export.recover import checkpoint_from_graph

    src, dst = Path(graph), Path(out)
    if not src.is_file():
        raise SpaceposeError(f"no such graph: {src}")
    if dst.exists() and dst.resolve() == src.resolve():
        raise SpaceposeError(f"{dst} is the graph being re-exported; write the new one elsewhere and compare first")
    check_overwrite(dst, force)
    meta = read_metadata(src)
    ckpt = checkpoint_from_graph(src)
    keep = {k: v for k, v in meta.items() if k not in ("export", "exported_utc", "reexported")}
    keep["exported_utc"] = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    keep["reexported"] = {"from": src.name, "first_exported_utc": (meta.get("reexported") or {}).get(
        "first_exported_utc", meta.get("exported_utc")), "previous_export": meta.get("export") or {}}
    if ckpt["kind"] == "stereo":
        from spacepose.models.stereo_config import StereoConfig
        from spacepose.models.tsca_stereo import TSCAStereo

        model = TSCAStereo(StereoConfig.from_dict(ckpt["stereo_config"])).eval()
        model.load_state_dict(ckpt["model"])
        size, iters = tuple(int(v) for v in meta["input_size"]), int(meta["iters"])
        onnx_stereo.export_stereo(model, dst, size=size, iters=iters, metadata=keep, force=force)
        torch_parity = onnx_stereo.parity_check(model, dst, size=size, iters=iters)
        left, right = onnx_stereo.parity_inputs(size)
        feeds = {"left": left, "right": right}
    else:
        from spacepose.models.pose_config import PoseNetConfig
        from spacepose.models.pose_net import PoseNet

        model = PoseNet(PoseNetConfig.from_dict(ckpt["net_config"])).eval()
        model.load_state_dict(ckpt["model"])
        onnx_pose.export_pose(model, dst, metadata=keep, force=force)
        torch_parity = onnx_pose.parity_check(model, dst)["max"]
        feeds = onnx_pose.example_feeds(model.cfg.input_spec(), seed=1)
    enforce_parity(dst, torch_parity, TOLERANCE)
    old, new = _graph_outputs(src, feeds), _graph_outputs(dst, feeds)
    graph_parity = max(max_abs_diff(f"output {i}", b, a) for i, (a, b) in enumerate(zip(old, new)))
    if not graph_parity < TOLERANCE:
        dst.unlink(missing_ok=True)
        raise SpaceposeError(f"re-exported graph differs from {src} by {graph_parity:.3g} (>= {TOLERANCE}); removed")
    flags = dict(read_metadata(dst).get("export") or {})
    log.info("re-exported %s -> %s: parity recovered %.2g, torch %.2g, graph %.2g", src, dst, ckpt["parity"],
             torch_parity, graph_parity)
    return {"path": str(dst), "kind": ckpt["kind"], "recovery_parity": float(ckpt["parity"]),
            "torch_parity": float(torch_parity), "graph_parity": float(graph_parity), "export": flags}
