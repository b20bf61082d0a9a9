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
                 "--time-limit-s", "600", "--commit", "feedbeef"])
    report = json.loads((out / "job.json").read_text())
    assert code == 0 and report["ok"], json.dumps(report["phases"], indent=1)[-3000:]
    assert set(report["phases"]) == {"render", "recover", "train", "export"}
    names = {p.name for p in out.iterdir()}
    assert {"stereo.onnx", "pose.onnx", "stereo_weights.pt", "pose_weights.pt", "stereo_log.jsonl",
            "pose_log.jsonl", "job.json"} <= names
    assert all((out / n).stat().st_size < 16 * 2**20 for n in names)     # what a device call can return
    meta = read_metadata(out / "stereo.onnx")
    assert meta["kind"] == "stereo" and meta["training_commit"] == "feedbeef"    # not the copy's stale .git
    assert meta["dataset"]["seed"] == 11 and meta["dataset"]["train_frames"] == 9   # the data rendered there
    weights = torch.load(out / "pose_weights.pt", weights_only=False)
    assert "optimizer" not in weights and weights["step"] == 1 and weights["folded_bn"]


def test_job_commands_budget_and_kinds(tmp_path):
    from spacepose.tools.device_job import _with_time_limit, build_parser, job_commands

    args = build_parser().parse_args(["--work", str(tmp_path), "--out", str(tmp_path / "o"), "--kinds", "stereo",
                                      "--stereo-workers", "14", "--pose-symmetric-flip", "z"])
    phases = job_commands(args, tmp_path)
    assert [len(phases[k]) for k in ("render", "recover", "train", "export")] == [1, 1, 1, 1]
    train = phases["train"][0]
    assert "train-stereo" in train and "--pace-lr" in train
    assert train[train.index("--workers") + 1] == "14"
    assert train[train.index("--photometric") + 1] == "wide"
    assert "export-stereo" in phases["export"][0] and phases["recover"][0][4].endswith("stereo.onnx")
    limited = _with_time_limit(train, 123.4)
    assert limited[limited.index("--time-limit-s") + 1] == "123" and len(limited) == len(train)
    both = job_commands(build_parser().parse_args(["--work", str(tmp_path), "--out", str(tmp_path / "o"),
                                                   "--pose-symmetric-flip", "z"]), tmp_path)
    pose = both["train"][1]
    assert "train-pose" in pose and pose[pose.index("--symmetric-flip") + 1] == "z"
    resumed = job_commands(build_parser().parse_args(["--work", str(tmp_path), "--out", str(tmp_path / "o"),
                                                      "--kinds", "stereo", "--stereo-init", "w.pt",
                                                      "--stereo-oversample", "mixed=4",
                                                      "--stereo-photometric", "mild"]), tmp_path)
    assert resumed["recover"] == []                        # carried weights: nothing to rebuild
    stereo = resumed["train"][0]
    assert stereo[stereo.index("--init") + 1] == "w.pt"
    assert stereo[stereo.index("--photometric") + 1] == "mild"
    assert stereo[stereo.index("--oversample") + 1:stereo.index("--oversample") + 3] == ["mixed=4", "--threads"]
