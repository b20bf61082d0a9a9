"""Tests of spacepose.geometry: disparity/depth, back-projection (vs OpenCV), sampling, intrinsics."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import cv2
import numpy as np
import pytest

from spacepose.errors import ShapeError
from spacepose.geometry import (
    BackProjection,
    backproject,
    crop_intrinsics,
    depth_to_disparity,
    disparity_to_depth,
    project,
    resize_intrinsics,
    sample_indices,
)

# paper rig (spec/CONVENTIONS.md)
F_PX = 1600.0
CX, CY = 639.5, 479.5
BASELINE = 1.0
K_PAPER = np.array([[F_PX, 0.0, CX], [0.0, F_PX, CY], [0.0, 0.0, 1.0]])

RTOL32 = 1e-6  # float32 outputs
ATOL64 = 1e-12  # float64 outputs


class TestDisparityToDepth:
    def test_paper_rig_values(self):
        disparity = np.array([[160.0, 32.0], [0.0, -5.0]], dtype=np.float32)
        depth = disparity_to_depth(disparity, F_PX, BASELINE)
        assert depth.dtype == np.float32 and depth.shape == (2, 2)
        np.testing.assert_allclose(depth, [[10.0, 50.0], [0.0, 0.0]], rtol=RTOL32)

    def test_non_finite_is_invalid(self):
        disparity = np.array([[np.nan, np.inf, -np.inf, 80.0]], dtype=np.float64)
        depth = disparity_to_depth(disparity, F_PX, BASELINE)
        np.testing.assert_array_equal(depth, np.array([[0.0, 0.0, 0.0, 20.0]], dtype=np.float32))

    def test_round_trip(self):
        rng = np.random.default_rng(0)
        depth = rng.uniform(10.0, 50.0, size=(7, 9)).astype(np.float32)
        depth[0, 0] = 0.0
        back = disparity_to_depth(depth_to_disparity(depth, F_PX, BASELINE), F_PX, BASELINE)
        np.testing.assert_allclose(back, depth, rtol=1e-6)
        assert back[0, 0] == 0.0

    def test_depth_to_disparity_values(self):
        depth = np.array([[10.0, 50.0, 0.0, np.inf]], dtype=np.float32)
        np.testing.assert_allclose(depth_to_disparity(depth, F_PX, BASELINE), [[160.0, 32.0, 0.0, 0.0]], rtol=RTOL32)

    @pytest.mark.parametrize("func", [disparity_to_depth, depth_to_disparity])
    def test_bad_input(self, func):
        with pytest.raises(ShapeError, match=r"must have shape \(\*, \*\)"):
            func(np.ones((2, 2, 1), np.float32), F_PX, BASELINE)
        with pytest.raises(ShapeError, match="dtype"):
            func(np.ones((2, 2), np.int32), F_PX, BASELINE)
        with pytest.raises(ShapeError, match="numpy array"):
            func([[1.0]], F_PX, BASELINE)
        with pytest.raises(ValueError, match="focal_px"):
            func(np.ones((2, 2), np.float32), 0.0, BASELINE)
        with pytest.raises(ValueError, match="baseline_m"):
            func(np.ones((2, 2), np.float32), F_PX, float("nan"))


class TestBackproject:
    def test_opencv_reproject_cross_check(self):
        """Our back-projection of Z = f B / d equals cv2.reprojectImageTo3D with OpenCV's own Q."""
        w, h = 64, 48
        K = np.array([[80.0, 0.0, 31.5], [0.0, 80.0, 23.5], [0.0, 0.0, 1.0]])
        baseline = 0.5
        *_, Q, _, _ = cv2.stereoRectify(
            K, np.zeros(5), K, np.zeros(5), (w, h), np.eye(3), np.array([[-baseline], [0.0], [0.0]]),
            flags=cv2.CALIB_ZERO_DISPARITY, alpha=0,
        )
        # OpenCV: Q = [[1,0,0,-cx],[0,1,0,-cy],[0,0,0,f],[0,0,-1/Tx,0]] with Tx = -B, so Q[3,2] = +1/B
        expected_q = np.array([[1, 0, 0, -31.5], [0, 1, 0, -23.5], [0, 0, 0, 80.0], [0, 0, 1 / baseline, 0]])
        np.testing.assert_allclose(Q, expected_q, atol=1e-9)

        rng = np.random.default_rng(1)
        disparity = rng.uniform(1.0, 20.0, size=(h, w)).astype(np.float32)
        disparity[rng.random((h, w)) < 0.2] = 0.0
        reference = cv2.reprojectImageTo3D(disparity, Q)  # (H, W, 3) float32; junk where d == 0

        depth = disparity_to_depth(disparity, 80.0, baseline)
        result = backproject(depth, K)
        assert result.points.shape == (int(np.count_nonzero(disparity)), 3)
        u, v = result.pixels[:, 0], result.pixels[:, 1]
        np.testing.assert_allclose(result.points, reference[v, u], rtol=1e-5, atol=1e-5)

    def test_hand_computed_point(self):
        depth = np.zeros((960, 1280), np.float32)
        depth[479, 1279] = 10.0  # u = 1279, v = 479
        result = backproject(depth, K_PAPER)
        np.testing.assert_array_equal(result.pixels, [[1279, 479]])
        np.testing.assert_allclose(result.points, [[(1279 - CX) * 10.0 / F_PX, (479 - CY) * 10.0 / F_PX, 10.0]], rtol=RTOL32)
        assert result.colors is None and len(result) == 1

    def test_project_inverts_backproject(self):
        rng = np.random.default_rng(2)
        depth = rng.uniform(10.0, 50.0, size=(12, 16)).astype(np.float32)
        K = np.array([[20.0, 0.3, 7.5], [0.0, 22.0, 5.5], [0.0, 0.0, 1.0]])  # with skew
        result = backproject(depth, K)
        np.testing.assert_allclose(project(result.points.astype(np.float64), K), result.pixels, atol=1e-4)

    def test_mask_colours_and_invalid_depth(self):
        depth = np.array([[1.0, 2.0, 0.0], [np.nan, 5.0, 6.0]], np.float32)
        mask = np.array([[True, False, True], [True, True, True]])
        image = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3)
        result = backproject(depth, K_PAPER, mask=mask, image=image)
        # valid: (0,0), (1,1), (1,2) in row-major order; (0,1) masked, (0,2) zero depth, (1,0) NaN
        np.testing.assert_array_equal(result.pixels, [[0, 0], [1, 1], [2, 1]])
        np.testing.assert_allclose(result.points[:, 2], [1.0, 5.0, 6.0])
        assert result.colors.dtype == np.float32
        np.testing.assert_array_equal(result.colors, image[[0, 1, 1], [0, 1, 2]].astype(np.float32))
        grey = backproject(depth, K_PAPER, image=image[:, :, 0])
        assert grey.colors.shape == (4, 1)

    def test_empty(self):
        result = backproject(np.zeros((4, 5), np.float32), K_PAPER)
        assert result.points.shape == (0, 3) and result.pixels.shape == (0, 2)
        assert result.points.dtype == np.float32 and result.pixels.dtype == np.int32

    def test_frozen(self):
        result = backproject(np.ones((2, 2), np.float32), K_PAPER)
        assert isinstance(result, BackProjection)
        with pytest.raises(dataclasses.FrozenInstanceError):
            result.points = np.zeros((0, 3))

    def test_bad_input(self):
        depth = np.ones((4, 5), np.float32)
        with pytest.raises(ShapeError, match=r"depth must have shape"):
            backproject(np.ones((4, 5, 1), np.float32), K_PAPER)
        with pytest.raises(ShapeError, match=r"depth must have dtype"):
            backproject(np.ones((4, 5), np.uint16), K_PAPER)
        with pytest.raises(ShapeError, match=r"K must have shape \(3, 3\)"):
            backproject(depth, np.eye(4))
        with pytest.raises(ShapeError, match=r"K must have dtype"):
            backproject(depth, np.eye(3, dtype=int))
        with pytest.raises(ShapeError, match=r"K must be finite"):
            backproject(depth, np.full((3, 3), np.nan))
        with pytest.raises(ValueError, match=r"fx > 0"):
            backproject(depth, np.diag([0.0, 1.0, 1.0]))
        with pytest.raises(ShapeError, match=r"mask must have shape \(4, 5\)"):
            backproject(depth, K_PAPER, mask=np.ones((5, 4), bool))
        with pytest.raises(ShapeError, match=r"mask must have dtype"):
            backproject(depth, K_PAPER, mask=np.ones((4, 5), np.uint8))
        with pytest.raises(ShapeError, match=r"image must have shape \(4, 5"):
            backproject(depth, K_PAPER, image=np.ones((4, 6, 3), np.uint8))
        with pytest.raises(ShapeError, match=r"image must have an integer or floating dtype"):
            backproject(depth, K_PAPER, image=np.ones((4, 5), bool))


