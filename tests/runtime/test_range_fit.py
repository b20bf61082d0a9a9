"""Tests of spacepose.range_fit (a valid pose's range from the stereo pair at full resolution) and its use by the
estimator."""

import json
import math
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))  # --import-mode=importlib: find the helpers

from spacepose.bundle import load_bundle  # noqa: E402
from spacepose.errors import BundleError, ShapeError  # noqa: E402
from spacepose.range_fit import (RangeFit, RangeFitConfig, fit_range, parse_range_fit,  # noqa: E402
                                 refine_disparity, visible_samples)

F, B = 800.0, 1.0
K = np.array([[F, 0.0, 319.5], [0.0, F, 239.5], [0.0, 0.0, 1.0]])


def _texture(h=480, w=640, seed=0):
    """Smooth random texture in [0, 255] (blurred noise: linear interpolation of it is close to exact)."""
    rng = np.random.default_rng(seed)
    return cv2.GaussianBlur(rng.random((h, w)).astype(np.float32), (0, 0), 1.5) * 255.0 * 4.0


def _shifted(image, shift):
    """``out(x, y) = image(x + shift, y)`` (what a right camera sees of a wall at disparity ``shift``)."""
    h, w = image.shape
    xx, yy = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    return cv2.remap(image, xx + np.float32(shift), yy, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT)


@pytest.mark.parametrize("section, match", [
    ([], "must be an object"),
    ({"windows": 7}, "unknown keys"),
    ({"window_px": 7.0}, "must be an integer"),
    ({"window_px": True}, "must be an integer"),
    ({"span_px": "1"}, "must be a number"),
    ({"span_px": float("nan")}, "finite"),
    ({"window_px": 8}, "odd integer"),
    ({"step_px": 2.0, "span_px": 1.0}, "step_px <= span_px"),
    ({"step_px": 0.0}, "0 < step_px"),
    ({"min_samples": 2}, "min_samples"),
    ({"steps": 0}, "steps"),
    ({"max_move_m": -1.0}, "positive"),
])
def test_bad_sections_are_refused(section, match):
    with pytest.raises(BundleError, match=match):
        parse_range_fit(section)


def test_a_section_defaults_and_none():
    assert parse_range_fit(None) is None
    assert parse_range_fit({}) == RangeFitConfig()
    got = parse_range_fit({"window_px": 5, "span_px": 2, "steps": 3})
    assert got == RangeFitConfig(window_px=5, span_px=2.0, steps=3) and isinstance(got.span_px, float)
    np.testing.assert_allclose(RangeFitConfig().offsets, np.linspace(-1.0, 1.0, 21), atol=1e-12)
    np.testing.assert_allclose(RangeFitConfig(span_px=0.5, step_px=0.2).offsets, [-0.4, -0.2, 0.0, 0.2, 0.4])


@pytest.mark.parametrize("true_shift, bias", [(20.3, -0.3), (35.0, 0.45), (12.62, 0.0), (20.0, -0.85)])
def test_the_refined_disparity_finds_a_sub_pixel_shift(true_shift, bias):
    left = _texture()
    right = _shifted(left, true_shift)           # right(x - d) = left(x): the left pixel x is seen at x - d
    disparity = np.full(left.shape, true_shift + bias, np.float32)
    disparity[:, :40] = 0.0                       # unknown: stays 0
    box = (20, 100, 400, 300)
    out = refine_disparity(left, right, disparity, box, RangeFitConfig())
    assert out.shape == (200, 380) and out.dtype == np.float32
    assert np.all(out[:, :20] == 0.0)
    inner = out[10:-10, 30:-10]
    assert abs(float(np.median(inner)) - true_shift) < 0.03
    assert np.percentile(np.abs(inner - true_shift), 90) < 0.1


def test_the_refined_disparity_stays_within_the_search():
    left = _texture()
    right = _shifted(left, 24.0)
    disparity = np.full(left.shape, 20.0, np.float32)     # 4 px off: beyond the +-1 px searched
    out = refine_disparity(left, right, disparity, (100, 100, 300, 300), RangeFitConfig())
    assert np.all(out >= 19.0 - 1e-6) and np.all(out <= 21.0 + 1e-6)
    with pytest.raises(ShapeError):
        refine_disparity(left, right[:, :-1], disparity, (100, 100, 300, 300), RangeFitConfig())


