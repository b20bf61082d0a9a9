"""Tests of spacepose.tools.calibrate_uncertainty and the sigmas eval-pose records."""

import json
import math
import types

import numpy as np
import pytest

from spacepose.confidence import ConfidenceConfig, calibrated_confidence
from spacepose.tools.calibrate_uncertainty import (GATE_PROBABILITIES, NOMINAL, confidence_check, coverage,
                                                   fit_confidence, fit_position_uncertainty, fit_tail_dof,
                                                   fit_uncertainty, format_tail_check, main, nees_values,
                                                   normal_within, pose_errors, position_coverage, position_errors,
                                                   right_nees, tail_check, within_tolerance, wrong_poses)
from spacepose.uncertainty import PositionUncertaintyConfig, UncertaintyConfig, pose_uncertainty, position_uncertainty

TRUE = UncertaintyConfig(range_k=0.2, lateral_px=1.0, lateral_floor_m=0.02, rotation_k_deg=40.0, rotation_floor_deg=0.8,
                         rotation_chamfer_deg=1.5)
FOCAL = 800.0


def _rows(config, n=4000, seed=0, focal=FOCAL, tails=None):
    """eval-pose rows of valid poses whose errors are drawn from ``config``'s normal model (``tails``: Student-t
    degrees of freedom for heavier-tailed errors of the same variance), then one invalid row. ``e_t`` is the
    centre's miss: the translation error of a target whose centre is its origin."""
    rng = np.random.default_rng(seed)

    def draw(sigma, size=None):
        if tails is None:
            return rng.normal(0.0, sigma, size)
        return rng.standard_t(tails, size) * sigma * math.sqrt((tails - 2.0) / tails)

    rows = []
    for _ in range(n):
        z = rng.uniform(10.0, 50.0)
        tau = max(0.15, z ** 2 * 0.25 / (focal * 1.0))
        chamfer = rng.uniform(0.4, 2.5)
        spread = pose_uncertainty(np.array([0.0, 0.0, z]), tau, focal, config, chamfer)
        e_range = float(draw(spread.sigma_range_m))
        e_lat = np.linalg.norm(draw(spread.sigma_lateral_m, 2))
        e_R = np.linalg.norm(draw(spread.sigma_rotation_deg, 3))
        e_pos = math.hypot(e_range, e_lat)
        rows.append({"valid": True, "depth_tolerance_m": tau, "position": [0.0, 0.0, z + e_range],
                     "e_pos_los": e_range, "e_pos": e_pos, "e_t": e_pos, "e_R": e_R, "outline_chamfer_px": chamfer})
    rows.append({"valid": False, "depth_tolerance_m": float("nan"), "position": [float("nan")] * 3,
                 "e_pos_los": float("nan"), "e_pos": float("nan"), "e_t": float("nan"), "e_R": float("nan")})
    return rows


def test_the_fit_recovers_the_constants_of_a_normal_model():
    err = pose_errors(_rows(TRUE), FOCAL)
    assert len(err["range"]) == 4000          # the invalid row is left out
    fit = fit_uncertainty(err)
    assert fit.range_k == pytest.approx(TRUE.range_k, rel=0.1)
    assert fit.lateral_px == pytest.approx(TRUE.lateral_px, rel=0.15)
    assert fit.rotation_k_deg == pytest.approx(TRUE.rotation_k_deg, rel=0.2)
    assert fit.rotation_chamfer_deg == pytest.approx(TRUE.rotation_chamfer_deg, rel=0.2)
    assert fit.rotation_floor_deg == pytest.approx(TRUE.rotation_floor_deg, abs=0.6)
    cov = coverage(pose_errors(_rows(TRUE, seed=1), FOCAL), fit, FOCAL)
    for key, share in NOMINAL.items():
        assert cov[key] == pytest.approx(share, abs=0.04), key
    assert cov["wrong"] <= 8            # a normal's tails beyond 0.5 m / 20 degrees: about 0.1 % here
    assert cov["spearman_position"] > 0.2 and cov["spearman_rotation"] > 0.2