class TestSampleIndices:
    def test_without_replacement(self):
        idx = sample_indices(100, 30, seed=3)
        assert idx.dtype == np.int64 and idx.shape == (30,)
        assert len(np.unique(idx)) == 30 and idx.min() >= 0 and idx.max() < 100

    def test_deterministic(self):
        np.testing.assert_array_equal(sample_indices(50, 20, seed=7), sample_indices(50, 20, seed=7))
        assert not np.array_equal(sample_indices(50, 20, seed=7), sample_indices(50, 20, seed=8))

    def test_pads_by_repetition(self):
        idx = sample_indices(3, 8, seed=0)
        assert idx.shape == (8,)
        counts = np.bincount(idx, minlength=3)
        assert sorted(counts.tolist()) == [2, 3, 3]
        assert set(idx[:3].tolist()) == {0, 1, 2}

    def test_exact_and_zero(self):
        assert sorted(sample_indices(5, 5, seed=0).tolist()) == [0, 1, 2, 3, 4]
        assert sample_indices(5, 0, seed=0).shape == (0,)

    def test_bad_input(self):
        with pytest.raises(ShapeError, match="empty point set"):
            sample_indices(0, 10, seed=0)
        with pytest.raises(ShapeError, match="n_out must be >= 0"):
            sample_indices(10, -1, seed=0)
        with pytest.raises(ShapeError, match="n_available must be an integer"):
            sample_indices(10.0, 3, seed=0)
        with pytest.raises(ShapeError, match="seed must be an integer"):
            sample_indices(10, 3, seed=None)


