"""Arguments and helpers shared by ``spacepose export-stereo`` and ``spacepose export-pose`` (stdlib only
at import time: the heavy imports stay inside :func:`require_export_extras`)."""

from __future__ import annotations

import argparse
import gzip
import json
from pathlib import Path
from typing import Any

__all__ = ["add_checkpoint_arguments", "add_metrics_arguments", "require_export_extras", "load_metrics"]


def add_checkpoint_arguments(parser: argparse.ArgumentParser, kind: str) -> None:
    """CHECKPOINT (``runs/KIND/last.pt``) and --out (``runtime/bundles/default/KIND.onnx``)."""
    parser.add_argument("checkpoint", type=Path, help=f"training checkpoint (runs/{kind}/last.pt)")
    parser.add_argument("--out", type=Path, default=Path(f"runtime/bundles/default/{kind}.onnx"))


def add_metrics_arguments(parser: argparse.ArgumentParser, kind: str) -> None:
    """--metrics (``eval-KIND`` output to embed) and --no-parity."""
    parser.add_argument("--metrics", type=Path, default=None, help=f"JSON of test metrics to embed (eval-{kind} output)")
    parser.add_argument("--no-parity", action="store_true", help="skip the torch vs onnxruntime check")


def require_export_extras() -> None:
    """MissingExtraError unless torch and onnx are installed."""
    from spacepose._optional import import_optional

    import_optional("torch")
    import_optional("onnx")


def load_metrics(path: Path | None) -> dict[str, Any] | None:
    """The metrics to embed from an eval report (its ``ours.overall`` section, else the whole object);
    a ``.gz`` report (how older reports are stored) is read through gzip."""
    if path is None:
        return None
    doc = json.loads(gzip.decompress(path.read_bytes()) if path.suffix == ".gz" else path.read_text())
    return doc.get("ours", {}).get("overall", doc) if isinstance(doc, dict) else None
