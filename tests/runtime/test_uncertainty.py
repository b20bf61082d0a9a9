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
from spacepose.uncertainty import UncertaintyConfig, parse_uncertainty, pose_uncertainty  # noqa: E402

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


def _estimator(tmp_path, monkeypatch, section):
    """test_flip_classifier's estimator whose registration decides a valid pose, with ``section`` as the
    bundle's uncertainty section (None: none)."""
    from test_flip_classifier import _flip_estimator

    from spacepose.calibration.rig import paper_rig
    from spacepose.estimator import PoseEstimator

    est = _flip_estimator(tmp_path, monkeypatch, 0.95, registration={"min_margin": 0.0}, decide_prob=0.999)
    data = json.loads((est.bundle.path / "bundle.json").read_text())
    if section is not None:
        data["uncertainty"] = section
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
