"""The accelerator job end to end on the CPU with tiny numbers: render, recover, fine-tune both, export."""

import gzip
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
                 "--time-limit-s", "600", "--commit", "feedbeef", "--eval-frames", "10", "--eval-restyle-seed", "5",
                 "--eval-workers", "2", "--eval-stereo-frames", "1"])
    report = json.loads((out / "job.json").read_text())
    assert code == 0 and report["ok"], json.dumps(report["phases"], indent=1)[-3000:]
    assert set(report["phases"]) == {"render", "recover", "train", "export", "evaluate"}
    names = {p.name for p in out.iterdir()}
    assert {"stereo.onnx", "pose.onnx", "stereo_weights.pt", "pose_weights.pt", "stereo_log.jsonl",
            "pose_log.jsonl", "job.json", "eval.json.gz"} == names
    assert all((out / n).stat().st_size < 16 * 2**20 for n in names)     # what a device call can return
    # the evaluation: the new graphs in an open copy of the bundle, on fresh frames (plain and restyled)
    ev = json.loads(gzip.decompress((out / "eval.json.gz").read_bytes()))
    assert ev["graphs_replaced"] == ["stereo.onnx", "pose.onnx"] and ev["eval_seed"] == 1011
    data = json.loads((tmp_path / "work" / "eval" / "data" / "dataset.json").read_text())
    assert data["seed"] == 1011 and data["count"] == 10
    assert len(ev["plain"]["frames"]) == len(ev["restyled"]["frames"]) == 9         # their train split
    assert [r["frame"] for r in ev["plain"]["frames"]] == [r["frame"] for r in ev["restyled"]["frames"]]
    assert ev["plain"]["bundle"].endswith("bundle_open") and ev["stereo"]["frames"] == 1
    opened = json.loads((tmp_path / "work" / "eval" / "bundle_open" / "bundle.json").read_text())
    assert opened["silhouette"]["max_chamfer_px"] == 100.0 and "min_valid" not in opened["confidence"]
    assert ((tmp_path / "work" / "eval" / "bundle" / "stereo.onnx").read_bytes()
            == (out / "stereo.onnx").read_bytes())
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
    from spacepose.tools.device_job import eval_commands

    assert "evaluate" not in phases                        # evaluation is its own phase, off by default
    ev_args = build_parser().parse_args(["--work", str(tmp_path), "--out", str(tmp_path / "o"), "--eval-frames", "900",
                                         "--eval-restyle-seed", "7", "--eval-workers", "15", "--data-seed", "21"])
    steps = eval_commands(ev_args, tmp_path)
    render = steps["render"][0]
    assert render[render.index("--seed") + 1] == "1021" and render[render.index("--count") + 1] == "900"
    assert "--no-depth" in render and steps["restyle"][0][-1] == "7"
    plain, stereo = steps["plain"]
    assert plain[plain.index("--workers") + 1] == "15" and plain[plain.index("--bundle") + 1].endswith("bundle_open")
    assert "eval-stereo" in stereo and stereo[stereo.index("--bundle") + 1].endswith("eval/bundle")
    assert steps["restyled"][0][steps["restyled"][0].index("--out") + 1].endswith("open_restyled.json.gz")
    bare = eval_commands(build_parser().parse_args(["--work", str(tmp_path), "--out", "o", "--eval-frames", "9",
                                                    "--eval-stereo-frames", "0"]), tmp_path)
    assert bare["restyle"] == [] and bare["restyled"] == [] and len(bare["plain"]) == 1
    resumed = job_commands(build_parser().parse_args(["--work", str(tmp_path), "--out", str(tmp_path / "o"),
                                                      "--kinds", "stereo", "--stereo-init", "w.pt",
                                                      "--stereo-oversample", "mixed=4",
                                                      "--stereo-photometric", "mild"]), tmp_path)
    assert resumed["recover"] == []                        # carried weights: nothing to rebuild
    stereo = resumed["train"][0]
    assert stereo[stereo.index("--init") + 1] == "w.pt"
    assert stereo[stereo.index("--photometric") + 1] == "mild"
    assert stereo[stereo.index("--oversample") + 1:stereo.index("--oversample") + 3] == ["mixed=4", "--threads"]