def _plate(n=40, half=(1.2, 0.8)):
    """(n*n, 3) samples of a flat plate in the object's z = 0 plane (the object frame's centre at its middle)."""
    g = np.stack(np.meshgrid(np.linspace(-half[0], half[0], n), np.linspace(-half[1], half[1], n), indexing="ij"), -1)
    return np.hstack([g.reshape(-1, 2), np.zeros((n * n, 1))])


def test_visible_samples_hide_the_back_and_drop_what_is_outside():
    front = _plate(120)                                     # samples 1.3 px apart at 10 m: every cell has one
    back = _plate(30) + [0.0, 0.0, 0.5]                     # behind the front plate (R = I: object z is depth)
    surface = np.vstack([front, back])
    u, v, z = visible_samples(np.eye(3), np.array([0.0, 0.0, 10.0]), surface, K, (640, 480), 3.0, 0.1)
    assert len(z) > 0 and np.all(np.abs(z - 10.0) < 1e-9)   # only the front plate is seen
    u, v, z = visible_samples(np.eye(3), np.array([3.5, 0.0, 10.0]), front, K, (640, 480), 3.0, 0.1)
    assert len(z) < len(front) and np.all(u <= 639.0)       # the part beyond the right edge is dropped
    assert len(visible_samples(np.eye(3), np.array([0.0, 0.0, -5.0]), front, K, (640, 480), 3.0, 0.1)[0]) == 0


def _scene(z_true=16.0, bias=0.4, tilt_deg=20.0):
    """A textured wall at depth ``z_true`` (both images), a plate target on it turned about y by ``tilt_deg``...
    kept simple: the target lies in the wall's plane (R turns it within that plane), so its model disparity is
    f B / z_true everywhere. The stereo disparity given is the truth plus ``bias``."""
    left = _texture(seed=1)
    d = F * B / z_true
    right = _shifted(left, d)
    a = math.radians(tilt_deg)
    R = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])
    t_true = np.array([0.6, -0.4, z_true])
    disparity = np.full(left.shape, d + bias, np.float32)
    return left, right, disparity, R, t_true


def test_the_fit_moves_the_pose_to_the_range_the_images_show():
    left, right, disparity, R, t_true = _scene()
    centre = np.array([0.1, 0.05, 0.0])
    c_true = R @ centre + t_true
    c_start = c_true * (15.2 / c_true[2])                   # 0.8 m too near, on the centre's line of sight
    t_start = c_start - R @ centre
    fit = fit_range(R, t_start, centre, _plate(), left, right, disparity, K, B, RangeFitConfig())
    assert isinstance(fit, RangeFit) and fit.t is not None and fit.why == ""
    c = R @ centre + fit.t
    assert abs(c[2] - t_true[2]) < 0.02                    # 16 m, from 15.2 m and a disparity 0.4 px off
    np.testing.assert_allclose(np.cross(c / np.linalg.norm(c), c_true / np.linalg.norm(c_true)), 0.0, atol=1e-9)
    assert fit.move_m == pytest.approx(np.linalg.norm(c) - np.linalg.norm(c_start))
    assert fit.samples >= 30 and fit.residual_px < -1.0   # the start is too near: the images show less disparity
    # a stereo disparity beyond the search (3.4 px off) is not mended: the fit lands 2.4 px off, far from 16 m
    biased = fit_range(R, t_start, centre, _plate(), left, right, disparity + 3.0, K, B, RangeFitConfig())
    assert biased.t is not None and abs((R @ centre + biased.t)[2] - t_true[2]) > 0.5


def test_the_fit_accepts_grey_and_colour_images_of_any_integer_type():
    left, right, disparity, R, t_true = _scene()
    surface, centre = _plate(), np.zeros(3)
    want = fit_range(R, t_true + [0, 0, 0.3], centre, surface, left, right, disparity, K, B, RangeFitConfig())
    as_u8 = [np.clip(np.rint(im / 4.0), 0, 255).astype(np.uint8) for im in (left, right)]
    got = fit_range(R, t_true + [0, 0, 0.3], centre, surface, *(np.repeat(im[..., None], 3, 2) for im in as_u8),
                    disparity, K, B, RangeFitConfig())
    assert want.t is not None and got.t is not None
    assert abs(got.t[2] - want.t[2]) < 0.02


