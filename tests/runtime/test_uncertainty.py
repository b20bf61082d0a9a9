"""Tests of spacepose.uncertainty and the estimator's per-frame position covariance and rotation sigma."""

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))  # --import-mode=importlib: find the helpers

from spacepose.bundle import load_bundle  # noqa: E402
from spacepose.errors import BundleError  # noqa: E402
from spacepose.uncertainty import (PositionUncertaintyConfig, UncertaintyConfig, parse_position_uncertainty,  # noqa: E402
                                   parse_uncertainty, pose_uncertainty, position_uncertainty)

SECTION = {"range_k": 0.3, "lateral_px": 1.2, "lateral_floor_m": 0.02, "rotation_k_deg": 80.0,
           "rotation_floor_deg": 0.5, "rotation_chamfer_deg": 1.5}
CONFIG = UncertaintyConfig(**SECTION)


def test_the_covariance_is_long_along_the_line_of_sight():
    position = np.array([3.0, -4.0, 30.0])
    spread = pose_uncertainty(position, 0.8, 800.0, CONFIG, 1.2)
    cov = spread.position_cov
    assert np.allclose(cov, cov.T)
    u = position / np.linalg.norm(position)
    # the line of sight is an eigenvector with sigma_range^2; every direction across it has sigma_lateral^2
    assert np.allclose(cov @ u, spread.sigma_range_m ** 2 * u)
    across = np.cross(u, [1.0, 0.0, 0.0])
    across /= np.linalg.norm(across)
    assert np.allclose(cov @ across, spread.sigma_lateral_m ** 2 * across)
    assert spread.sigma_range_m == pytest.approx(0.3 * 0.8)
    ratio = np.linalg.norm(position) / 800.0
    assert spread.sigma_lateral_m == pytest.approx(math.hypot(0.02, 1.2 * ratio))
    assert spread.sigma_rotation_deg == pytest.approx(math.sqrt(0.5 ** 2 + (80.0 * ratio) ** 2 + (1.5 * 1.2) ** 2))
    assert np.all(np.linalg.eigvalsh(cov) > 0)


def test_a_longer_focal_length_gives_smaller_sigmas_across_and_in_rotation():
    near = pose_uncertainty(np.array([0.0, 0.0, 40.0]), 1.0, 800.0, CONFIG, 1.0)
    sharp = pose_uncertainty(np.array([0.0, 0.0, 40.0]), 1.0, 1600.0, CONFIG, 1.0)
    assert sharp.sigma_range_m == near.sigma_range_m          # the range sigma follows tau (which holds f already)
    assert sharp.sigma_lateral_m < near.sigma_lateral_m
    assert sharp.sigma_rotation_deg < near.sigma_rotation_deg
    no_floor = UncertaintyConfig(0.3, 1.2, 0.0, 80.0, 0.0)
    a = pose_uncertainty(np.array([0.0, 0.0, 40.0]), 1.0, 800.0, no_floor)
    b = pose_uncertainty(np.array([0.0, 0.0, 40.0]), 1.0, 1600.0, no_floor)
    assert a.sigma_lateral_m == pytest.approx(2 * b.sigma_lateral_m)
    assert a.sigma_rotation_deg == pytest.approx(2 * b.sigma_rotation_deg)


@pytest.mark.parametrize("position, tau, focal", [
    ([0.0, 0.0, 0.0], 0.5, 800.0),          # no range
    ([np.nan, 0.0, 20.0], 0.5, 800.0),
    ([0.0, 0.0, 20.0], float("nan"), 800.0),  # no depth tolerance (no registration)
    ([0.0, 0.0, 20.0], 0.0, 800.0),
    ([0.0, 0.0, 20.0], 0.5, -1.0),
])
def test_no_uncertainty_without_finite_positive_inputs(position, tau, focal):
    assert pose_uncertainty(np.array(position), tau, focal, CONFIG) is None


def test_the_position_must_be_a_3_vector():
    from spacepose.errors import ShapeError

    with pytest.raises(ShapeError):
        pose_uncertainty(np.zeros(2), 0.5, 800.0, CONFIG)


