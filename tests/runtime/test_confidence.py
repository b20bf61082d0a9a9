"""Tests of spacepose.confidence: the probability of a tolerance from the uncertainty, its recalibration,
the bundle section and the estimator's confidence."""

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parent))  # --import-mode=importlib: find the helpers

from spacepose.bundle import load_bundle  # noqa: E402
from spacepose.confidence import (ConfidenceConfig, calibrated_confidence, parse_confidence,  # noqa: E402
                                  position_within_probability, rotation_within_probability, within_probability)
from spacepose.errors import BundleError  # noqa: E402

SECTION = {"position_m": 0.1, "rotation_deg": 2.0, "bias": 1.6, "slope": 1.3}
CONFIG = ConfidenceConfig(**SECTION)


@pytest.mark.parametrize("sigma,radius", [(0.05, 0.1), (0.2, 0.1), (0.01, 0.1), (1.0, 0.05)])
def test_an_isotropic_position_gives_the_chi_square_3_probability(sigma, radius):
    expected = stats.chi2(3).cdf((radius / sigma) ** 2)
    assert position_within_probability(sigma, sigma, radius) == pytest.approx(expected, abs=1e-6)


@pytest.mark.parametrize("s_range,s_lat,radius", [(0.3, 0.02, 0.1), (0.01, 0.2, 0.1), (0.08, 0.03, 0.1),
                                                  (0.5, 0.5, 2.0), (0.002, 0.06, 0.1), (0.2, 0.001, 0.1)])
def test_an_anisotropic_position_matches_sampling(s_range, s_lat, radius):
    rng = np.random.default_rng(7)
    x = rng.normal(size=(400_000, 3)) * np.array([s_range, s_lat, s_lat])
    sampled = float(np.mean(np.linalg.norm(x, axis=1) <= radius))
    assert position_within_probability(s_range, s_lat, radius) == pytest.approx(sampled, abs=3e-3)


def test_a_very_short_range_sigma_leaves_the_two_cross_range_axes():
    assert position_within_probability(1e-6, 0.05, 0.1) == pytest.approx(stats.chi2(2).cdf((0.1 / 0.05) ** 2),
                                                                          abs=1e-6)


@pytest.mark.parametrize("sigma,tol", [(0.5, 2.0), (1.0, 2.0), (3.0, 2.0), (20.0, 2.0), (0.05, 2.0)])
def test_the_rotation_probability_is_the_chi_3_distribution(sigma, tol):
    assert rotation_within_probability(sigma, tol) == pytest.approx(stats.chi(3).cdf(tol / sigma), abs=1e-9)


@pytest.mark.parametrize("args", [(0.0, 0.1, 0.1), (0.1, -1.0, 0.1), (0.1, 0.1, 0.0), (float("nan"), 0.1, 0.1),
                                  (0.1, float("inf"), 0.1)])
def test_position_inputs_must_be_finite_and_positive(args):
    with pytest.raises(ValueError):
        position_within_probability(*args)


@pytest.mark.parametrize("args", [(0.0, 2.0), (1.0, 0.0), (float("nan"), 2.0)])
def test_rotation_inputs_must_be_finite_and_positive(args):
    with pytest.raises(ValueError):
        rotation_within_probability(*args)


def test_the_probability_falls_as_any_sigma_grows():
    base = within_probability(0.05, 0.02, 1.0, CONFIG)
    assert 0.0 < base < 1.0
    assert within_probability(0.10, 0.02, 1.0, CONFIG) < base
    assert within_probability(0.05, 0.04, 1.0, CONFIG) < base
    assert within_probability(0.05, 0.02, 2.0, CONFIG) < base


def test_the_recalibration_is_the_identity_at_bias_0_slope_1_and_monotone():
    identity = ConfidenceConfig(position_m=0.1, rotation_deg=2.0, bias=0.0, slope=1.0)
    for p in (0.01, 0.3, 0.5, 0.9, 0.999):
        assert calibrated_confidence(p, identity) == pytest.approx(p, rel=1e-9)
    values = [calibrated_confidence(p, CONFIG) for p in np.linspace(0.0, 1.0, 101)]
    assert all(b > a for a, b in zip(values, values[1:-1]))      # strictly rising (p = 1 clips like 1 - 1e-6)
    assert 0.0 < values[0] < values[-1] < 1.0                   # clipped: never exactly 0 or 1, no overflow
    steep = ConfidenceConfig(position_m=0.1, rotation_deg=2.0, bias=-500.0, slope=50.0)
    assert 0.0 <= calibrated_confidence(0.0, steep) <= calibrated_confidence(1.0, steep) <= 1.0
    with pytest.raises(ValueError):
        calibrated_confidence(float("nan"), CONFIG)


