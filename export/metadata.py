"""The metadata contract written into every exported stereo graph (and mirrored in bundle.json).

One JSON object stored under the ONNX ``metadata_props`` key ``"spacepose"``; the runtime reads it
back with :func:`spacepose.onnx_session.session_metadata` and checks it
(:func:`spacepose.stereo_stage.validate_stereo_metadata`).
"""

from __future__ import annotations

import datetime as _dt
import os
import subprocess
from pathlib import Path
from typing import Any, Mapping

__all__ = ["SCHEMA_VERSION", "STEREO_NORMALISATION", "COMMIT_ENV", "stereo_metadata", "git_commit", "provenance", "with_extra"]

SCHEMA_VERSION = 1

#: what the graph expects, by name (runtime/bundle.py checks the same name): "rgb_0_255" = float32
#: NCHW RGB in [0, 255], grey replicated to 3 channels, uint16 scaled by 255/65535, no mean/std
#: (the network normalises internally)
STEREO_NORMALISATION = "rgb_0_255"


#: environment variable that names the source commit when the tree's own ``.git`` does not (a copy of the
#: working tree on a lent accelerator carries a ``.git`` from an older checkout)
COMMIT_ENV = "SPACEPOSE_COMMIT"


def git_commit(cwd: str | Path | None = None) -> str | None:
    """The commit the source tree is at: ``$SPACEPOSE_COMMIT`` when set, else ``git rev-parse HEAD`` with
    ``+dirty`` appended when tracked files differ from it; None when git or the repo is unavailable."""
    named = os.environ.get(COMMIT_ENV, "").strip()
    if named:
        return named
    where = cwd or Path(__file__).resolve().parent
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=where, capture_output=True, text=True, timeout=10,
                             check=True)
        status = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=where,
                                capture_output=True, text=True, timeout=30, check=True)
    except (OSError, subprocess.SubprocessError):
        return None
    head = out.stdout.strip()
    if not head:
        return None
    return head + "+dirty" if status.stdout.strip() else head


def provenance(*, dataset: Mapping[str, Any] | None = None, training_commit: str | None = None,
               metrics: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The contract keys every exported graph carries: dataset, training commit (``git_commit()`` if
    None), metrics and the export time (UTC)."""
    return {
        "dataset": dict(dataset or {}),
        "training_commit": training_commit if training_commit is not None else git_commit(),
        "metrics": dict(metrics or {}),
        "exported_utc": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
    }


def with_extra(meta: dict[str, Any], extra: Mapping[str, Any] | None) -> dict[str, Any]:
    """``meta`` updated with ``extra`` (when given)."""
    if extra:
        meta.update(dict(extra))
    return meta


def stereo_metadata(
    *,
    input_size: tuple[int, int],
    iters: int,
    stereo_config: Mapping[str, Any],
    dataset: Mapping[str, Any] | None = None,
    training_commit: str | None = None,
    metrics: Mapping[str, Any] | None = None,
    extra: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """The contract dict of a stereo graph.

    Args:
        input_size: (width, height) of the fixed graph input.
        iters: update iterations frozen into the graph.
        stereo_config: ``StereoConfig.to_dict()`` of the exported model.
        dataset: e.g. ``{"path", "seed", "size", "train_frames"}``.
        training_commit: commit the checkpoint was trained at (``git_commit()`` if None).
        metrics: measured test metrics (EPE, D1, ...), when known.
    """
    w, h = (int(v) for v in input_size)
    cfg = dict(stereo_config)
    meta = {
        "schema": SCHEMA_VERSION,
        "kind": "stereo",
        "inputs": {"left": [1, 3, h, w], "right": [1, 3, h, w]},
        "outputs": {"disparity": [1, 1, h, w]},
        "input_size": [w, h],
        "iters": int(iters),
        "normalisation": STEREO_NORMALISATION,
        "disparity_units": "input pixels of the graph view (divide by the view scale for frame pixels)",
        "variant": cfg.get("variant"),
        "max_disp": cfg.get("max_disp"),
        "config": cfg,
        **provenance(dataset=dataset, training_commit=training_commit, metrics=metrics),
    }
    return with_extra(meta, extra)
