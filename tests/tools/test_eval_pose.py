"""eval_pose: aggregation maths, overlays, and the full pipeline on a tiny rendered dataset."""

from __future__ import annotations

import argparse
import json
import sys
import types
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))  # --import-mode=importlib: find the helpers
from _pose_fixtures import make_pose_bundle, pose_dataset, train_tiny  # noqa: E402

from spacepose.tools.eval_pose import (confidence_table, distance_bin, draw_box_overlay, evaluate_pose,  # noqa: E402
                                       format_tables, summarise, write_report)


def row(valid=True, e_t=0.1, e_R=1.0, conf=0.5, regime="sun", distance=15.0):
    return {"valid": valid, "e_t": e_t if valid else float("nan"), "e_R": e_R if valid else float("nan"),
            "add": 0.2 if valid else float("nan"), "speed": 0.01 if valid else float("nan"), "confidence": conf,
            "status": "ok" if valid else "weak_votes", "regime": regime, "distance": distance}


class TestAggregation:
    def test_summarise(self):
        rows = [row(e_t=0.1, e_R=1.0), row(e_t=0.3, e_R=179.0), row(valid=False), row(e_t=0.2, e_R=2.0)]
        s = summarise(rows)
        assert s["frames"] == 4 and s["valid"] == 3 and s["valid_fraction"] == 0.75
        assert s["e_t_mean"] == pytest.approx(0.2) and s["e_t_median"] == pytest.approx(0.2)
        assert s["e_R_median"] == pytest.approx(2.0) and s["flips"] == 1
        assert s["statuses"] == {"ok": 3, "weak_votes": 1}
        empty = summarise([row(valid=False)])
        assert empty["valid"] == 0 and np.isnan(empty["e_t_mean"])
        # e_R up to the declared flip: the flipped pose counts by its distance to the label's flip
        sym = summarise([dict(row(e_R=179.0), e_R_sym=1.0), dict(row(e_R=3.0), e_R_sym=3.0)])
        assert sym["e_R_sym_median"] == pytest.approx(2.0) and sym["flips"] == 1
        assert np.isnan(s["e_R_sym_median"])   # rows without it (a baseline) give NaN, not an error

    def test_position_without_attitude(self):
        """Frames with a usable target position (valid or not): their share, e_pos statistics and the share
        within the frame's depth tolerance; rows without the keys (a baseline) count no position."""
        rows = [dict(row(), position_valid=True, e_pos=0.1, e_pos_los=0.1, depth_tolerance_m=0.5),
                dict(row(valid=False), position_valid=True, e_pos=0.9, e_pos_los=-0.3, depth_tolerance_m=0.5),
                dict(row(valid=False), position_valid=False, e_pos=float("nan"), e_pos_los=float("nan"),
                     depth_tolerance_m=float("nan")),
                dict(row(valid=False), position_valid=True, e_pos=0.2, e_pos_los=0.05, depth_tolerance_m=0.5)]
        s = summarise(rows)
        assert s["position_valid"] == 3 and s["position_fraction"] == 0.75 and s["valid"] == 1
        assert s["e_pos_mean"] == pytest.approx(0.4) and s["e_pos_median"] == pytest.approx(0.2)
        assert s["e_pos_max"] == pytest.approx(0.9) and s["e_pos_within_tolerance"] == pytest.approx(2 / 3)
        assert s["e_pos_los_mean"] == pytest.approx(-0.05)   # the range bias
        base = summarise([row(), row(valid=False)])
        assert base["position_valid"] == 0 and np.isnan(base["e_pos_mean"])

    def test_confidence_table_highest_first(self):
        rows = [row(conf=c, e_t=1.0 - c) for c in np.linspace(0.1, 0.9, 8)] + [row(valid=False, conf=0.0)]
        table = confidence_table(rows, n_bins=4)
        assert [b["frames"] for b in table] == [2, 2, 2, 2]
        assert table[0]["confidence_min"] > table[-1]["confidence_max"]
        assert table[0]["e_t_median"] < table[-1]["e_t_median"]
        # the mean confidence and the share within the pose bar (0.10 m and 2 degrees), per bin
        assert table[0]["confidence_mean"] == pytest.approx(np.mean(np.linspace(0.1, 0.9, 8)[-2:]))
        assert [b["within_bar"] for b in table] == [0.5, 0.0, 0.0, 0.0]   # e_t 0.10 and 0.21 in the top bin

    def test_distance_bins(self):
        assert distance_bin(10.0) == "10-20m" and distance_bin(49.9) == "40-50m" and distance_bin(23.5) == "20-30m"

    def test_overlay_draws_box(self):
        img = np.zeros((120, 160, 3), np.uint8)
        K = np.array([[200.0, 0, 79.5], [0, 200.0, 59.5], [0, 0, 1]])
        corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
        out = draw_box_overlay(img, K, corners, [(np.eye(3), np.array([0, 0, 15.0]), (0, 255, 0)),
                                                 (np.full((3, 3), np.nan), np.zeros(3), (255, 255, 255))])
        assert out[..., 1].max() > 0 and out[..., 0].max() == 0 and img.max() == 0


