"""Tests of spacepose.fit.fit_rigid: weighted Kabsch/Umeyama without scale."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from spacepose.errors import ShapeError
from spacepose.fit import STATUSES, RigidFit, fit_rigid

EXACT = 1e-9  # noise-free recovery tolerance


def random_pose(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    return Rotation.random(random_state=rng.integers(2**31)).as_matrix(), rng.uniform(-20, 20, 3)


def assert_invalid(fit: RigidFit, status: str) -> None:
    assert not fit.valid and fit.status == status
    assert fit.R.shape == (3, 3) and fit.t.shape == (3,)
    assert np.all(np.isnan(fit.R)) and np.all(np.isnan(fit.t)) and np.isnan(fit.rms)


class TestFitRigid:
    def test_smoke(self) -> None:
        rng = np.random.default_rng(0)
        src = rng.normal(size=(9, 3))
        fit = fit_rigid(src, src)
        assert isinstance(fit, RigidFit) and fit.valid and fit.status == "ok"
        assert fit.R.dtype == np.float64 and fit.t.dtype == np.float64
        np.testing.assert_allclose(fit.R, np.eye(3), atol=EXACT)
        np.testing.assert_allclose(fit.t, 0.0, atol=EXACT)
        assert fit.rms <= EXACT
        with pytest.raises(AttributeError):
            fit.valid = False  # type: ignore[misc]  # frozen

    def test_exact_on_noise_free_keypoints(self) -> None:
        rng = np.random.default_rng(1)
        for _ in range(20):
            R, t = random_pose(rng)
            src = rng.uniform(-2, 2, (9, 3))  # 8 keypoints + centre of a ~4 m target
            fit = fit_rigid(src, src @ R.T + t)
            assert fit.valid
            np.testing.assert_allclose(fit.R, R, atol=EXACT)
            np.testing.assert_allclose(fit.t, t, atol=EXACT)
            assert fit.rms <= EXACT

    def test_planar_src_is_fine(self) -> None:
        rng = np.random.default_rng(2)
        R, t = random_pose(rng)
        src = np.c_[rng.normal(size=(6, 2)), np.zeros(6)]
        fit = fit_rigid(src, src @ R.T + t)
        assert fit.valid
        np.testing.assert_allclose(fit.R, R, atol=EXACT)
        np.testing.assert_allclose(fit.t, t, atol=EXACT)

    def test_three_points(self) -> None:
        rng = np.random.default_rng(3)
        R, t = random_pose(rng)
        src = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
        fit = fit_rigid(src, src @ R.T + t)
        np.testing.assert_allclose(fit.R, R, atol=EXACT)
        np.testing.assert_allclose(fit.t, t, atol=EXACT)

    def test_weights_match_scipy_align_vectors(self) -> None:
        rng = np.random.default_rng(4)
        R, t = random_pose(rng)
        src = rng.normal(size=(12, 3))
        dst = src @ R.T + t + rng.normal(0, 0.05, (12, 3))
        w = rng.uniform(0.1, 3.0, 12)
        fit = fit_rigid(src, dst, w)
        c_src, c_dst = w @ src / w.sum(), w @ dst / w.sum()
        rot, _ = Rotation.align_vectors(dst - c_dst, src - c_src, weights=w)
        np.testing.assert_allclose(fit.R, rot.as_matrix(), atol=1e-9)
        np.testing.assert_allclose(fit.t, c_dst - rot.as_matrix() @ c_src, atol=1e-9)
        resid = src @ fit.R.T + fit.t - dst
        assert fit.rms == pytest.approx(np.sqrt(w @ (resid**2).sum(1) / w.sum()), rel=1e-12)

    def test_unweighted_equals_unit_weights_and_scale_invariance(self) -> None:
        rng = np.random.default_rng(5)
        src, dst = rng.normal(size=(10, 3)), rng.normal(size=(10, 3))
        a, b, c = fit_rigid(src, dst), fit_rigid(src, dst, np.ones(10)), fit_rigid(src, dst, np.full(10, 7.0))
        np.testing.assert_allclose(a.R, b.R, atol=1e-12)
        np.testing.assert_allclose(a.R, c.R, atol=1e-12)
        np.testing.assert_allclose(a.t, c.t, atol=1e-12)

    def test_zero_weight_points_are_ignored(self) -> None:
        rng = np.random.default_rng(6)
        R, t = random_pose(rng)
        src = rng.normal(size=(8, 3))
        dst = src @ R.T + t
        dst[0] += 100.0  # a wild keypoint with zero weight
        w = np.ones(8)
        w[0] = 0.0
        fit = fit_rigid(src, dst, w)
        np.testing.assert_allclose(fit.R, R, atol=EXACT)
        np.testing.assert_allclose(fit.t, t, atol=EXACT)

    def test_reflected_target_still_gives_a_rotation(self) -> None:
        rng = np.random.default_rng(7)
        src = rng.normal(size=(10, 3))
        dst = src * [1.0, 1.0, -1.0]  # a mirror image: the best orthogonal map has det -1
        fit = fit_rigid(src, dst)
        assert fit.valid
        assert np.linalg.det(fit.R) == pytest.approx(1.0, abs=1e-12)
        np.testing.assert_allclose(fit.R @ fit.R.T, np.eye(3), atol=1e-12)
        rot, _ = Rotation.align_vectors(dst - dst.mean(0), src - src.mean(0))
        np.testing.assert_allclose(fit.R, rot.as_matrix(), atol=1e-9)

    def test_integer_and_float32_input(self) -> None:
        src = np.array([[0, 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 3]])
        fit = fit_rigid(src, (src + [1, 2, 3]).astype(np.float32))
        np.testing.assert_allclose(fit.R, np.eye(3), atol=EXACT)
        np.testing.assert_allclose(fit.t, [1, 2, 3], atol=EXACT)

    @pytest.mark.parametrize(
        ("case", "status"),
        [
            ("two_points", "too_few_points"),
            ("empty", "too_few_points"),
            ("two_positive_weights", "too_few_points"),
            ("nan_src", "non_finite"),
            ("inf_dst", "non_finite"),
            ("nan_weight", "non_finite"),
            ("negative_weight", "bad_weights"),
            ("zero_weights", "bad_weights"),
            ("collinear", "degenerate"),
            ("near_collinear", "degenerate"),
            ("coincident", "degenerate"),
            ("coincident_at_origin", "degenerate"),
        ],
    )
    def test_invalid_content(self, case: str, status: str) -> None:
        rng = np.random.default_rng(8)
        src = rng.normal(size=(6, 3))
        dst = src + 1.0
        w = None
        line = np.linspace(0, 1, 6)[:, None] * [1.0, 2.0, 3.0] + [4.0, 5.0, 6.0]
        if case == "two_points":
            src, dst = src[:2], dst[:2]
        elif case == "empty":
            src, dst = src[:0], dst[:0]
        elif case == "two_positive_weights":
            w = np.array([1.0, 1.0, 0.0, 0.0, 0.0, 0.0])
        elif case == "nan_src":
            src[2, 1] = np.nan
        elif case == "inf_dst":
            dst[0, 0] = np.inf
        elif case == "nan_weight":
            w = np.ones(6)
            w[3] = np.nan
        elif case == "negative_weight":
            w = np.ones(6)
            w[3] = -0.1
        elif case == "zero_weights":
            w = np.zeros(6)
        elif case == "collinear":
            src = line
        elif case == "near_collinear":
            src = line + rng.normal(0, 1e-9, line.shape)
        elif case == "coincident":
            src = np.tile([3.0, -2.0, 10.0], (6, 1)) + rng.normal(0, 1e-14, (6, 3))
        elif case == "coincident_at_origin":
            src = np.zeros((6, 3))
        assert status in STATUSES
        assert_invalid(fit_rigid(src, dst, w), status)

    def test_bad_input(self) -> None:
        pts = np.zeros((5, 3))
        with pytest.raises(ShapeError, match=r"src must have shape \(\*, 3\)"):
            fit_rigid(np.zeros((5, 2)), pts)
        with pytest.raises(ShapeError, match=r"dst must have shape \(5, 3\)"):
            fit_rigid(pts, np.zeros((4, 3)))
        with pytest.raises(ShapeError, match=r"weights must have shape \(5\)"):
            fit_rigid(pts, pts, np.ones(4))
        with pytest.raises(ShapeError, match="src must be a numpy array"):
            fit_rigid([[0.0, 0.0, 0.0]] * 5, pts)  # type: ignore[arg-type]
        with pytest.raises(ShapeError, match="src must have a float or integer dtype"):
            fit_rigid(pts.astype(bool), pts)
        with pytest.raises(ValueError, match="rel_tol must be in"):
            fit_rigid(pts, pts, rel_tol=1.5)


unit = st.floats(-1.0, 1.0, allow_nan=False)
quaternions = st.tuples(unit, unit, unit, unit).filter(lambda q: np.linalg.norm(q) > 0.1)
translations = st.tuples(*[st.floats(-50.0, 50.0, allow_nan=False)] * 3)


class TestFitRigidProperties:
    @settings(max_examples=60, deadline=None)
    @given(q=quaternions, t=translations, n=st.integers(3, 40), seed=st.integers(0, 2**31 - 1))
    def test_recovers_random_poses_exactly(self, q, t, n, seed) -> None:
        rng = np.random.default_rng(seed)
        R = Rotation.from_quat(q).as_matrix()
        src = rng.uniform(-3.0, 3.0, (n, 3))
        if np.linalg.svd(src - src.mean(0), compute_uv=False)[1] < 1e-3:
            return  # a random draw too close to a line is not this property's concern
        fit = fit_rigid(src, src @ R.T + np.asarray(t))
        assert fit.valid
        np.testing.assert_allclose(fit.R, R, atol=EXACT)
        np.testing.assert_allclose(fit.t, t, atol=EXACT * 10)  # |t| up to 87 m
        assert np.linalg.det(fit.R) == pytest.approx(1.0, abs=1e-12)

    @settings(max_examples=60, deadline=None)
    @given(seed=st.integers(0, 2**31 - 1), n=st.integers(3, 30), reflect=st.booleans())
    def test_never_a_reflection_and_agrees_with_scipy(self, seed, n, reflect) -> None:
        rng = np.random.default_rng(seed)
        src = rng.normal(size=(n, 3))
        dst = rng.normal(size=(n, 3)) * 2.0 + rng.uniform(-10, 10, 3)
        if reflect:
            dst = src @ np.diag([1.0, -1.0, 1.0]) + rng.normal(0, 0.1, (n, 3))
        w = rng.uniform(0.01, 1.0, n)
        fit = fit_rigid(src, dst, w)
        assert fit.valid
        assert np.linalg.det(fit.R) == pytest.approx(1.0, abs=1e-10)
        np.testing.assert_allclose(fit.R @ fit.R.T, np.eye(3), atol=1e-10)
        c_src, c_dst = w @ src / w.sum(), w @ dst / w.sum()
        rot, _ = Rotation.align_vectors(dst - c_dst, src - c_src, weights=w)
        # Both minimise the same cost; compare costs (the optimum is not unique when degenerate).
        cost_ours = w @ (((src - c_src) @ fit.R.T - (dst - c_dst)) ** 2).sum(1)
        cost_scipy = w @ (((src - c_src) @ rot.as_matrix().T - (dst - c_dst)) ** 2).sum(1)
        assert cost_ours <= cost_scipy + 1e-9 * max(1.0, cost_scipy)
