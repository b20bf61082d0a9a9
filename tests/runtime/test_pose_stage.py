"""Tests of spacepose.pose_stage: votes -> MeanShift -> fit -> validity and confidence."""

import math

import numpy as np
import pytest

from spacepose.bundle import VotingConfig
from spacepose.errors import ShapeError
from spacepose.pose_stage import depth_sigma, solve_pose, voting_bandwidth

KP = np.array([[2.4, 0.0, 0.2], [-2.4, 0.0, 0.2], [0.0, 1.5, 0.0], [0.0, -1.5, 0.0],
               [0.5, 0.5, 1.0], [-0.5, -0.5, -0.3], [1.2, -0.8, 0.6], [-1.0, 1.0, 0.8]])
CENTRE = np.array([0.1, -0.2, 0.3])
CONFIG = VotingConfig(min_points=32)
COMMON = dict(config=CONFIG, diameter_m=6.0, distance_range_m=(10.0, 50.0), focal_px=800.0, baseline_m=1.0)


def _rotation(seed):
    q = np.random.default_rng(seed).normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _scene(R, t, n=400, noise=0.0, seed=0, keypoints=KP):
    """Points on the target, graph outputs that vote for the true keypoints (+ noise)."""
    rng = np.random.default_rng(seed)
    points = (rng.uniform(-2, 2, size=(n, 3)) @ R.T + t).astype(np.float64)
    kp_cam = keypoints @ R.T + t
    ctr_cam = R @ CENTRE + t
    kp_off = kp_cam[:, None, :] - points[None] + noise * rng.normal(size=(len(keypoints), n, 3))
    ctr_off = ctr_cam - points + noise * rng.normal(size=(n, 3))
    seg = np.tile([-5.0, 5.0], (n, 1))
    return points, seg[None].astype(np.float32), kp_off[None].astype(np.float32), ctr_off[None].astype(np.float32)


class TestBandwidth:
    def test_depth_sigma(self):
        assert depth_sigma(10.0, 800.0, 1.0, 0.5) == pytest.approx(100 * 0.5 / 800)

    def test_size_term_near_noise_term_far(self):
        near = voting_bandwidth(10.0, 6.0, CONFIG, 800.0, 1.0)
        far = voting_bandwidth(50.0, 6.0, CONFIG, 800.0, 1.0)
        assert near == pytest.approx(max(CONFIG.bandwidth_fraction * 6.0, CONFIG.k_sigma * 100 * 0.25 / 800))
        assert far == pytest.approx(CONFIG.k_sigma * 2500 * 0.25 / 800)
        assert far > near