@pytest.mark.parametrize("changes, match", [
    ({"range_k": 0.0}, "range_k must be > 0"),
    ({"lateral_px": -1.0}, "lateral_px must be finite and >= 0"),
    ({"rotation_k_deg": float("nan")}, "rotation_k_deg must be finite"),
    ({"lateral_px": 0.0, "lateral_floor_m": 0.0}, "singular"),
    ({"rotation_k_deg": 0.0, "rotation_floor_deg": 0.0, "rotation_chamfer_deg": 0.0}, "cannot all be 0"),
    ({"rotation_chamfer_deg": -0.1}, "rotation_chamfer_deg must be finite and >= 0"),
    ({"tail_dof": 2.0}, "tail_dof must be 0"),
    ({"tail_dof": 1.0}, "tail_dof must be 0"),
    ({"tail_dof": float("inf")}, "tail_dof must be finite"),
])
def test_bad_constants_are_refused(changes, match):
    with pytest.raises(ValueError, match=match):
        UncertaintyConfig(**{**SECTION, **changes})
    with pytest.raises(BundleError, match=match):
        parse_uncertainty({**SECTION, **changes})


@pytest.mark.parametrize("section, match", [
    ([1, 2], "must be an object"),
    ({**SECTION, "extra": 1.0}, "unknown keys"),
    ({k: v for k, v in SECTION.items() if k != "range_k"}, "lacks"),
    ({**SECTION, "rotation_chamfer_deg": None}, "must be a number"),
    ({**SECTION, "range_k": True}, "must be a number"),
    ({**SECTION, "range_k": "0.3"}, "must be a number"),
])
def test_malformed_sections_are_refused(section, match):
    with pytest.raises(BundleError, match=match):
        parse_uncertainty(section)


def test_an_absent_section_is_none():
    assert parse_uncertainty(None) is None
    assert parse_uncertainty(dict(SECTION)) == CONFIG
    without = {k: v for k, v in SECTION.items() if k != "rotation_chamfer_deg"}   # optional: no chamfer term
    assert parse_uncertainty(without).rotation_chamfer_deg == 0.0
    assert parse_uncertainty(dict(SECTION)).tail_dof == 0.0                      # optional: normal tails
    assert parse_uncertainty({**SECTION, "tail_dof": 3.5}).tail_dof == 3.5


def test_the_estimator_gives_the_gates_of_its_bundles_tails(tmp_path, monkeypatch):
    from spacepose.tails import nees_gate

    normal = _estimator(tmp_path / "n", monkeypatch, SECTION)
    assert normal.nees_gate(0.99) == pytest.approx(11.3449, abs=1e-4)          # chi-square, 3 axes
    heavy = _estimator(tmp_path / "t", monkeypatch, {**SECTION, "tail_dof": 3.6})
    assert heavy.nees_gate(0.99) == pytest.approx(nees_gate(0.99, 3, 3.6))
    assert heavy.nees_gate(0.99) > 2.0 * normal.nees_gate(0.99)
    assert _estimator(tmp_path / "none", monkeypatch, None).nees_gate(0.95) == pytest.approx(7.8147, abs=1e-4)
    with pytest.raises(ValueError):
        heavy.nees_gate(1.0)


def test_the_rotation_sigma_grows_with_the_outline_chamfer_and_needs_it():
    position = np.array([0.0, 0.0, 25.0])
    tight, loose = (pose_uncertainty(position, 0.5, 800.0, CONFIG, c) for c in (0.5, 2.5))
    assert loose.sigma_rotation_deg > tight.sigma_rotation_deg
    assert np.allclose(loose.position_cov, tight.position_cov)    # the position's does not depend on it
    unknown = pose_uncertainty(position, 0.5, 800.0, CONFIG)     # no chamfer: no rotation sigma, a position one
    assert math.isnan(unknown.sigma_rotation_deg) and np.all(np.isfinite(unknown.position_cov))
    plain = UncertaintyConfig(**{**SECTION, "rotation_chamfer_deg": 0.0})
    assert math.isfinite(pose_uncertainty(position, 0.5, 800.0, plain).sigma_rotation_deg)


def test_the_bundle_section_needs_registration(tmp_path):
    from _bundle_fixtures import make_bundle

    folder = make_bundle(tmp_path / "plain", manifest_overrides={"uncertainty": SECTION})
    with pytest.raises(BundleError, match="needs a registration"):
        load_bundle(folder)
    assert load_bundle(make_bundle(tmp_path / "none")).uncertainty is None


def _estimator(tmp_path, monkeypatch, section, more=None):
    """test_flip_classifier's estimator whose registration decides a valid pose, with ``section`` as the
    bundle's uncertainty section (None: none) and the sections of ``more`` added."""
    from test_flip_classifier import _flip_estimator

    from spacepose.calibration.rig import paper_rig
    from spacepose.estimator import PoseEstimator

    est = _flip_estimator(tmp_path, monkeypatch, 0.95, registration={"min_margin": 0.0}, decide_prob=0.999)
    data = json.loads((est.bundle.path / "bundle.json").read_text())
    if section is not None:
        data["uncertainty"] = section
    data.update(more or {})
    (est.bundle.path / "bundle.json").write_text(json.dumps(data))
    return PoseEstimator(paper_rig(640, 480), bundle=load_bundle(est.bundle.path), threads=1)


