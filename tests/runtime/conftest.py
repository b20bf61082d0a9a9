"""Session fixture: a tiny random-init stereo graph (64x64, 2 iterations) for runtime tests."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def tiny_stereo_graph(tmp_path_factory) -> Path:
    pytest.importorskip("torch")
    from spacepose.export.onnx_stereo import export_random_stereo

    folder = tmp_path_factory.mktemp("tiny_bundle")
    path, _ = export_random_stereo(folder / "stereo.onnx", size=(64, 64), iters=2)
    return path
