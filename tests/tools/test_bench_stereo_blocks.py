"""bench_stereo_blocks: each block exported in the exporter's form computes what the original computes,
and every block the table names is timed (timings themselves are never asserted)."""

import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("onnxruntime")

from spacepose.models.stereo_config import StereoConfig  # noqa: E402
from spacepose.models.tsca_stereo import TSCAStereo  # noqa: E402
from spacepose.tools.bench_stereo_blocks import bench_blocks, capture_block_inputs  # noqa: E402


def test_blocks_are_captured_exported_and_timed():
    torch.manual_seed(0)
    model = TSCAStereo(StereoConfig.cpu()).eval()
    left, right = torch.rand(1, 3, 32, 64) * 255, torch.rand(1, 3, 32, 64) * 255
    inputs = capture_block_inputs(model, left, right, ("stem.0", "decoders.2.up", "classifier", "no.such.block"))
    assert sorted(inputs) == ["classifier", "decoders.2.up", "stem.0"]
    assert inputs["stem.0"][0].shape[:3] == (1, model.cfg.groups, model.cfg.num_disp)
    rows = bench_blocks(model, {}, (64, 32), 2, threads=1, calls=1, blocks=("stem.0", "decoders.2.up", "classifier"))
    names = [r["block"] for r in rows]
    assert names[:2] == ["prefix (features + correlation)", "regularizer + classifier"]
    assert names[2:5] == ["regularizer.stem.0", "regularizer.decoders.2.up", "regularizer.classifier"]
    assert names[-1] == "whole network, 2 iterations"
    for r in rows:
        assert r["onnxruntime_ms"] > 0 and r["torch_ms"] > 0 and r["speedup"] > 0
        assert r["max_abs_diff"] < 1e-3, r                   # the exported form is the same function