class TestIntrinsics:
    def test_crop(self):
        K = crop_intrinsics(K_PAPER, 100, 50.0)
        np.testing.assert_allclose(K, [[F_PX, 0, CX - 100], [0, F_PX, CY - 50], [0, 0, 1]], atol=ATOL64)
        assert K.dtype == np.float64 and K is not K_PAPER and K_PAPER[0, 2] == CX

    def test_resize_paper_rig_to_640x480(self):
        K = resize_intrinsics(K_PAPER, 0.5, 0.5)
        # cx' = (639.5 + 0.5) * 0.5 - 0.5 = 319.5: the image centre of a 640 px wide image
        np.testing.assert_allclose(K, [[800.0, 0, 319.5], [0, 800.0, 239.5], [0, 0, 1]], atol=ATOL64)

    def test_resize_matches_cv2_resize(self):
        """A 2x2 bright block whose centre projects from a point lands where the resized K says."""
        K = np.array([[40.0, 0, 15.5], [0, 40.0, 11.5], [0, 0, 1.0]])
        point = np.array([[0.125, -0.025, 1.0]])  # projects to (20.5, 10.5): centre of pixels 20..21, 10..11
        np.testing.assert_allclose(project(point, K), [[20.5, 10.5]], atol=ATOL64)
        image = np.zeros((24, 32), np.float32)
        image[10:12, 20:22] = 1.0
        small = cv2.resize(image, (16, 12), interpolation=cv2.INTER_AREA)
        ys, xs = np.nonzero(small)
        weights = small[ys, xs]
        centroid = np.array([np.sum(xs * weights), np.sum(ys * weights)]) / np.sum(weights)
        np.testing.assert_allclose(project(point, resize_intrinsics(K, 0.5, 0.5))[0], centroid, atol=1e-6)
        # and a 3x upscale with bilinear interpolation keeps the block centre at (cx+0.5)*3-0.5
        big = cv2.resize(image, (96, 72), interpolation=cv2.INTER_LINEAR)
        ys, xs = np.nonzero(big)
        weights = big[ys, xs]
        centroid = np.array([np.sum(xs * weights), np.sum(ys * weights)]) / np.sum(weights)
        np.testing.assert_allclose(project(point, resize_intrinsics(K, 3.0, 3.0))[0], centroid, atol=1e-4)

    def test_bad_input(self):
        with pytest.raises(ShapeError, match=r"K must have shape"):
            crop_intrinsics(np.eye(2), 0, 0)
        with pytest.raises(ShapeError, match=r"K must be finite"):
            resize_intrinsics(np.full((3, 3), np.inf), 1.0, 1.0)
        with pytest.raises(ShapeError, match=r"K must have dtype"):
            resize_intrinsics(np.eye(3, dtype=np.int64), 1.0, 1.0)
        with pytest.raises(ValueError, match="sx"):
            resize_intrinsics(K_PAPER, -1.0, 1.0)
        with pytest.raises(ValueError, match="x0"):
            crop_intrinsics(K_PAPER, float("nan"), 0)