@pytest.mark.parametrize("changes,match", [({"position_m": 0.0}, "position_m"), ({"rotation_deg": -1.0}, "rotation_deg"),
                                           ({"slope": 0.0}, "slope"), ({"bias": float("nan")}, "bias"),
                                           ({"bias": True}, "bias"), ({"min_valid": -0.01}, "min_valid"),
                                           ({"min_valid": 1.0}, "min_valid"), ({"min_valid": True}, "min_valid")])
def test_bad_constants_are_refused(changes, match):
    with pytest.raises(ValueError, match=match):
        ConfidenceConfig(**{**SECTION, **changes})


@pytest.mark.parametrize("section,match", [([1, 2], "must be an object"), ({**SECTION, "extra": 1}, "unknown keys"),
                                           ({"position_m": 0.1}, "lacks"), ({**SECTION, "slope": "1"}, "slope"),
                                           ({**SECTION, "slope": -1.0}, "slope")])
def test_malformed_sections_are_refused(section, match):
    with pytest.raises(BundleError, match=match):
        parse_confidence(section)


def test_an_absent_section_is_none_and_a_good_one_parses():
    assert parse_confidence(None) is None
    assert parse_confidence(dict(SECTION)) == CONFIG
    assert CONFIG.min_valid == 0.0                       # the floor is optional and off by default
    assert parse_confidence({**SECTION, "min_valid": 0.08}).min_valid == 0.08
    with pytest.raises(BundleError, match="min_valid"):
        parse_confidence({**SECTION, "min_valid": 1.5})


def test_the_bundle_section_needs_the_uncertainty_section(tmp_path):
    from _bundle_fixtures import make_bundle

    folder = make_bundle(tmp_path / "plain", manifest_overrides={"confidence": SECTION})
    with pytest.raises(BundleError, match="needs an uncertainty section"):
        load_bundle(folder)
    assert load_bundle(make_bundle(tmp_path / "none")).confidence is None


UNCERTAINTY = {"range_k": 0.3, "lateral_px": 0.5, "lateral_floor_m": 0.02, "rotation_k_deg": 20.0,
               "rotation_floor_deg": 0.0, "rotation_chamfer_deg": 1.5}


def _estimator(tmp_path, monkeypatch, more=None):
    """test_uncertainty's estimator (its registration decides a valid pose, with UNCERTAINTY) with ``more``
    sections added to the bundle."""
    from test_uncertainty import _estimator as uncertainty_estimator

    return uncertainty_estimator(tmp_path, monkeypatch, UNCERTAINTY, more)


def test_a_valid_pose_reports_the_probability_and_keeps_its_decision(tmp_path, monkeypatch):
    import spacepose.estimator as estimator_module
    from _bundle_fixtures import synthetic_pair
    from test_flip_classifier import _decision

    left, right = synthetic_pair()
    results = {}
    for name, more in (("off", None), ("on", {"confidence": SECTION})):
        est = _estimator(tmp_path / name, monkeypatch, more)
        monkeypatch.setattr(estimator_module, "decide_outline", _decision(est, {}, 1.2, 0.3))
        results[name] = est.estimate(left, right)
    off, on = results["off"], results["on"]
    assert off.valid and on.valid, (off.detail, on.detail)
    # the decision is the same: the section changes the reported confidence only
    assert np.array_equal(on.R, off.R) and np.array_equal(on.t, off.t) and on.status == off.status
    assert np.array_equal(on.position_cov, off.position_cov)
    assert on.decision_confidence == off.decision_confidence == off.confidence
    # the confidence, recomputed from the reported covariance and rotation sigma
    u = on.position / np.linalg.norm(on.position)
    s_range = math.sqrt(u @ on.position_cov @ u)
    s_lat = math.sqrt((np.trace(on.position_cov) - s_range ** 2) / 2.0)
    expected = calibrated_confidence(within_probability(s_range, s_lat, on.sigma_rotation_deg, CONFIG), CONFIG)
    assert on.confidence == pytest.approx(expected, rel=1e-9)
    assert on.confidence != pytest.approx(off.confidence)
    line = json.loads(json.dumps(on.to_dict("f")))
    assert line["confidence"] == pytest.approx(expected, rel=1e-9)