def test_a_fit_that_cannot_be_trusted_is_not_applied():
    left, right, disparity, R, t_true = _scene()
    surface, centre = _plate(), np.zeros(3)
    far = fit_range(R, t_true + [0, 0, -0.8], centre, surface, left, right, disparity, K, B,
                    RangeFitConfig(max_move_m=0.2))
    assert far.t is None and "beyond 0.2 m" in far.why and far.move_m == pytest.approx(0.8, abs=0.05)
    few = fit_range(R, t_true, centre, surface, left, right, disparity, K, B, RangeFitConfig(min_samples=5000))
    assert few.t is None and "visible surface samples" in few.why and math.isnan(few.move_m)
    blank = fit_range(R, t_true, centre, surface, left, right, np.zeros_like(disparity), K, B, RangeFitConfig())
    assert blank.t is None and "match the disparity" in blank.why
    nan = fit_range(R, np.full(3, np.nan), centre, surface, left, right, disparity, K, B, RangeFitConfig())
    assert nan.t is None and "not finite" in nan.why
    with pytest.raises(ValueError, match="differ in size"):
        fit_range(R, t_true, centre, surface, left[:-2], right[:-2], disparity, K, B, RangeFitConfig())
    with pytest.raises(ShapeError):
        fit_range(R, t_true[:2], centre, surface, left, right, disparity, K, B, RangeFitConfig())


def _with_section(tmp_path, section):
    """(estimator of test_silhouette's outline bundle, the same bundle's folder with ``range_fit`` = section)."""
    from test_silhouette import _estimator

    est = _estimator(tmp_path, {"min_margin": 0.99}, {"max_chamfer_px": 100.0, "min_margin_px": 0.0})
    data = json.loads((est.bundle.path / "bundle.json").read_text())
    data["range_fit"] = section
    (est.bundle.path / "bundle.json").write_text(json.dumps(data))
    return est, est.bundle.path


def _range_estimator(tmp_path, section):
    from spacepose.calibration.rig import paper_rig
    from spacepose.estimator import PoseEstimator

    est, folder = _with_section(tmp_path, section)
    return est, PoseEstimator(paper_rig(640, 480), bundle=load_bundle(folder), threads=1)


def test_a_bundle_with_a_range_fit_needs_enough_surface_points(tmp_path):
    _, folder = _with_section(tmp_path, {"min_samples": 4000})
    with pytest.raises(BundleError, match="min_samples"):
        load_bundle(folder)
    _, folder = _with_section(tmp_path / "ok", {"window_px": 9})
    assert load_bundle(folder).range_fit == RangeFitConfig(window_px=9)


@pytest.mark.parametrize("applied", [True, False])
def test_the_estimator_reports_the_fitted_range_after_its_checks(tmp_path, monkeypatch, applied):
    import spacepose.estimator as estimator_module
    from _bundle_fixtures import synthetic_pair

    left, right = synthetic_pair()
    without, with_fit = _range_estimator(tmp_path, {})
    base = without.estimate(left, right)
    assert base.valid and math.isnan(base.range_fit_m) and "range_fit" not in base.timings_ms
    seen = {}

    def fake_fit(R, t, centre, surface, left_r, right_r, disparity, K_, baseline, config):
        seen.update(R=R, t=t, surface=surface, shapes=(left_r.shape, right_r.shape, disparity.shape), config=config)
        return (RangeFit(t * 1.01, 0.05, 123, 0.2) if applied else
                RangeFit(None, math.nan, 3, math.nan, "3 visible surface samples (< 30)"))

    monkeypatch.setattr(estimator_module, "fit_range", fake_fit)
    res = with_fit.estimate(left, right)
    assert res.valid and res.decided_by == base.decided_by and "range_fit" in res.timings_ms
    np.testing.assert_allclose(seen["R"], base.R)           # the checked pose goes in ...
    np.testing.assert_allclose(seen["t"], base.t)
    assert seen["shapes"] == ((480, 640, 3), (480, 640, 3), (480, 640)) and seen["config"] == RangeFitConfig()
    assert len(seen["surface"]) == len(with_fit.bundle.surface_points)
    np.testing.assert_allclose(res.R, base.R)               # ... and the rotation comes out unchanged
    if applied:
        np.testing.assert_allclose(res.t, base.t * 1.01)
        assert res.range_fit_m == 0.05
        np.testing.assert_allclose(res.position, res.R @ np.asarray(with_fit.bundle.centre) + res.t)
    else:
        np.testing.assert_allclose(res.t, base.t)
        assert math.isnan(res.range_fit_m)


