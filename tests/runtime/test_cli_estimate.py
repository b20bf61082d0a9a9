"""Tests of `spacepose estimate` (runtime/cli_estimate.py) on a tiny folder with the test bundle."""

import csv
import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))  # --import-mode=importlib: find the helpers
from _bundle_fixtures import make_bundle, synthetic_pair  # noqa: E402

from spacepose.calibration.rig import paper_rig, save_rig  # noqa: E402
from spacepose.cli import main  # noqa: E402
from spacepose.imageio import write_image  # noqa: E402


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    root = tmp_path_factory.mktemp("estimate")
    bundle = make_bundle(root / "bundle")
    save_rig(paper_rig(640, 480), root / "rig.yaml")
    seq = root / "seq"
    (seq / "left").mkdir(parents=True)
    (seq / "right").mkdir()
    left, right = synthetic_pair()
    write_image(seq / "left" / "000000.png", left)
    write_image(seq / "right" / "000000.png", right)
    (seq / "left" / "000001.png").write_bytes(b"not a png")        # corrupt
    (seq / "right" / "000001.png").write_bytes(b"not a png")
    write_image(seq / "left" / "000002.png", left)                  # right partner missing
    write_image(seq / "left" / "000003.png", np.zeros_like(left))   # eclipse
    write_image(seq / "right" / "000003.png", np.zeros_like(right))
    write_image(seq / "left" / "000004.png", left[..., 0])          # grey, valid
    write_image(seq / "right" / "000004.png", right[..., 0])
    return root, seq, bundle


def _args(root, seq, bundle, out, *extra):
    return ["estimate", str(seq), "--calib", str(root / "rig.yaml"), "--out", str(out),
            "--bundle", str(bundle), "--threads", "1", *extra]


def test_every_frame_gets_a_line(setup, tmp_path, capsys):
    root, seq, bundle = setup
    out = tmp_path / "poses.jsonl"
    assert main(_args(root, seq, bundle, out, "--csv", str(tmp_path / "p.csv"), "--overlay",
                      str(tmp_path / "ov"))) == 0
    records = [json.loads(line) for line in out.read_text().splitlines()]
    assert [r["frame"] for r in records] == [f"00000{i}.png" for i in range(5)]
    status = {r["frame"]: (r["valid"], r["status"]) for r in records}
    assert status["000000.png"] == (True, "ok")
    assert status["000001.png"] == (False, "bad_input")
    assert status["000002.png"] == (False, "bad_input")
    assert status["000003.png"] == (False, "no_target")
    assert status["000004.png"][0] is True
    for r in records:
        assert set(r) >= {"frame", "valid", "status", "R", "t", "q_wxyz", "confidence", "timings_ms", "tracked"}
        assert len(r["R"]) == 3 and len(r["t"]) == 3 and len(r["q_wxyz"]) == 4
    for r in records:   # the target's position: with every valid pose, else only on an undecided (weak_votes) frame
        assert len(r["position"]) == 3 and (r["position_valid"] or not r["valid"])
        assert not r["position_valid"] or r["valid"] or r["status"] == "weak_votes"
    rows = list(csv.reader((tmp_path / "p.csv").open()))
    assert rows[0][:3] == ["frame", "valid", "status"] and len(rows) == 6
    assert rows[0][-4:] == ["position_valid", "px", "py", "pz"]
    assert [row[-4] for row in rows[1:]] == [str(r["position_valid"]) for r in records]
    assert sorted(p.name for p in (tmp_path / "ov").iterdir()) == ["000000.png", "000003.png", "000004.png"]
    captured = capsys.readouterr()
    assert "5/5" in captured.err and "2 valid" in captured.out
    assert f"{sum(r['position_valid'] for r in records)} target positions" in captured.out


def test_refuses_to_overwrite(setup, tmp_path, capsys):
    root, seq, bundle = setup
    out = tmp_path / "poses.jsonl"
    out.write_text("keep me\n")
    assert main(_args(root, seq, bundle, out)) == 2
    assert out.read_text() == "keep me\n"
    assert "--force" in capsys.readouterr().err
    assert main(_args(root, seq, bundle, out, "--force")) == 0
    assert len(out.read_text().splitlines()) == 5


def test_refuses_non_empty_overlay(setup, tmp_path):
    root, seq, bundle = setup
    (tmp_path / "ov").mkdir()
    (tmp_path / "ov" / "x.png").write_bytes(b"")
    assert main(_args(root, seq, bundle, tmp_path / "p.jsonl", "--overlay", str(tmp_path / "ov"))) == 2
    assert not (tmp_path / "p.jsonl").exists()


def test_folder_without_right(setup, tmp_path, capsys):
    root, _, bundle = setup
    (tmp_path / "seq" / "left").mkdir(parents=True)
    assert main(_args(root, tmp_path / "seq", bundle, tmp_path / "p.jsonl")) == 2
    assert "right/" in capsys.readouterr().err


def test_prior_max_gap_option(setup, tmp_path, capsys, monkeypatch):
    root, seq, bundle = setup
    import spacepose.estimator as est_mod

    seen = []
    real_init = est_mod.PoseEstimator.__init__

    def spy(self, *args, **kwargs):
        seen.append(kwargs.get("prior_max_gap", "default"))
        real_init(self, *args, **kwargs)

    monkeypatch.setattr(est_mod.PoseEstimator, "__init__", spy)
    assert main(_args(root, seq, bundle, tmp_path / "a.jsonl", "--prior-max-gap", "0")) == 0
    assert main(_args(root, seq, bundle, tmp_path / "b.jsonl")) == 0
    assert seen == [0, "default"]
    with pytest.raises(SystemExit):
        main(_args(root, seq, bundle, tmp_path / "c.jsonl", "--prior-max-gap", "-1"))
    assert ">= 0" in capsys.readouterr().err and not (tmp_path / "c.jsonl").exists()


def test_prior_window_option(setup, tmp_path, monkeypatch):
    """--prior-window brings back the window from the previous pose; by default every frame runs the coarse pass."""
    root, seq, bundle = setup
    import spacepose.estimator as est_mod

    seen = []
    real_init = est_mod.PoseEstimator.__init__

    def spy(self, *args, **kwargs):
        real_init(self, *args, **kwargs)
        seen.append(self.prior_window)

    monkeypatch.setattr(est_mod.PoseEstimator, "__init__", spy)
    assert main(_args(root, seq, bundle, tmp_path / "a.jsonl", "--prior-window")) == 0
    assert main(_args(root, seq, bundle, tmp_path / "b.jsonl")) == 0
    assert seen == [True, False]