def test_a_valid_pose_carries_its_covariance_into_the_json_line(tmp_path, monkeypatch):
    import spacepose.estimator as estimator_module
    from _bundle_fixtures import synthetic_pair
    from test_flip_classifier import _decision

    left, right = synthetic_pair()
    est = _estimator(tmp_path, monkeypatch, SECTION)
    monkeypatch.setattr(estimator_module, "decide_outline", _decision(est, {}, 1.2, 0.3))
    assert est.bundle.uncertainty == CONFIG
    res = est.estimate(left, right)
    assert res.valid, res.detail
    assert np.isfinite(res.outline_chamfer_px)
    expected = pose_uncertainty(res.position, res.depth_tolerance_m, est.focal_px, CONFIG, res.outline_chamfer_px)
    assert np.allclose(res.position_cov, expected.position_cov)
    assert res.sigma_rotation_deg == pytest.approx(expected.sigma_rotation_deg)
    line = json.loads(json.dumps(res.to_dict("f")))
    assert np.allclose(line["position_cov"], expected.position_cov)
    assert line["sigma_rotation_deg"] == pytest.approx(expected.sigma_rotation_deg)


def test_without_the_section_or_a_valid_pose_there_is_none(tmp_path, monkeypatch):
    import spacepose.estimator as estimator_module
    from _bundle_fixtures import synthetic_pair
    from test_flip_classifier import _decision

    left, right = synthetic_pair()
    est = _estimator(tmp_path / "off", monkeypatch, None)
    monkeypatch.setattr(estimator_module, "decide_outline", _decision(est, {}, 1.2, 0.3))
    res = est.estimate(left, right)
    assert res.valid and np.all(np.isnan(res.position_cov)) and math.isnan(res.sigma_rotation_deg)
    line = res.to_dict()
    assert line["position_cov"] is None and line["sigma_rotation_deg"] is None
    est = _estimator(tmp_path / "on", monkeypatch, SECTION)
    res = est.estimate(np.zeros_like(left), np.zeros_like(right))   # eclipse: no pose
    assert not res.valid and res.to_dict()["position_cov"] is None and res.to_dict()["sigma_rotation_deg"] is None


POSITION_SECTION = {"range_k": 0.25, "range_chamfer_k": 0.12, "lateral_px": 0.3, "lateral_floor_m": 0.01,
                    "lateral_chamfer_m": 0.035}
POSITION_CONFIG = PositionUncertaintyConfig(**POSITION_SECTION)


def test_a_position_without_a_pose_gets_a_covariance_that_grows_with_the_chamfer():
    position = np.array([1.0, 2.0, 30.0])
    tight, loose = (position_uncertainty(position, 0.6, 800.0, POSITION_CONFIG, c) for c in (0.5, 2.8))
    u = position / np.linalg.norm(position)
    for spread, chamfer in ((tight, 0.5), (loose, 2.8)):
        assert np.allclose(spread.position_cov @ u, spread.sigma_range_m ** 2 * u)
        assert spread.sigma_range_m == pytest.approx(0.6 * math.hypot(0.25, 0.12 * chamfer))
        ratio = np.linalg.norm(position) / 800.0
        assert spread.sigma_lateral_m == pytest.approx(math.sqrt(0.01 ** 2 + (0.3 * ratio) ** 2 + (0.035 * chamfer) ** 2))
        assert math.isnan(spread.sigma_rotation_deg)          # no attitude, no rotation sigma
        assert np.all(np.linalg.eigvalsh(spread.position_cov) > 0)
    assert loose.sigma_range_m > tight.sigma_range_m and loose.sigma_lateral_m > tight.sigma_lateral_m


@pytest.mark.parametrize("tau, chamfer", [(0.5, float("nan")), (0.5, -1.0), (float("nan"), 1.0), (0.0, 1.0)])
def test_a_position_without_its_inputs_gets_no_covariance(tau, chamfer):
    assert position_uncertainty(np.array([0.0, 0.0, 20.0]), tau, 800.0, POSITION_CONFIG, chamfer) is None


def test_a_covariance_that_would_be_singular_is_not_given():
    only_chamfer = PositionUncertaintyConfig(0.25, 0.0, 0.0, 0.0, 0.03)
    assert position_uncertainty(np.array([0.0, 0.0, 20.0]), 0.5, 800.0, only_chamfer, 0.0) is None
    assert position_uncertainty(np.array([0.0, 0.0, 20.0]), 0.5, 800.0, only_chamfer, 0.4) is not None


