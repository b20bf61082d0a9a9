"""The accelerator job end to end on the CPU with tiny numbers: render, recover, fine-tune both, export."""

import json

import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("onnx")
pytest.importorskip("embreex")


@pytest.mark.slow
def test_device_job_returns_graphs_weights_and_logs(tmp_path):
    from spacepose.onnx_session import read_metadata
    from spacepose.tools.device_job import main

    out = tmp_path / "out"
    code = main(["--work", str(tmp_path / "work"), "--out", str(out), "--frames", "10", "--size", "320x240",
                 "--render-workers", "1", "--loader-workers", "0", "--threads", "1", "--stereo-steps", "1",
                 "--pose-steps", "1", "--stereo-batch", "2", "--pose-batch", "2", "--val-every", "100",
                 "--time-limit-s", "600"])
    report = json.loads((out / "job.json").read_text())
    assert code == 0 and report["ok"], json.dumps(report["phases"], indent=1)[-3000:]
    assert set(report["phases"]) == {"render", "recover", "train", "export"}
    names = {p.name for p in out.iterdir()}
    assert {"stereo.onnx", "pose.onnx", "stereo_weights.pt", "pose_weights.pt", "stereo_log.jsonl",
            "pose_log.jsonl", "job.json"} <= names
    assert all((out / n).stat().st_size < 16 * 2**20 for n in names)     # what a device call can return
    assert read_metadata(out / "stereo.onnx")["kind"] == "stereo"
    weights = torch.load(out / "pose_weights.pt", weights_only=False)
    assert "optimizer" not in weights and weights["step"] == 1 and weights["folded_bn"]
