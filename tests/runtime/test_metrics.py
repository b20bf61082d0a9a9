"""Tests of spacepose.metrics: hand-computed values, edge cases, properties (hypothesis), bad inputs."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from spacepose.errors import ShapeError
from spacepose.metrics import (
    add,
    add_s,
    bad_tau,
    d1,
    epe,
    rmse,
    rotation_error_deg,
    speed_score,
    stereo_metrics,
    translation_error,
)

ATOL = 1e-12
ANGLE_ATOL_DEG = 1e-6


def rot_z(theta_rad: float) -> np.ndarray:
    c, s = math.cos(theta_rad), math.sin(theta_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rodrigues(rotvec) -> np.ndarray:
    R, _ = cv2.Rodrigues(np.asarray(rotvec, dtype=np.float64).reshape(3, 1))
    return R


# ----------------------------------------------------------------------------- stereo

# pred - gt errors on the valid pixels: 0.5, 2, 4, 10 (gt 10, 10, 100, 100); the 5th pixel is masked
PRED = np.array([[10.5, 12.0, 104.0], [110.0, 999.0, 0.0]], np.float32)
GT = np.array([[10.0, 10.0, 100.0], [100.0, 1.0, 0.0]], np.float32)
VALID = np.array([[True, True, True], [True, False, False]])


class TestStereoMetrics:
    def test_hand_computed(self):
        # |e| = 0.5, 2, 4, 10
        assert epe(PRED, GT, VALID) == pytest.approx(16.5 / 4, abs=ATOL)
        assert rmse(PRED, GT, VALID) == pytest.approx(math.sqrt((0.25 + 4 + 16 + 100) / 4), abs=ATOL)
        assert bad_tau(PRED, GT, VALID, 1.0) == pytest.approx(75.0, abs=ATOL)
        assert bad_tau(PRED, GT, VALID, 3.0) == pytest.approx(50.0, abs=ATOL)
        # D1: 4 px on gt 100 is > 3 px but < 5 px (5 %): not an outlier; 10 px on gt 100 is
        assert d1(PRED, GT, VALID) == pytest.approx(25.0, abs=ATOL)
        metrics = stereo_metrics(PRED, GT, VALID)
        assert metrics == pytest.approx(
            {"epe": 4.125, "rmse": math.sqrt(120.25 / 4), "bad1": 75.0, "bad3": 50.0, "d1": 25.0, "n_valid": 4.0},
            abs=ATOL,
        )
        assert all(type(v) is float for v in metrics.values())

    def test_d1_needs_both_conditions(self):
        gt = np.array([[10.0, 10.0, 200.0]], np.float32)
        pred = np.array([[13.5, 12.9, 209.0]], np.float32)  # 3.5 px (35 %), 2.9 px (29 %), 9 px (4.5 %)
        valid = np.ones_like(gt, bool)
        assert d1(pred, gt, valid) == pytest.approx(100.0 / 3, abs=1e-9)

    def test_strict_threshold(self):
        gt = np.zeros((1, 2), np.float64)
        pred = np.array([[1.0, 3.0]])
        valid = np.ones((1, 2), bool)
        assert bad_tau(pred, gt, valid, 1.0) == pytest.approx(50.0)  # exactly 1 px is not "bad-1"
        assert stereo_metrics(pred, gt, valid)["bad3"] == 0.0

    def test_float64_accumulation(self):
        gt = np.zeros((1000, 1000), np.float32)
        pred = np.full((1000, 1000), 0.1, np.float32)
        assert epe(pred, gt, np.ones(gt.shape, bool)) == pytest.approx(float(np.float32(0.1)), rel=1e-12)

    def test_empty_mask_is_nan(self):
        empty = np.zeros(GT.shape, bool)
        metrics = stereo_metrics(PRED, GT, empty)
        assert metrics["n_valid"] == 0.0
        assert all(math.isnan(metrics[k]) for k in ("epe", "rmse", "bad1", "bad3", "d1"))
        for value in (epe(PRED, GT, empty), rmse(PRED, GT, empty), bad_tau(PRED, GT, empty, 1.0), d1(PRED, GT, empty)):
            assert math.isnan(value)

    def test_non_finite_gt_is_ignored(self):
        gt = GT.copy()
        gt[0, 0] = np.inf
        valid = VALID.copy()
        metrics = stereo_metrics(PRED, gt, valid)
        assert metrics["n_valid"] == 3.0
        assert metrics["epe"] == pytest.approx(16.0 / 3, abs=ATOL)

    def test_perfect_prediction(self):
        metrics = stereo_metrics(GT, GT, VALID)
        assert metrics == pytest.approx({"epe": 0.0, "rmse": 0.0, "bad1": 0.0, "bad3": 0.0, "d1": 0.0, "n_valid": 4.0})

    @pytest.mark.parametrize("func", [epe, rmse, d1, stereo_metrics, lambda p, g, v: bad_tau(p, g, v, 2.0)])
    def test_bad_input(self, func):
        with pytest.raises(ShapeError, match=r"pred must have shape \(\*, \*\)"):
            func(PRED[None], GT, VALID)
        with pytest.raises(ShapeError, match=r"gt must have shape \(2, 3\)"):
            func(PRED, GT[:, :2], VALID)
        with pytest.raises(ShapeError, match=r"valid must have shape \(2, 3\)"):
            func(PRED, GT, VALID.T)
        with pytest.raises(ShapeError, match=r"valid must have dtype"):
            func(PRED, GT, VALID.astype(np.uint8))
        with pytest.raises(ShapeError, match=r"pred must have dtype"):
            func(PRED.astype(np.int32), GT, VALID)
        nan_pred = PRED.copy()
        nan_pred[0, 0] = np.nan
        with pytest.raises(ShapeError, match=r"pred \(inside the valid mask\) must be finite"):
            func(nan_pred, GT, VALID)
        nan_pred = PRED.copy()
        nan_pred[1, 2] = np.nan  # outside the mask: fine
        func(nan_pred, GT, VALID)

    def test_bad_tau_value(self):
        with pytest.raises(ValueError, match="tau"):
            bad_tau(PRED, GT, VALID, -1.0)


# ----------------------------------------------------------------------------- pose

rotvecs = arrays(np.float64, 3, elements=st.floats(-4.0, 4.0, allow_nan=False))
angles = st.floats(0.0, math.pi, allow_nan=False)
vectors = arrays(np.float64, 3, elements=st.floats(-100.0, 100.0, allow_nan=False))


class TestTranslationError:
    def test_hand_computed(self):
        assert translation_error(np.array([1.0, 2.0, 10.0]), np.array([4.0, 6.0, 10.0])) == pytest.approx(5.0, abs=ATOL)

    @given(vectors, vectors, vectors)
    @settings(max_examples=60, deadline=None)
    def test_triangle_inequality_and_symmetry(self, a, b, c):
        ab, bc, ac = translation_error(a, b), translation_error(b, c), translation_error(a, c)
        assert ac <= ab + bc + 1e-9
        assert ab == translation_error(b, a)
        assert translation_error(a, a) == 0.0

    def test_bad_input(self):
        with pytest.raises(ShapeError, match=r"^t must have shape \(3\), got \(4,\)"):
            translation_error(np.zeros(4), np.zeros(3))
        with pytest.raises(ShapeError, match=r"t_hat must have dtype"):
            translation_error(np.zeros(3), np.zeros(3, int))
        with pytest.raises(ShapeError, match=r"t_hat must be finite"):
            translation_error(np.zeros(3), np.array([0.0, np.nan, 0.0]))


class TestRotationError:
    def test_hand_computed(self):
        assert rotation_error_deg(np.eye(3), rot_z(math.radians(30.0))) == pytest.approx(30.0, abs=ANGLE_ATOL_DEG)
        assert rotation_error_deg(np.eye(3), np.diag([1.0, -1.0, -1.0])) == pytest.approx(180.0, abs=ANGLE_ATOL_DEG)
        assert rotation_error_deg(np.eye(3), np.eye(3)) == 0.0

    @pytest.mark.parametrize("angle_rad", [0.0, 1e-12, 1e-9, 1e-7, 1e-4])
    def test_near_identity(self, angle_rad):
        R = rodrigues([0.3, -0.2, 0.9])
        R_hat = R @ rodrigues(np.array([1.0, 2.0, 2.0]) / 3.0 * angle_rad)
        value = rotation_error_deg(R, R_hat)
        assert math.isfinite(value)
        assert value == pytest.approx(math.degrees(angle_rad), abs=1e-12 + 1e-6 * math.degrees(angle_rad))

    @pytest.mark.parametrize("delta_rad", [0.0, 1e-12, 1e-9, 1e-6, 1e-3])
    def test_near_180(self, delta_rad):
        axis = np.array([2.0, -1.0, 2.0]) / 3.0
        R = rodrigues([0.1, 0.5, -0.3])
        R_hat = R @ rodrigues(axis * (math.pi - delta_rad))
        value = rotation_error_deg(R, R_hat)
        assert math.isfinite(value) and value <= 180.0
        assert value == pytest.approx(180.0 - math.degrees(delta_rad), abs=1e-6)

    @pytest.mark.parametrize("base", [np.eye(3), np.diag([1.0, -1.0, -1.0])])
    def test_slightly_non_orthogonal(self, base):
        rng = np.random.default_rng(5)
        for _ in range(20):
            R_hat = base + rng.normal(scale=1e-7, size=(3, 3))
            value = rotation_error_deg(np.eye(3), R_hat)
            assert math.isfinite(value)
            assert value == pytest.approx(0.0 if base[1, 1] > 0 else 180.0, abs=1e-4)
        # arccos of the trace alone would be NaN here: (tr - 1) / 2 > 1
        R_hat = np.eye(3) * (1.0 + 1e-9)
        assert np.trace(R_hat) > 3.0 and rotation_error_deg(np.eye(3), R_hat) == 0.0

    @given(rotvecs, rotvecs)
    @settings(max_examples=60, deadline=None)
    def test_symmetric_and_bounded(self, a, b):
        R, R_hat = rodrigues(a), rodrigues(b)
        value = rotation_error_deg(R, R_hat)
        assert 0.0 <= value <= 180.0
        assert value == pytest.approx(rotation_error_deg(R_hat, R), abs=1e-9)

    @given(rotvecs, angles)
    @settings(max_examples=60, deadline=None)
    def test_about_z_equals_theta(self, rotvec, theta):
        R = rodrigues(rotvec)
        assert rotation_error_deg(R, R @ rot_z(theta)) == pytest.approx(math.degrees(theta), abs=ANGLE_ATOL_DEG)

    @given(rotvecs, rotvecs, rotvecs)
    @settings(max_examples=40, deadline=None)
    def test_triangle_inequality(self, a, b, c):
        Ra, Rb, Rc = rodrigues(a), rodrigues(b), rodrigues(c)
        assert rotation_error_deg(Ra, Rc) <= rotation_error_deg(Ra, Rb) + rotation_error_deg(Rb, Rc) + 1e-6

    def test_bad_input(self):
        with pytest.raises(ShapeError, match=r"R must have shape \(3, 3\)"):
            rotation_error_deg(np.eye(4), np.eye(3))
        with pytest.raises(ShapeError, match=r"R_hat must have dtype"):
            rotation_error_deg(np.eye(3), np.eye(3, dtype=np.int64))
        with pytest.raises(ShapeError, match=r"R_hat must be finite"):
            rotation_error_deg(np.eye(3), np.full((3, 3), np.nan))


# model points: corners of a 2 x 1 x 0.5 m box
BOX = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-0.5, 0.5) for z in (-0.25, 0.25)])
T0 = np.array([0.0, 0.0, 10.0])


class TestAddAndAddS:
    def test_translation_only(self):
        t_hat = T0 + np.array([0.3, 0.0, 0.4])
        assert add(np.eye(3), T0, np.eye(3), t_hat, BOX) == pytest.approx(0.5, abs=ATOL)
        # ADD-S never exceeds ADD (each point's own image is a candidate neighbour)
        assert add_s(np.eye(3), T0, np.eye(3), t_hat, BOX) <= 0.5 + ATOL

    def test_symmetric_flip(self):
        """A 180° turn about z maps the box onto itself: ADD is large, ADD-S is zero."""
        R_hat = rot_z(math.pi)
        expected_add = np.mean(np.linalg.norm(BOX - BOX @ R_hat.T, axis=1))  # = mean 2*sqrt(x^2 + y^2)
        assert add(np.eye(3), T0, R_hat, T0, BOX) == pytest.approx(expected_add, abs=ATOL)
        assert expected_add == pytest.approx(2.0 * math.sqrt(1.25), abs=ATOL)
        assert add_s(np.eye(3), T0, R_hat, T0, BOX) == pytest.approx(0.0, abs=1e-12)

    def test_add_s_hand_computed(self):
        points = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
        # shift 0.25 m along x: est = {0.25, 1.25}; true 0 -> 0.25 away, true 1 -> 0.25 away
        assert add_s(np.eye(3), T0, np.eye(3), T0 + [0.25, 0, 0], points) == pytest.approx(0.25, abs=ATOL)
        # shift 0.75 m: est = {0.75, 1.75}; true 0 -> 0.75 away, true 1 -> 0.25 away (to 0.75)
        assert add_s(np.eye(3), T0, np.eye(3), T0 + [0.75, 0, 0], points) == pytest.approx(0.5, abs=ATOL)
        assert add(np.eye(3), T0, np.eye(3), T0 + [0.75, 0, 0], points) == pytest.approx(0.75, abs=ATOL)

    def test_add_s_matches_brute_force_across_chunks(self, monkeypatch):
        import spacepose.metrics as metrics_module

        monkeypatch.setattr(metrics_module, "_NN_CHUNK_ELEMENTS", 97)  # many small chunks
        rng = np.random.default_rng(6)
        points = rng.normal(size=(300, 3))
        R_hat, t_hat = rodrigues([0.1, -0.2, 0.05]), T0 + [0.01, 0.02, -0.03]
        est = points @ R_hat.T + t_hat
        true = points + T0
        reference = np.mean(np.min(np.linalg.norm(true[:, None, :] - est[None, :, :], axis=2), axis=1))
        assert add_s(np.eye(3), T0, R_hat, t_hat, points) == pytest.approx(reference, abs=1e-12)
        assert add_s(np.eye(3), T0, R_hat, t_hat, points) <= add(np.eye(3), T0, R_hat, t_hat, points)

    @pytest.mark.parametrize("func", [add, add_s])
    def test_bad_input(self, func):
        I, t = np.eye(3), T0
        with pytest.raises(ShapeError, match=r"points must have shape \(\*, 3\)"):
            func(I, t, I, t, BOX[:, :2])
        with pytest.raises(ShapeError, match=r"points must have dtype"):
            func(I, t, I, t, BOX.astype(int))
        with pytest.raises(ShapeError, match=r"points must be finite"):
            func(I, t, I, t, np.vstack([BOX, [np.nan, 0, 0]]))
        with pytest.raises(ShapeError, match=r"at least one point"):
            func(I, t, I, t, np.zeros((0, 3)))
        with pytest.raises(ShapeError, match=r"R_hat must have shape"):
            func(I, t, I[:2], t, BOX)
        with pytest.raises(ShapeError, match=r"t must have shape"):
            func(I, t[:2], I, t, BOX)


class TestSpeedScore:
    def test_hand_computed(self):
        t_hat = T0 + np.array([0.0, 0.3, 0.4])  # 0.5 m error at 10 m: 0.05
        R_hat = rot_z(0.1)
        assert speed_score(np.eye(3), T0, R_hat, t_hat) == pytest.approx(0.05 + 0.1, abs=1e-12)

    def test_thresholds_off_by_default(self):
        t_hat = T0 + np.array([0.0, 0.0, 0.01])  # 0.001 relative
        R_hat = rot_z(math.radians(0.2))
        expected = 0.001 + math.radians(0.2)
        assert speed_score(np.eye(3), T0, R_hat, t_hat) == pytest.approx(expected, abs=1e-12)
        assert speed_score(np.eye(3), T0, R_hat, t_hat, apply_thresholds=True) == 0.0
        # only the term under its threshold is zeroed
        R_big = rot_z(math.radians(1.0))
        assert speed_score(np.eye(3), T0, R_big, t_hat, apply_thresholds=True) == pytest.approx(math.radians(1.0), abs=1e-12)

    def test_bad_input(self):
        I = np.eye(3)
        with pytest.raises(ValueError, match="non-zero ground-truth translation"):
            speed_score(I, np.zeros(3), I, T0)
        with pytest.raises(ShapeError, match=r"R must have shape"):
            speed_score(I[:2], T0, I, T0)
        with pytest.raises(ShapeError, match=r"t_hat must be finite"):
            speed_score(I, T0, I, np.array([np.inf, 0.0, 0.0]))
        with pytest.raises(ShapeError, match=r"t must have dtype"):
            speed_score(I, T0.astype(int), I, T0)