def test_full_pipeline_with_baseline(tmp_path_factory, tmp_path, monkeypatch, capsys):
    pytest.importorskip("torch")
    root = pose_dataset(tmp_path_factory)
    ckpt = train_tiny(root, tmp_path / "run", steps=1)
    bundle = make_pose_bundle(tmp_path / "bundle", ckpt)

    fake = types.ModuleType("spacepose.tools.classical_pose")
    fake.estimate_classical = lambda left, right, K, baseline_m, pts, normals: types.SimpleNamespace(
        R=np.eye(3), t=np.array([0.0, 0.0, 15.0]), valid=True)
    fake.model_cloud = lambda target, n=20000, seed=0: (np.zeros((10, 3)), np.tile([0.0, 0.0, 1.0], (10, 1)))
    monkeypatch.setitem(sys.modules, "spacepose.tools.classical_pose", fake)

    from spacepose.tools import cli_eval_pose

    parser = argparse.ArgumentParser()
    cli_eval_pose.add_arguments(parser)
    out = tmp_path / "eval"
    args = parser.parse_args([str(root), "--bundle", str(bundle), "--out", str(out), "--baseline", "classical",
                              "--overlays", "1", "--refine"])
    assert cli_eval_pose.run(args) == 0
    report = json.loads((out / "pose_eval.json").read_text())
    n_test = sum(1 for l in (root / "labels.jsonl").read_text().splitlines() if '"split": "test"' in l)
    assert report["ours"]["overall"]["frames"] == n_test and report["refine"] is True
    assert all("flip_margin" in f for f in report["frames"])
    assert report["baseline"]["overall"]["valid"] == n_test           # the fake baseline is always valid
    assert report["baseline"]["overall"]["e_t_mean"] >= 0.0
    for f in report["frames"]:
        assert f["status"] in ("ok", "no_target", "too_few_points", "weak_votes", "fit_residual", "out_of_range")
        assert (f["decided_by"] != "") == f["valid"]   # what picked a valid pose from its flip; "" otherwise
        assert f["position_valid"] or not f["valid"]     # a valid pose always has its position
        assert np.isfinite(f["e_pos"]) == f["position_valid"]
        assert np.isfinite(f["e_pos_los"]) == f["position_valid"] and not abs(f["e_pos_los"]) > f["e_pos"] + 1e-9
    assert (out / "fig14_errors_vs_distance.png").is_file() and (out / "pose_eval.md").is_file()
    assert [p.suffix for p in (out / "overlays").iterdir()] == [".jpg"]
    assert "baseline (classical)" in capsys.readouterr().out
    # --skip leaves out the first frames of the split (frames a calibration used)
    from spacepose.errors import DatasetError

    last = evaluate_pose(root, bundle, skip=n_test - 1, overlays=0, threads=1)
    assert [f["frame"] for f in last["frames"]] == [report["frames"][-1]["frame"]]
    with pytest.raises(DatasetError, match="no frames"):
        evaluate_pose(root, bundle, skip=n_test, overlays=0, threads=1)
    with pytest.raises(ValueError, match="skip"):
        evaluate_pose(root, bundle, skip=-1, overlays=0, threads=1)