def test_wrong_poses_do_not_widen_the_fit_and_stand_out_of_it():
    rows = _rows(TRUE)
    before = pose_errors(rows, FOCAL)
    clean = fit_uncertainty(before)
    for r in rows[:60]:   # 1.5 % flips and 2 m misses
        r["e_R"], r["e_pos_los"], r["e_pos"] = 175.0, 2.0, 2.0
    err = pose_errors(rows, FOCAL)
    wrong = wrong_poses(err)
    assert wrong[:60].all() and wrong[60:].sum() == wrong_poses(before)[60:].sum()
    fit = fit_uncertainty(err)
    for key in ("range_k", "lateral_px", "rotation_k_deg", "rotation_chamfer_deg"):
        assert getattr(fit, key) == pytest.approx(getattr(clean, key), rel=0.05), key
    cov = coverage(err, clean, FOCAL)
    assert cov["wrong"] == wrong.sum() and cov["wrong_flagged"] > 0.9 and cov["right_flagged"] < 0.02
    for key in ("nees_range", "nees_lateral", "nees_rotation"):   # a consistent covariance: about 1 per axis
        assert cov[key] == pytest.approx(1.0, abs=0.1), key


def test_coverage_sees_sigmas_that_are_too_small():
    tight = UncertaintyConfig(range_k=0.1, lateral_px=0.3, lateral_floor_m=0.005, rotation_k_deg=10.0,
                              rotation_floor_deg=0.2, rotation_chamfer_deg=0.4)
    cov = coverage(pose_errors(_rows(TRUE), FOCAL), tight, FOCAL)
    assert cov["range_1"] < 0.4 and cov["lateral_1"] < 0.2 and cov["rotation_median"] < 0.3


def test_coverage_of_the_recorded_sigmas_matches_the_recomputed_one():
    rows = _rows(TRUE, n=300)
    for r in rows:
        if r["valid"]:
            spread = pose_uncertainty(np.asarray(r["position"]), r["depth_tolerance_m"], FOCAL, TRUE,
                                      r["outline_chamfer_px"])
            r.update(sigma_range_m=spread.sigma_range_m, sigma_lateral_m=spread.sigma_lateral_m,
                     sigma_rotation_deg=spread.sigma_rotation_deg)
    err = pose_errors(rows, FOCAL)
    assert coverage(err) == pytest.approx(coverage(err, TRUE, FOCAL), nan_ok=True)
    assert coverage(pose_errors(_rows(TRUE, n=30), FOCAL)) == {"poses": 0}   # no recorded sigmas


def test_too_few_poses_are_not_fitted():
    with pytest.raises(ValueError, match="too few"):
        fit_uncertainty(pose_errors(_rows(TRUE, n=10), FOCAL))


