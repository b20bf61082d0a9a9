"""Tests of spacepose.tools.calibrate_photo and the Table 4 formatter of spacepose.tools.ablate_stereo."""

import numpy as np
import pytest

from spacepose.tools.calibrate_photo import perturbations, summarise


def test_perturbations_start_with_the_true_pose_and_move_it():
    R, t = np.eye(3), np.array([1.0, 2.0, 30.0])
    poses = perturbations(R, t, diameter=5.0)
    assert next(iter(poses)) == "true" and poses["true"][1] is t
    np.testing.assert_allclose(poses["depth+10%"][1], t * 1.1)
    np.testing.assert_allclose(poses["depth-20%"][1], t * 0.8)
    np.testing.assert_allclose(poses["shift 0.5D"][1], t + [2.5, 0, 0])
    for axis in "xyz":
        R_flip = poses[f"flip180 {axis}"][0]
        np.testing.assert_allclose(R_flip @ R_flip.T, np.eye(3), atol=1e-12)
        assert np.trace(R_flip) == pytest.approx(-1.0) and np.linalg.det(R_flip) == pytest.approx(1.0)


def test_summarise_threshold_and_rejections():
    rows = [{"frame": str(i), "regime": "sun" if i % 2 else "mixed", "distance": 20.0, "patches": 100,
             "true": 0.5 + 0.01 * i, "depth+10%": 0.1 * (i % 7), "flip180": None,
             "fitness": {"true": 0.9, "depth+10%": 0.5, "flip180": 0.88}} for i in range(50)]
    out = summarise(rows, quantile=0.1)
    true = np.array([r["true"] for r in rows])
    assert out["threshold"] == pytest.approx(np.quantile(true, 0.1))
    table = {r["pose"]: r for r in out["table"]}
    assert table["true"]["rejected"] == pytest.approx(np.mean(true < out["threshold"]))
    depth = np.array([r["depth+10%"] for r in rows])
    assert table["depth+10%"]["rejected"] == pytest.approx(np.mean(depth < out["threshold"]))
    assert table["flip180"]["unverifiable"] == 50 and np.isnan(table["flip180"]["rejected"])
    assert table["flip180"]["fitness_within_005_of_true"] == 1.0 and table["depth+10%"]["fitness_within_005_of_true"] == 0.0
    assert set(out["per_regime_true"]) == {"sun", "mixed"}


def test_table4_format_and_variant_check():
    from spacepose.tools.ablate_stereo import format_table, main

    row = {"variant": "ta", "params_m": 1.0, "steps": 10, "epe": 2.5, "d1": 10.0, "bad1": 30.0, "bad3": 12.0,
           "latency_ms_median": 500.0, "sgbm": {"epe": 4.0, "d1": 9.0}}
    text = format_table([row])
    assert "| ta | √ |  |" in text and "StereoSGBM" in text and "2.50" in text
    with pytest.raises(SystemExit):
        main(["data", "--variants", "bogus"])


def test_bench_time_calls_counts_every_timed_call():
    from spacepose.tools.bench_graphs import time_calls

    seen = []
    out = time_calls(seen.append, [1, 2, 3], repeats=2)
    assert out["calls"] == 6 and len(seen) == 9  # one warm-up pass, then two timed passes
    assert out["median_ms"] >= 0 and out["p95_ms"] >= out["median_ms"] - 1e-9