class TestSolvePose:
    @pytest.mark.parametrize("seed", [0, 1, 2])
    def test_exact_votes_exact_pose(self, seed):
        R, t = _rotation(seed), np.array([0.5, -1.0, 20.0 + 5 * seed])
        res = solve_pose(*_scene(R, t, seed=seed), KP, CENTRE, **COMMON)
        assert res.valid and res.status == "ok"
        np.testing.assert_allclose(res.R, R, atol=1e-5)
        np.testing.assert_allclose(res.t, t, atol=1e-4)
        assert res.fit_rms < 1e-4
        assert 0.99 < res.confidence <= 1.0
        assert res.n_target == res.n_inliers == 400

    def test_noisy_votes_lower_confidence_still_close(self):
        R, t = _rotation(3), np.array([0.0, 0.0, 15.0])
        exact = solve_pose(*_scene(R, t), KP, CENTRE, **COMMON)
        noisy = solve_pose(*_scene(R, t, noise=0.1), KP, CENTRE, **COMMON)
        assert noisy.valid
        assert np.linalg.norm(noisy.t - t) < 0.1
        assert 0.0 < noisy.confidence < exact.confidence

    def test_unbatched_outputs_accepted(self):
        R, t = _rotation(4), np.array([0.0, 0.0, 30.0])
        pts, seg, kp, ctr = _scene(R, t)
        res = solve_pose(pts, seg[0], kp[0], ctr[0], KP, CENTRE, **COMMON)
        assert res.valid

    def test_scattered_votes_are_weak(self):
        R, t = _rotation(5), np.array([0.0, 0.0, 12.0])
        pts, seg, kp, ctr = _scene(R, t)
        rng = np.random.default_rng(1)
        ctr = ctr + rng.uniform(-20, 20, size=ctr.shape).astype(np.float32)
        res = solve_pose(pts, seg, kp, ctr, KP, CENTRE, **COMMON)
        assert not res.valid and res.status in ("weak_votes", "too_few_points")
        assert res.confidence == 0.0 and np.all(np.isnan(res.R))

    def test_scattered_keypoint_votes_are_weak(self):
        R, t = _rotation(6), np.array([0.0, 0.0, 12.0])
        pts, seg, kp, ctr = _scene(R, t)
        kp = kp + np.random.default_rng(2).uniform(-20, 20, size=kp.shape).astype(np.float32)
        res = solve_pose(pts, seg, kp, ctr, KP, CENTRE, **COMMON)
        assert not res.valid and res.status == "weak_votes"

    def test_min_keypoints_rejects_fits_on_too_few_agreeing_keypoints(self):
        R, t = _rotation(8), np.array([0.0, 0.0, 14.0])
        pts, seg, kp, ctr = _scene(R, t)
        kp[0, 4:] += np.random.default_rng(3).uniform(-20, 20, size=kp[0, 4:].shape).astype(np.float32)
        loose = solve_pose(pts, seg, kp, ctr, KP, CENTRE, **COMMON)          # 4 agreeing keypoints >= 3
        assert loose.valid
        strict = dict(COMMON, config=VotingConfig(min_points=32, min_keypoints=6))
        res = solve_pose(pts, seg, kp, ctr, KP, CENTRE, **strict)
        assert not res.valid and res.status == "weak_votes" and np.all(np.isnan(res.t))

    def test_min_confidence_turns_a_weak_pose_invalid(self):
        R, t = _rotation(3), np.array([0.0, 0.0, 15.0])
        noisy = solve_pose(*_scene(R, t, noise=0.1), KP, CENTRE, **COMMON)
        assert noisy.valid and noisy.confidence < 0.99
        above = dict(COMMON, config=VotingConfig(min_points=32, min_confidence=noisy.confidence + 1e-3))
        below = dict(COMMON, config=VotingConfig(min_points=32, min_confidence=noisy.confidence - 1e-3))
        rejected = solve_pose(*_scene(R, t, noise=0.1), KP, CENTRE, **above)
        assert not rejected.valid and rejected.status == "weak_votes" and rejected.confidence == 0.0
        assert solve_pose(*_scene(R, t, noise=0.1), KP, CENTRE, **below).valid

    def test_flip_guard_mirrored_votes(self):
        """Votes for a mirror image of the model: the fit stays a rotation and is rejected."""
        R, t = _rotation(7), np.array([0.0, 0.0, 20.0])
        mirrored = KP * np.array([-1.0, 1.0, 1.0])
        centre_m = CENTRE * np.array([-1.0, 1.0, 1.0])
        pts, seg, kp, ctr = _scene(R, t, keypoints=mirrored)
        ctr = (R @ centre_m + t - pts)[None].astype(np.float32)
        res = solve_pose(pts, seg, kp, ctr, KP, CENTRE, **COMMON)
        assert not res.valid and res.status == "fit_residual"
        assert res.fit_rms > res.bandwidth

    def test_fit_rotation_is_proper(self):
        R, t = _rotation(8), np.array([1.0, 2.0, 25.0])
        res = solve_pose(*_scene(R, t, noise=0.05), KP, CENTRE, **COMMON)
        assert np.linalg.det(res.R) == pytest.approx(1.0)

    def test_no_target(self):
        R, t = _rotation(9), np.array([0.0, 0.0, 20.0])
        pts, seg, kp, ctr = _scene(R, t)
        res = solve_pose(pts, -seg, kp, ctr, KP, CENTRE, **COMMON)
        assert (res.valid, res.status, res.confidence) == (False, "no_target", 0.0)

    def test_too_few_points(self):
        R, t = _rotation(10), np.array([0.0, 0.0, 20.0])
        pts, seg, kp, ctr = _scene(R, t)
        seg = seg.copy()
        seg[0, 10:] = [5.0, -5.0]
        res = solve_pose(pts, seg, kp, ctr, KP, CENTRE, **COMMON)
        assert res.status == "too_few_points" and res.n_target == 10

    def test_out_of_range(self):
        R, t = _rotation(11), np.array([0.0, 0.0, 90.0])
        res = solve_pose(*_scene(R, t), KP, CENTRE, **COMMON)
        assert not res.valid and res.status == "out_of_range"
        np.testing.assert_allclose(res.t, t, atol=1e-3)  # the pose is reported, but not valid

    def test_non_finite_outputs(self):
        R, t = _rotation(12), np.array([0.0, 0.0, 20.0])
        pts, seg, kp, ctr = _scene(R, t)
        res = solve_pose(pts, seg, kp, np.full_like(ctr, np.nan), KP, CENTRE, **COMMON)
        assert res.status == "bad_input"
        # a few NaN rows are just dropped
        ctr = ctr.copy()
        ctr[0, :5] = np.nan
        assert solve_pose(pts, seg, kp, ctr, KP, CENTRE, **COMMON).valid

    def test_offset_sign(self):
        R, t = _rotation(13), np.array([0.0, 0.0, 20.0])
        pts, seg, kp, ctr = _scene(R, t)
        res = solve_pose(pts, seg, -kp, -ctr, KP, CENTRE, offset_sign=-1, **COMMON)
        assert res.valid
        np.testing.assert_allclose(res.t, t, atol=1e-4)

    @pytest.mark.parametrize("bad", ["points", "seg", "kp", "model"])
    def test_shape_errors(self, bad):
        R, t = _rotation(14), np.array([0.0, 0.0, 20.0])
        pts, seg, kp, ctr = _scene(R, t)
        model = KP
        if bad == "points":
            pts = pts[:, :2]
        elif bad == "seg":
            seg = seg[:, :-1]
        elif bad == "kp":
            kp = kp[..., :2]
        else:
            model = KP[:3]
        with pytest.raises(ShapeError):
            solve_pose(pts, seg, kp, ctr, model, CENTRE, **COMMON)

    def test_confidence_formula_factors(self):
        R, t = _rotation(15), np.array([0.0, 0.0, 20.0])
        res = solve_pose(*_scene(R, t, noise=0.05), KP, CENTRE, **COMMON)
        f = res.factors
        assert set(f) == {"cluster", "keypoints", "fit", "points"}
        assert res.confidence == pytest.approx(math.prod(f.values()))
        assert all(0.0 <= v <= 1.0 for v in f.values())