@pytest.mark.parametrize("changes, match", [
    ({"range_k": 0.0, "range_chamfer_k": 0.0}, "cannot both be 0"),
    ({"lateral_px": 0.0, "lateral_floor_m": 0.0, "lateral_chamfer_m": 0.0}, "singular"),
    ({"lateral_chamfer_m": -0.1}, "lateral_chamfer_m must be finite and >= 0"),
    ({"range_k": float("inf")}, "range_k must be finite"),
])
def test_bad_position_constants_are_refused(changes, match):
    with pytest.raises(ValueError, match=match):
        PositionUncertaintyConfig(**{**POSITION_SECTION, **changes})
    with pytest.raises(BundleError, match=match):
        parse_position_uncertainty({**POSITION_SECTION, **changes})


@pytest.mark.parametrize("section, match", [
    ("0.3", "must be an object"),
    ({**POSITION_SECTION, "rotation_k_deg": 1.0}, "unknown keys"),
    ({k: v for k, v in POSITION_SECTION.items() if k != "range_chamfer_k"}, "lacks"),   # every key is needed
    ({**POSITION_SECTION, "lateral_px": [0.3]}, "must be a number"),
])
def test_malformed_position_sections_are_refused(section, match):
    with pytest.raises(BundleError, match=match):
        parse_position_uncertainty(section)
    assert parse_position_uncertainty(None) is None
    assert parse_position_uncertainty(dict(POSITION_SECTION)) == POSITION_CONFIG


def test_the_position_section_needs_registration(tmp_path):
    from _bundle_fixtures import make_bundle

    folder = make_bundle(tmp_path / "plain", manifest_overrides={"position_uncertainty": POSITION_SECTION})
    with pytest.raises(BundleError, match="position_uncertainty needs a registration"):
        load_bundle(folder)
    assert load_bundle(make_bundle(tmp_path / "none")).position_uncertainty is None


def test_a_position_only_frame_carries_its_covariance_into_the_json_line(tmp_path):
    """test_silhouette's plate: the registration never decides, the outline's fit (chamfer 2.2 px) is too loose
    to decide, so the frame has a position and no pose; with the section it has a covariance, the pose's
    section does not give it one, and without the section it has none."""
    from _bundle_fixtures import synthetic_pair
    from test_silhouette import _estimator as plate_estimator
    from test_silhouette import _with_outline_chamfer

    from spacepose.calibration.rig import paper_rig
    from spacepose.estimator import PoseEstimator

    left, right = synthetic_pair()

    def estimate(name, sections):
        est = plate_estimator(tmp_path / name, {"min_margin": 0.99, "position_max_tau_m": 5.0},
                              {"max_chamfer_px": 1.5, "min_margin_px": 5.0})
        data = json.loads((est.bundle.path / "bundle.json").read_text())
        data.update(sections)
        (est.bundle.path / "bundle.json").write_text(json.dumps(data))
        est = PoseEstimator(paper_rig(640, 480), bundle=load_bundle(est.bundle.path), threads=1)
        return est, _with_outline_chamfer(est, 2.2).estimate(left, right)

    est, res = estimate("on", {"position_uncertainty": POSITION_SECTION, "uncertainty": SECTION})
    assert est.bundle.position_uncertainty == POSITION_CONFIG
    assert res.status == "weak_votes" and not res.valid and res.position_valid
    assert res.outline_chamfer_px == pytest.approx(2.2)
    expected = position_uncertainty(res.position, res.depth_tolerance_m, est.focal_px, POSITION_CONFIG, 2.2)
    assert np.allclose(res.position_cov, expected.position_cov) and math.isnan(res.sigma_rotation_deg)
    line = json.loads(json.dumps(res.to_dict("f")))
    assert np.allclose(line["position_cov"], expected.position_cov) and line["sigma_rotation_deg"] is None
    _, pose_only = estimate("pose", {"uncertainty": SECTION})   # the valid poses' section alone: nothing here
    assert pose_only.position_valid and np.all(np.isnan(pose_only.position_cov))
    _, off = estimate("off", {})
    assert off.position_valid and off.to_dict()["position_cov"] is None


def test_the_shipped_bundle_models_heavy_tails():
    """Session 31 (reports/tails_s31/rule.txt): the shipped sigmas' errors are Student-t with about 3.6 degrees
    of freedom, so the 99 % gate is more than twice chi-square's."""
    shipped = load_bundle(None, verify_graphs=False).uncertainty
    assert shipped is not None and 2.0 < shipped.tail_dof < 10.0