def test_the_command_fits_and_writes_json(tmp_path, capsys):
    report = tmp_path / "pose_eval.json"
    report.write_text(json.dumps({"focal_px": FOCAL, "frames": _rows(TRUE, n=600)}))
    out = tmp_path / "fit.json"
    assert main([str(report), "--fit", "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert set(data["fit"]) == {"range_k", "lateral_px", "lateral_floor_m", "rotation_k_deg", "rotation_floor_deg",
                                "rotation_chamfer_deg"}
    assert data["coverage"][str(report)]["poses"] == 600
    assert '"uncertainty"' in capsys.readouterr().out
    bare = tmp_path / "bare.json"
    bare.write_text(json.dumps({"frames": _rows(TRUE, n=100)}))
    with pytest.raises(SystemExit):
        main([str(bare), "--fit"])                     # no focal length known


def test_eval_pose_records_the_sigmas_along_and_across_the_line_of_sight():
    from spacepose.tools.eval_pose import predicted_sigmas

    position = np.array([2.0, 1.0, 20.0])
    spread = pose_uncertainty(position, 0.6, FOCAL, TRUE, 1.1)
    result = types.SimpleNamespace(position=position, position_cov=spread.position_cov,
                                   sigma_rotation_deg=spread.sigma_rotation_deg)
    got = predicted_sigmas(result)
    assert got["sigma_range_m"] == pytest.approx(spread.sigma_range_m)
    assert got["sigma_lateral_m"] == pytest.approx(spread.sigma_lateral_m)
    assert got["sigma_rotation_deg"] == pytest.approx(spread.sigma_rotation_deg)
    none = predicted_sigmas(types.SimpleNamespace(position=position, position_cov=np.full((3, 3), np.nan),
                                                  sigma_rotation_deg=float("nan")))
    assert all(math.isnan(v) for v in none.values())


TRUE_P = PositionUncertaintyConfig(range_k=0.25, range_chamfer_k=0.12, lateral_px=0.4, lateral_floor_m=0.01,
                                   lateral_chamfer_m=0.035)


def _position_rows(config, n=4000, seed=0, focal=FOCAL):
    """eval-pose rows of frames with a position and no pose, errors drawn from ``config``'s normal model, and
    valid poses (which position_errors leaves out)."""
    rng = np.random.default_rng(seed)
    rows = []
    for _ in range(n):
        z = rng.uniform(10.0, 50.0)
        tau = max(0.15, z ** 2 * 0.25 / (focal * 1.0))
        chamfer = rng.uniform(0.3, 3.0)
        spread = position_uncertainty(np.array([0.0, 0.0, z]), tau, focal, config, chamfer)
        e_range = rng.normal(0.0, spread.sigma_range_m)
        e_lat = np.linalg.norm(rng.normal(0.0, spread.sigma_lateral_m, 2))
        rows.append({"valid": False, "position_valid": True, "depth_tolerance_m": tau,
                     "position": [0.0, 0.0, z + e_range], "e_pos_los": e_range, "e_pos": math.hypot(e_range, e_lat),
                     "e_R": float("nan"), "outline_chamfer_px": chamfer})
    return rows + _rows(TRUE, n=50, seed=seed)


def test_the_position_fit_recovers_the_constants_of_a_normal_model():
    err = position_errors(_position_rows(TRUE_P), FOCAL)
    assert len(err["range"]) == 4000 and np.all(np.isnan(err["e_R"]))    # the valid poses are left out
    fit = fit_position_uncertainty(err)
    assert fit.range_k == pytest.approx(TRUE_P.range_k, rel=0.15)
    assert fit.range_chamfer_k == pytest.approx(TRUE_P.range_chamfer_k, rel=0.2)
    assert fit.lateral_chamfer_m == pytest.approx(TRUE_P.lateral_chamfer_m, rel=0.15)
    assert fit.lateral_px == pytest.approx(TRUE_P.lateral_px, rel=0.3)
    cov = position_coverage(position_errors(_position_rows(TRUE_P, seed=1), FOCAL), fit, FOCAL)
    assert cov["positions"] == 4000
    for key in ("range_1", "range_2", "lateral_1", "lateral_2"):
        assert cov[key] == pytest.approx(NOMINAL[key], abs=0.04), key
    assert cov["nees_range"] == pytest.approx(1.0, abs=0.1) and cov["nees_lateral"] == pytest.approx(1.0, abs=0.1)
    assert cov["spearman_position"] > 0.2


def test_far_off_positions_do_not_widen_the_position_fit_and_stand_out():
    rows = _position_rows(TRUE_P)
    clean = fit_position_uncertainty(position_errors(rows, FOCAL))
    for r in rows[:60]:
        r["e_pos_los"], r["e_pos"] = 4.0, 5.0
    err = position_errors(rows, FOCAL)
    assert wrong_poses(err)[:60].all()
    fit = fit_position_uncertainty(err)
    assert fit.range_k == pytest.approx(clean.range_k, rel=0.05)
    assert fit.lateral_chamfer_m == pytest.approx(clean.lateral_chamfer_m, rel=0.05)
    cov = position_coverage(err, clean, FOCAL)
    # the 60 far off are all beyond the gate (so are a few of the model's own tails past 0.5 m)
    assert cov["wrong"] >= 60 and round(cov["wrong_flagged"] * cov["wrong"]) >= 60 and cov["right_flagged"] < 0.02
    tight = PositionUncertaintyConfig(0.1, 0.0, 0.0, 0.005, 0.01)
    assert position_coverage(err, tight, FOCAL)["range_1"] < 0.5
    assert position_coverage(position_errors(rows[:10], FOCAL)) == {"positions": 0}    # nothing recorded
    with pytest.raises(ValueError, match="too few"):
        fit_position_uncertainty(position_errors(rows[60:80], FOCAL))


def test_the_command_fits_the_positions(tmp_path, capsys):
    report = tmp_path / "pose_eval.json"
    report.write_text(json.dumps({"focal_px": FOCAL, "frames": _position_rows(TRUE_P, n=500)}))
    out = tmp_path / "fit.json"
    assert main([str(report), "--fit", "--positions", "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert set(data["fit"]) == {"range_k", "range_chamfer_k", "lateral_px", "lateral_floor_m", "lateral_chamfer_m"}
    assert data["coverage"][str(report)]["positions"] == 500
    assert '"position_uncertainty"' in capsys.readouterr().out


def test_the_eval_report_carries_both_coverages_from_the_recorded_sigmas():
    """eval-pose's grouped report and its markdown: the valid poses' coverage and the positions' (recorded sigmas)."""
    from spacepose.tools.eval_pose import _grouped, format_tables

    rows = []
    for r in _rows(TRUE, n=40) + _position_rows(TRUE_P, n=40)[:40]:
        r = dict(r, regime="sun", distance=20.0, e_t=0.1, add=0.1, speed=0.01, e_R_sym=1.0, status="x", confidence=0.5)
        r.setdefault("e_R", float("nan"))
        pos, tau, chamfer = np.asarray(r["position"]), r["depth_tolerance_m"], r.get("outline_chamfer_px", float("nan"))
        spread = (pose_uncertainty(pos, tau, FOCAL, TRUE, chamfer) if r["valid"]
                  else position_uncertainty(pos, tau, FOCAL, TRUE_P, chamfer) if r.get("position_valid") else None)
        r.update(sigma_range_m=float("nan"), sigma_lateral_m=float("nan"), sigma_rotation_deg=float("nan"))
        if spread is not None:
            r.update(sigma_range_m=spread.sigma_range_m, sigma_lateral_m=spread.sigma_lateral_m,
                     sigma_rotation_deg=spread.sigma_rotation_deg)
        rows.append(r)
    block = _grouped(rows)
    assert block["uncertainty"]["poses"] == 40 and block["position_uncertainty"]["positions"] == 40
    assert block["position_uncertainty"] == pytest.approx(
        position_coverage(position_errors(rows, FOCAL), TRUE_P, FOCAL), nan_ok=True)
    text = format_tables({"ours": block})
    assert "valid poses: 40 poses" in text and "positions without a pose: 40 positions without a pose" in text


# ------------------------------------------------------------------------------------------- confidence (session 30)
TOLERANCE = ConfidenceConfig(position_m=0.10, rotation_deg=2.0, bias=0.0, slope=1.0)


SMALL = UncertaintyConfig(range_k=0.1, lateral_px=0.5, lateral_floor_m=0.01, rotation_k_deg=20.0,
                          rotation_floor_deg=0.3, rotation_chamfer_deg=0.8)   # errors around the 0.10 m / 2 deg bar


def test_on_normal_errors_the_confidence_fit_is_the_identity_and_calibrated():
    err = pose_errors(_rows(SMALL, n=6000), FOCAL)
    p = normal_within(err, SMALL, FOCAL, TOLERANCE)
    within = within_tolerance(err, TOLERANCE)
    assert np.all(np.isfinite(p)) and 0.2 < within.mean() < 0.8
    fit = fit_confidence(p, within)
    assert fit.bias == pytest.approx(0.0, abs=0.15) and fit.slope == pytest.approx(1.0, abs=0.1)
    check = confidence_check(p, within, err["e_t"], err["e_R"])
    assert check["mean_confidence"] == pytest.approx(check["share_within"], abs=0.02)
    for b in check["bins"]:
        assert b["mean_confidence"] == pytest.approx(b["share_within"], abs=0.05)
    assert check["spearman_t"] < -0.2 and check["spearman_R"] < -0.2
    assert check["brier"] < check["brier_base"]


def test_heavy_tails_are_recalibrated_by_the_fit():
    err = pose_errors(_rows(SMALL, n=6000, tails=3.0, seed=1), FOCAL)
    p = normal_within(err, SMALL, FOCAL, TOLERANCE)
    within = within_tolerance(err, TOLERANCE)
    assert p.mean() < within.mean() - 0.05           # same variance, more mass near 0: the normal p is too low
    fit = fit_confidence(p, within)
    check_err = pose_errors(_rows(SMALL, n=6000, tails=3.0, seed=2), FOCAL)
    p2, within2 = normal_within(check_err, SMALL, FOCAL, TOLERANCE), within_tolerance(check_err, TOLERANCE)
    conf = np.array([calibrated_confidence(v, fit) for v in p2])
    raw, fitted = (confidence_check(c, within2, check_err["e_t"], check_err["e_R"]) for c in (p2, conf))
    assert abs(fitted["mean_confidence"] - fitted["share_within"]) < 0.02
    assert abs(raw["mean_confidence"] - raw["share_within"]) > 0.05
    assert fitted["brier"] < raw["brier"]


def test_the_confidence_fit_refuses_too_few_or_one_sided_poses():
    with pytest.raises(ValueError, match="too few"):
        fit_confidence(np.full(10, 0.5), np.ones(10, bool))
    with pytest.raises(ValueError, match="one side"):
        fit_confidence(np.full(100, 0.5), np.ones(100, bool))
    p = np.linspace(0.01, 0.99, 100)
    with pytest.raises(ValueError, match="converge"):
        fit_confidence(p, p > 0.5)                    # separable: the slope runs away


def test_the_confidence_check_counts_bins_and_rank_correlations():
    conf = np.array([0.9, 0.8, 0.2, 0.1, np.nan])
    within = np.array([True, True, False, False, True])
    e_t, e_R = np.array([0.01, 0.02, 0.3, 0.5, 9.0]), np.array([0.5, 0.7, 4.0, 9.0, 1.0])
    check = confidence_check(conf, within, e_t, e_R, n_bins=2)
    assert check["poses"] == 4                          # the NaN confidence is left out
    assert check["spearman_t"] == pytest.approx(-1.0) and check["spearman_R"] == pytest.approx(-1.0)
    assert [b["share_within"] for b in check["bins"]] == [0.0, 1.0]
    assert check["bins"][0]["mean_confidence"] == pytest.approx(0.15)
    assert check["brier"] == pytest.approx(np.mean([0.01, 0.04, 0.04, 0.01]))
    assert check["brier_base"] == pytest.approx(0.25)
    assert confidence_check(np.array([np.nan]), np.array([True]), e_t[:1], e_R[:1]) == {"poses": 0}


def test_the_command_fits_and_checks_the_confidence(tmp_path, capsys):
    from spacepose.bundle import load_bundle

    shipped = load_bundle(None, verify_graphs=False).uncertainty
    report = tmp_path / "pose_eval.json"
    report.write_text(json.dumps({"focal_px": FOCAL, "frames": _rows(shipped, n=800)}))
    out = tmp_path / "fit.json"
    assert main([str(report), "--confidence", "--fit", "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert set(data["fit"]) == {"position_m", "rotation_deg", "bias", "slope"}
    assert data["fit"]["position_m"] == 0.10 and data["fit"]["rotation_deg"] == 2.0
    assert data["check"][str(report)]["poses"] == 800
    assert '"confidence"' in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main([str(report), "--confidence", "--positions"])   # one of the two
    with pytest.raises(SystemExit):
        main([str(report), "--confidence", "--fit", "--tolerance", "0", "2"])   # a typed refusal, not a traceback
    few = tmp_path / "few.json"
    few.write_text(json.dumps({"focal_px": FOCAL, "frames": _rows(shipped, n=10)}))
    with pytest.raises(SystemExit):
        main([str(few), "--confidence", "--fit"])


def _multivariate_t_nees(nu, n, seed):
    """3-axis NEES values of Student-t errors with ``nu`` degrees of freedom and the covariance they are
    normalised by."""
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((n, 3)) * np.sqrt((nu - 2.0) / rng.chisquare(nu, (n, 1)))
    return np.sum(x ** 2, axis=1)


@pytest.mark.parametrize("nu", [3.0, 4.0, 8.0])
def test_the_tail_fit_recovers_the_degrees_of_freedom(nu):
    assert fit_tail_dof(_multivariate_t_nees(nu, 20_000, seed=int(nu))) == pytest.approx(nu, rel=0.1)


def test_normal_errors_fit_many_degrees_of_freedom_and_few_values_are_refused():
    assert fit_tail_dof(np.random.default_rng(0).chisquare(3, 20_000)) > 50.0
    with pytest.raises(ValueError):
        fit_tail_dof(np.ones(10))


def test_the_tail_check_counts_right_and_wrong_poses_beyond_each_gate():
    rows = _rows(TRUE, n=3000, seed=4, tails=3.0)
    err = pose_errors(rows, FOCAL)
    check = tail_check(err, TRUE, FOCAL, 3.0)
    assert check["right"] + check["wrong"] == check["poses"] == 3000
    for p in GATE_PROBABILITIES:
        t, chi2 = check["gates"][f"t_{p}"], check["gates"][f"chi2_{p}"]
        assert t["gate"] > chi2["gate"]
        assert t["right_position"] <= chi2["right_position"] and t["right_rotation"] <= chi2["right_rotation"]
    # heavy-tailed errors: chi-square's 99 % gate throws away several times 1 % of the right poses
    assert check["gates"]["chi2_0.99"]["right_position"] > 0.02
    d2_position, d2_rotation, right = nees_values(err, TRUE, FOCAL)
    assert len(d2_position) == len(d2_rotation) == len(right) == 3000
    assert len(right_nees([(err, FOCAL)], TRUE)) == 2 * int(right.sum())
    assert "chi-square" in format_tail_check("set", check)


def test_the_command_fits_and_checks_the_tails(tmp_path, capsys):
    from spacepose.bundle import load_bundle

    shipped = load_bundle(None, verify_graphs=False).uncertainty
    report = tmp_path / "pose_eval.json"
    report.write_text(json.dumps({"focal_px": FOCAL, "frames": _rows(shipped, n=1500, tails=4.0)}))
    out = tmp_path / "tails.json"
    assert main([str(report), "--tails", "--fit", "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert 2.0 < data["fit"]["tail_dof"] < 200.0
    assert data["check"][str(report)]["tail_dof"] == pytest.approx(data["fit"]["tail_dof"], abs=1e-3)
    assert '"tail_dof"' in capsys.readouterr().out
    assert main([str(report), "--tails"]) == 0          # the bundle's own tail_dof
    with pytest.raises(SystemExit):
        main([str(report), "--tails", "--confidence"])   # one of the two
    few = tmp_path / "few.json"
    few.write_text(json.dumps({"focal_px": FOCAL, "frames": _rows(shipped, n=5)}))
    with pytest.raises(SystemExit):
        main([str(few), "--tails", "--fit"])