class TestSurfaceFitness:
    SURFACE = np.random.default_rng(0).uniform(-2.0, 2.0, size=(600, 3)) * np.array([1.0, 0.6, 0.2])

    def test_right_pose_fits_wrong_pose_does_not(self):
        from spacepose.pose_stage import surface_fitness

        R, t = _rotation(11), np.array([1.0, -0.5, 25.0])
        observed = self.SURFACE[:300] @ R.T + t + np.random.default_rng(1).normal(0, 0.02, (300, 3))
        assert surface_fitness(R, t, observed, self.SURFACE, 0.1) > 0.95
        flipped = R @ np.diag([-1.0, -1.0, 1.0])  # 180 deg about the body z axis: a different surface
        assert surface_fitness(flipped, t + np.array([0.0, 0.0, 1.5]), observed, self.SURFACE, 0.1) < 0.3
        assert surface_fitness(R, t + np.array([0.0, 0.0, 3.0]), observed, self.SURFACE, 0.1) == 0.0

    @pytest.mark.parametrize("tol", [0.02, 0.1, 0.3])
    def test_equals_a_kdtree_count(self, tol):
        from scipy.spatial import cKDTree

        from spacepose.pose_stage import surface_fitness

        R, t = _rotation(5), np.array([0.3, 0.2, 30.0])
        observed = self.SURFACE @ R.T + t + np.random.default_rng(2).normal(0, 0.1, (600, 3))
        dist, _ = cKDTree(self.SURFACE @ R.T + t).query(observed)
        assert surface_fitness(R, t, observed, self.SURFACE, tol) == pytest.approx(np.mean(dist <= tol), abs=1e-12)

    def test_degenerate_inputs(self):
        from spacepose.pose_stage import surface_fitness

        assert surface_fitness(np.eye(3), np.zeros(3), np.zeros((0, 3)), self.SURFACE, 0.1) == 0.0
        assert surface_fitness(np.full((3, 3), np.nan), np.zeros(3), self.SURFACE, self.SURFACE, 0.1) == 0.0
        with pytest.raises(ShapeError, match="points"):
            surface_fitness(np.eye(3), np.zeros(3), np.zeros((5, 2)), self.SURFACE, 0.1)