def test_the_range_fit_runs_on_a_real_frame_of_the_tiny_bundle(tmp_path):
    """Not mocked: on the synthetic pair the fit runs; whether applied or not, the pose stays valid and finite."""
    from _bundle_fixtures import synthetic_pair

    left, right = synthetic_pair()
    without, with_fit = _range_estimator(tmp_path, {})
    base, res = without.estimate(left, right), with_fit.estimate(left, right)
    assert res.valid == base.valid and np.all(np.isfinite(res.t))
    assert math.isnan(res.range_fit_m) or abs(res.range_fit_m) <= RangeFitConfig().max_move_m


def test_the_shipped_bundle_fits_the_range():
    """reports/range_s42/plan.txt (met in session 42): the range fit with RangeFitConfig's defaults; plan3.txt's
    part B (met): for positions without a pose too."""
    assert load_bundle(None, verify_graphs=False).range_fit == RangeFitConfig(positions=1)


def test_the_section_s_positions_switch():
    assert RangeFitConfig().positions == 0 and parse_range_fit({"positions": 1}).positions == 1
    for bad in (2, True, 0.5):
        with pytest.raises(BundleError, match="positions"):
            parse_range_fit({"positions": bad})


@pytest.mark.parametrize("positions", [0, 1])
def test_a_position_without_a_pose_gets_the_fit_only_with_positions(tmp_path, monkeypatch, positions):
    """test_registration's ambiguous plate: the frame is weak_votes with a position. With ``positions`` 1 the fit
    reads the rotation the position came from and moves the position; with 0 (the default) it does not run."""
    import spacepose.estimator as estimator_module
    from _bundle_fixtures import synthetic_pair
    from test_registration import _registration_bundle

    from spacepose.calibration.rig import paper_rig
    from spacepose.estimator import PoseEstimator

    left, right = synthetic_pair()
    plain = _registration_bundle(tmp_path / "plain", {"min_margin": 0.5, "position_max_tau_m": 1.0})
    folder = _registration_bundle(tmp_path / "fit", {"min_margin": 0.5, "position_max_tau_m": 1.0})
    data = json.loads((folder / "bundle.json").read_text())
    data["range_fit"] = {"positions": positions, "min_samples": 3}
    (folder / "bundle.json").write_text(json.dumps(data))
    base = PoseEstimator(paper_rig(640, 480), bundle=load_bundle(plain), threads=1).estimate(left, right)
    assert base.status == "weak_votes" and base.position_valid and math.isnan(base.range_fit_m)
    calls = []

    def fake_fit(R, t, centre, surface, left_r, right_r, disparity, K_, baseline, config):
        calls.append((R, t, centre))
        return RangeFit(np.asarray(t) + [0.0, 0.0, 0.25], 0.25, 50, -0.1)

    monkeypatch.setattr(estimator_module, "fit_range", fake_fit)
    est = PoseEstimator(paper_rig(640, 480), bundle=load_bundle(folder), threads=1)
    res = est.estimate(left, right)
    assert res.status == "weak_votes" and not res.valid and res.position_valid
    if not positions:
        assert not calls and math.isnan(res.range_fit_m)
        np.testing.assert_allclose(res.position, base.position)
        return
    assert len(calls) == 1 and "range_fit" in res.timings_ms
    R_c, t_c, centre = calls[0]
    np.testing.assert_allclose(R_c @ centre + t_c, base.position, atol=1e-9)   # it starts at the route's position
    np.testing.assert_allclose(res.position, base.position + [0.0, 0.0, 0.25], atol=1e-9)
    assert res.range_fit_m == 0.25 and np.all(np.isnan(res.t))                  # still no pose


def test_the_shipped_position_covariance_is_plan4_s_fit():
    """reports/range_s42/plan4.txt (met in session 42): position_uncertainty fitted again after the positions' fit."""
    from spacepose.uncertainty import PositionUncertaintyConfig

    fit = json.loads((Path(__file__).resolve().parents[2] / "reports" / "range_s42" / "fit4_positions.json")
                     .read_text())["fit"]
    want = PositionUncertaintyConfig(**{k: round(float(v), 4) for k, v in fit.items()})
    assert load_bundle(None, verify_graphs=False).position_uncertainty == want