class TestProject:
    def test_hand_computed(self):
        points = np.array([[1.0, -0.5, 10.0], [0.0, 0.0, 50.0], [1.0, 1.0, 0.0], [1.0, 1.0, -2.0]])
        uv = project(points, K_PAPER)
        assert uv.dtype == np.float64 and uv.shape == (4, 2)
        np.testing.assert_allclose(uv[:2], [[CX + 160.0, CY - 80.0], [CX, CY]], atol=ATOL64)
        assert np.all(np.isnan(uv[2:]))

    def test_matches_cv2_project_points(self):
        rng = np.random.default_rng(4)
        points = rng.uniform([-3, -3, 10], [3, 3, 50], size=(20, 3))
        ref, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), K_PAPER, np.zeros(5))
        np.testing.assert_allclose(project(points, K_PAPER), ref[:, 0, :], atol=1e-9)

    def test_bad_input(self):
        with pytest.raises(ShapeError, match=r"points must have shape \(\*, 3\)"):
            project(np.ones((4, 2)), K_PAPER)
        with pytest.raises(ShapeError, match=r"points must have dtype"):
            project(np.ones((4, 3), np.int32), K_PAPER)
        with pytest.raises(ShapeError, match=r"points must be finite"):
            project(np.array([[np.nan, 0.0, 1.0]]), K_PAPER)
        with pytest.raises(ShapeError, match=r"K must have shape"):
            project(np.ones((4, 3)), K_PAPER[:2])


def test_flight_modules_import_no_training_stack():
    """geometry, metrics and imageio are flight runtime: numpy + OpenCV only."""
    code = (
        "import sys; import spacepose.geometry, spacepose.metrics, spacepose.imageio; "
        "bad = [m for m in ('torch', 'scipy', 'sklearn', 'trimesh') if m in sys.modules]; "
        "print(bad); sys.exit(1 if bad else 0)"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stdout + result.stderr
