"""tools.sequence: a tumbling sequence renders as a CLI folder with its labels, and runs in order."""

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

pytest.importorskip("trimesh")

from spacepose.metrics import rotation_error_deg  # noqa: E402
from spacepose.tools.sequence import _longest_run, evaluate_sequence, main, render_sequence, tumble  # noqa: E402


def test_tumble_turns_by_the_rate_about_one_axis():
    R0 = Rotation.random(random_state=0).as_matrix()
    Rs = tumble(R0, np.array([0.0, 1.0, 1.0]), 3.0, 5)
    np.testing.assert_allclose(Rs[0], R0, atol=1e-12)
    for a, b in zip(Rs[:-1], Rs[1:]):
        assert rotation_error_deg(a, b) == pytest.approx(3.0, abs=1e-6)
    step = Rs[1] @ R0.T
    axis = Rotation.from_matrix(step).as_rotvec()
    np.testing.assert_allclose(axis / np.linalg.norm(axis), np.array([0, 1, 1]) / np.sqrt(2), atol=1e-9)


def test_longest_run():
    assert _longest_run([]) == 0
    assert _longest_run([True, False, True, True, False, True]) == 2


def test_render_and_evaluate_a_short_sequence(tmp_path, capsys):
    out = render_sequence(tmp_path / "seq", frames=3, distance_m=20.0, rate_deg=5.0, size=(160, 120), seed=3)
    labels = [json.loads(line) for line in (out / "labels.jsonl").read_text().splitlines()]
    assert [r["frame"] for r in labels] == ["000000", "000001", "000002"]
    assert all(abs(r["t"][2] - 20.0) < 1e-9 for r in labels)
    assert rotation_error_deg(np.array(labels[0]["R"]), np.array(labels[2]["R"])) == pytest.approx(10.0, abs=1e-6)
    assert sorted(p.name for p in (out / "left").iterdir()) == ["000000.png", "000001.png", "000002.png"]
    assert (out / "rig.yaml").is_file()
    with pytest.raises(Exception, match="exists"):
        render_sequence(out, frames=1)
    report = evaluate_sequence(out, threads=1)    # the shipped bundle, run in order with use_prior
    s = report["summary"]
    assert s["frames"] == 3 and 0 <= s["valid"] <= 3 and s["flips"] <= s["valid"]
    assert {"status", "tracked", "e_t", "e_R", "flip_margin", "e_pos", "e_pos_los", "depth_tolerance_m",
            "sigma_range_m", "sigma_rotation_deg", "polish_deg", "polish_m"} <= set(report["frames"][0])
    for r in report["frames"]:   # the line-of-sight part of the centre's miss is a part of it
        assert (r["position_valid"] and abs(r["e_pos_los"]) <= r["e_pos"] + 1e-12) or (
            not r["position_valid"] and np.isnan(r["e_pos"]))
    assert main(["eval", str(out), "--threads", "1", "--json", str(tmp_path / "r.json"), "--prior-max-gap", "0"]) == 0
    assert json.loads((tmp_path / "r.json").read_text())["summary"]["frames"] == 3
    assert "summary:" in capsys.readouterr().out


def test_render_with_another_rig(tmp_path):
    from spacepose.calibration.rig import StereoRig, load_rig, save_rig

    K = np.array([[250.0, 0.0, 79.5], [0.0, 250.0, 59.5], [0.0, 0.0, 1.0]])
    rig = StereoRig(K, np.zeros(5), K, np.zeros(5), np.eye(3), np.array([-0.5, 0.0, 0.0]), (160, 120))
    save_rig(rig, tmp_path / "short.yaml")
    assert main(["render", str(tmp_path / "seq"), "--frames", "1", "--distance", "30", "--rig",
                 str(tmp_path / "short.yaml")]) == 0
    assert load_rig(tmp_path / "seq" / "rig.yaml").allclose(rig)
    out = render_sequence(tmp_path / "seq2", frames=1, distance_m=30.0, size=(80, 60), rig=rig)
    half = load_rig(out / "rig.yaml")
    assert half.image_size == (80, 60) and half.baseline_m == pytest.approx(0.5)