def test_a_valid_pose_without_a_rotation_sigma_claims_no_accuracy(tmp_path, monkeypatch):
    import spacepose.estimator as estimator_module
    from _bundle_fixtures import synthetic_pair
    from test_flip_classifier import _decision

    from spacepose.uncertainty import PoseUncertainty

    left, right = synthetic_pair()
    est = _estimator(tmp_path, monkeypatch, {"confidence": SECTION})
    monkeypatch.setattr(estimator_module, "decide_outline", _decision(est, {}, 1.2, 0.3))
    original = estimator_module.pose_uncertainty

    def no_rotation(*args, **kwargs):
        spread = original(*args, **kwargs)
        return PoseUncertainty(spread.position_cov, spread.sigma_range_m, spread.sigma_lateral_m, float("nan"))

    monkeypatch.setattr(estimator_module, "pose_uncertainty", no_rotation)
    res = est.estimate(left, right)
    assert res.valid and res.confidence == 0.0 and np.all(np.isfinite(res.position_cov))

    def zero_rotation(*args, **kwargs):   # constants without a rotation term and a chamfer of 0: sigma 0
        spread = original(*args, **kwargs)
        return PoseUncertainty(spread.position_cov, spread.sigma_range_m, spread.sigma_lateral_m, 0.0)

    monkeypatch.setattr(estimator_module, "pose_uncertainty", zero_rotation)
    res = est.estimate(left, right)
    assert res.valid and res.confidence == 0.0
    res = est.estimate(np.zeros_like(left), np.zeros_like(right))   # eclipse: no pose, no confidence
    assert not res.valid and res.confidence == 0.0 and res.decision_confidence == 0.0


def test_a_pose_under_the_floor_is_refused_and_not_the_next_prior(tmp_path, monkeypatch):
    import spacepose.estimator as estimator_module
    from _bundle_fixtures import synthetic_pair
    from test_flip_classifier import _decision

    left, right = synthetic_pair()

    def run(name, floor, registration=None):
        section = {**SECTION, "min_valid": floor} if floor is not None else SECTION
        more = {"confidence": section, **({"registration": registration} if registration else {})}
        est = _estimator(tmp_path / name, monkeypatch, more)
        monkeypatch.setattr(estimator_module, "decide_outline", _decision(est, {}, 1.2, 0.3))
        return est, est.estimate(left, right)

    _, free = run("free", None)
    assert free.valid, free.detail
    c = free.confidence
    assert 0.0 < c < 0.9
    # a floor under the pose's confidence changes nothing
    est, low = run("low", 0.5 * c)
    assert low.valid and np.array_equal(low.R, free.R) and low.confidence == c and est._prior is low
    # a floor over it: invalid, weak_votes, the reason in the detail, nothing of the pose reported, no prior
    est, high = run("high", 0.5 * (c + 1.0))
    assert (high.valid, high.status, high.confidence, high.decision_confidence) == (False, "weak_votes", 0.0, 0.0)
    assert "min_valid" in high.detail and f"{c:.3f}" in high.detail
    assert np.all(np.isnan(high.R)) and np.all(np.isnan(high.t)) and np.all(np.isnan(high.q_wxyz))
    assert high.decided_by == "" and not high.tracked and np.isnan(high.sigma_rotation_deg)
    assert est._prior is None
    # without the registration's position gate (the default) there is no position either ...
    assert not high.position_valid and np.all(np.isnan(high.position))
    line = json.loads(json.dumps(high.to_dict("f")))
    assert line["valid"] is False and line["R"][0] == [None, None, None] and line["confidence"] == 0.0
    # ... with it, the position a frame without a decision reports, near the refused pose's centre
    _, placed = run("placed", 0.5 * (c + 1.0), {"min_margin": 0.0, "position_max_tau_m": 9.0})
    assert not placed.valid and placed.status == "weak_votes" and placed.position_valid
    assert np.linalg.norm(placed.position - free.position) < 0.5


def test_the_shipped_bundle_has_the_floor_of_session_34():
    """reports/floor_s34/rule2.txt shipped confidence.min_valid 0.08 with session 19's stereo graph."""
    assert load_bundle(None, verify_graphs=False).confidence.min_valid == 0.08
