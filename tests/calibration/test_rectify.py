"""Tests of spacepose.calibration.rectify: rectified geometry, Q, remap tables and the ideal-rig shortcut."""

from __future__ import annotations

import pickle
import threading

import cv2
import numpy as np
import pytest

from spacepose.calibration.rectify import Rectification, rectify
from spacepose.calibration.rig import StereoRig, paper_rig
from spacepose.errors import CalibrationError, ShapeError

WIDTH, HEIGHT = 640, 480


def distorted_rig() -> StereoRig:
    M1 = np.array([[800.0, 0.0, 321.0], [0.0, 798.0, 242.0], [0.0, 0.0, 1.0]])
    M2 = np.array([[806.0, 0.0, 316.0], [0.0, 804.0, 237.0], [0.0, 0.0, 1.0]])
    R, _ = cv2.Rodrigues(np.array([0.01, -0.03, 0.008]))
    return StereoRig(M1, [-0.1, 0.02, 0, 0, 0], M2, [-0.09, 0.015, 0, 0, 0], R, [-0.12, 0.001, -0.002], (WIDTH, HEIGHT))


def opencv_rectify(rig: StereoRig, alpha: float):
    return cv2.stereoRectify(
        rig.M1, rig.D1, rig.M2, rig.D2, rig.image_size, rig.R, rig.T.reshape(3, 1),
        flags=cv2.CALIB_ZERO_DISPARITY, alpha=alpha,
    )


class TestIdealRig:
    @pytest.mark.parametrize("size", [(1280, 960), (640, 480), (320, 240)])
    def test_is_identity_and_returns_inputs(self, size):
        rig = paper_rig(*size)
        rect = rectify(rig)
        assert rect.is_identity
        np.testing.assert_array_equal(rect.K, rig.M1)
        assert rect.focal_px == rig.M1[0, 0] and rect.baseline_m == 1.0
        rng = np.random.default_rng(0)
        left = rng.integers(0, 256, (size[1], size[0], 3), dtype=np.uint8)
        right = rng.integers(0, 256, (size[1], size[0]), dtype=np.uint8)
        out_left, out_right = rect.rectify_pair(left, right)
        assert out_left is left and out_right is right

    def test_q_is_opencv_q(self):
        rig = paper_rig()
        rect = rectify(rig)
        _, _, P1, P2, Q, _, _ = opencv_rectify(rig, 0.0)
        np.testing.assert_allclose(rect.Q, Q, rtol=0, atol=1e-12)
        np.testing.assert_allclose(rect.P1, P1, rtol=0, atol=1e-12)
        np.testing.assert_allclose(rect.P2, P2, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(rect.Q[3, 2:], [1.0, 0.0])  # -1/Tx with Tx = -1 m

    def test_anisotropic_scaling_is_not_identity(self):
        rect = rectify(paper_rig(256, 256))  # fx != fy: stereoRectify resamples
        assert not rect.is_identity

    @pytest.mark.parametrize(
        "rig",
        [
            StereoRig(np.diag([800.0, 800, 1]), [0.01, 0, 0, 0], np.diag([800.0, 800, 1]), np.zeros(4), np.eye(3), [-0.1, 0, 0], (640, 480)),
            StereoRig(np.diag([800.0, 800, 1]), np.zeros(5), np.diag([801.0, 800, 1]), np.zeros(5), np.eye(3), [-0.1, 0, 0], (640, 480)),
            StereoRig(np.diag([800.0, 800, 1]), np.zeros(5), np.diag([800.0, 800, 1]), np.zeros(5), cv2.Rodrigues(np.array([0, 0.01, 0]))[0], [-0.1, 0, 0], (640, 480)),
            StereoRig(np.diag([800.0, 800, 1]), np.zeros(5), np.diag([800.0, 800, 1]), np.zeros(5), np.eye(3), [-0.1, 0.001, 0], (640, 480)),
        ],
        ids=["distortion", "focal", "rotation", "vertical-offset"],
    )
    def test_non_ideal_rigs_are_not_identity(self, rig):
        assert not rectify(rig).is_identity


class TestDistortedRig:
    @pytest.mark.parametrize("alpha", [0.0, 0.5, 1.0, -1.0])
    def test_matches_opencv(self, alpha):
        rig = distorted_rig()
        rect = rectify(rig, alpha)
        R1, R2, P1, P2, Q, roi1, roi2 = opencv_rectify(rig, alpha)
        for ours, theirs in ((rect.R1, R1), (rect.R2, R2), (rect.P1, P1), (rect.P2, P2), (rect.Q, Q)):
            np.testing.assert_allclose(ours, theirs, rtol=1e-12, atol=1e-12)
        assert rect.roi1 == tuple(roi1) and rect.roi2 == tuple(roi2)
        assert not rect.is_identity
        assert rect.focal_px == pytest.approx(P1[0, 0], rel=1e-12)
        assert rect.baseline_m == pytest.approx(rig.baseline_m, rel=1e-9)
        np.testing.assert_array_equal(rect.K, P1[:, :3])

    def test_rectified_points_are_row_aligned_with_disparity_fb_over_z(self):
        rig = distorted_rig()
        rect = rectify(rig)
        rng = np.random.default_rng(1)
        X_left = np.column_stack([rng.uniform(-0.5, 0.5, 50), rng.uniform(-0.4, 0.4, 50), rng.uniform(1.0, 5.0, 50)])
        X_right = X_left @ rig.R.T + rig.T
        rect_left = X_left @ rect.R1.T
        rect_right = X_right @ rect.R2.T
        homog = lambda X: np.hstack([X, np.ones((len(X), 1))])  # noqa: E731
        uv_left = (rect.P1 @ homog(rect_left).T).T
        uv_left = uv_left[:, :2] / uv_left[:, 2:]
        uv_right = (rect.K @ rect_right.T).T
        uv_right = uv_right[:, :2] / uv_right[:, 2:]
        np.testing.assert_allclose(uv_left[:, 1], uv_right[:, 1], atol=1e-9)
        disparity = uv_left[:, 0] - uv_right[:, 0]
        np.testing.assert_allclose(disparity, rect.focal_px * rect.baseline_m / rect_left[:, 2], rtol=1e-9)

    @pytest.mark.parametrize("rig", [paper_rig(WIDTH, HEIGHT), distorted_rig()], ids=["ideal", "distorted"])
    def test_reproject_image_to_3d_gives_fb_over_d(self, rig):
        rect = rectify(rig)
        disparity = np.random.default_rng(2).uniform(5.0, 80.0, (HEIGHT, WIDTH)).astype(np.float32)
        points = cv2.reprojectImageTo3D(disparity, rect.Q)
        np.testing.assert_allclose(points[..., 2], rect.focal_px * rect.baseline_m / disparity, rtol=1e-5)
        # x, y follow the rectified left camera: X = (u - cx) Z / f
        u = np.arange(WIDTH, dtype=np.float64)[None, :]
        np.testing.assert_allclose(points[..., 0], (u - rect.K[0, 2]) * points[..., 2] / rect.focal_px, rtol=1e-4, atol=1e-4)

    @pytest.mark.parametrize("side", ["left", "right"])
    def test_remap_samples_the_distorted_raw_pixel(self, side):
        """Rectified pixel (u, v) must read raw pixel projectPoints(Ri^T K^-1 [u, v, 1]) of camera i."""
        rig = distorted_rig()
        rect = rectify(rig)
        M, D, R = (rig.M1, rig.D1, rect.R1) if side == "left" else (rig.M2, rig.D2, rect.R2)
        ys, xs = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float32)
        raw_x = rect.rectify_image(xs, side)
        raw_y = rect.rectify_image(ys, side)
        rng = np.random.default_rng(3)
        u = rng.integers(40, WIDTH - 40, 200)
        v = rng.integers(40, HEIGHT - 40, 200)
        rays = np.linalg.inv(rect.K) @ np.vstack([u, v, np.ones_like(u)])
        expected, _ = cv2.projectPoints((R.T @ rays).T.astype(np.float64), np.zeros(3), np.zeros(3), M, D)
        expected = expected.reshape(-1, 2)
        # CV_16SC2 maps are fixed point (1/32 px)
        np.testing.assert_allclose(raw_x[v, u], expected[:, 0], atol=0.05)
        np.testing.assert_allclose(raw_y[v, u], expected[:, 1], atol=0.05)
        assert raw_x.dtype == np.float32 and raw_x.shape == (HEIGHT, WIDTH)


class TestRectifyPair:
    @pytest.mark.parametrize("shape, dtype", [((HEIGHT, WIDTH), np.uint8), ((HEIGHT, WIDTH, 3), np.uint8),
                                              ((HEIGHT, WIDTH, 3), np.uint16), ((HEIGHT, WIDTH, 1), np.uint8)])
    def test_keeps_shape_and_dtype(self, shape, dtype):
        rect = rectify(distorted_rig())
        image = np.full(shape, 100, dtype=dtype)
        left, right = rect.rectify_pair(image, image.copy())
        assert left.shape == shape and right.shape == shape and left.dtype == dtype
        assert left[HEIGHT // 2, WIDTH // 2].max() == 100  # the centre stays inside the image

    def test_maps_are_computed_once(self):
        rect = rectify(distorted_rig())
        results = []
        threads = [threading.Thread(target=lambda: results.append(rect.rectify_maps())) for _ in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert all(r is results[0] for r in results) and rect.rectify_maps() is results[0]
        (map1, map2), _ = results[0]
        assert map1.shape == (HEIGHT, WIDTH, 2) and map1.dtype == np.int16

    def test_pickle_drops_the_cache(self):
        rect = rectify(distorted_rig())
        rect.rectify_maps()
        clone = pickle.loads(pickle.dumps(rect))
        assert isinstance(clone, Rectification) and clone._maps is None
        np.testing.assert_array_equal(clone.Q, rect.Q)
        image = np.zeros((HEIGHT, WIDTH), np.uint8)
        assert clone.rectify_pair(image, image)[0].shape == (HEIGHT, WIDTH)

    def test_bad_inputs(self):
        rect = rectify(distorted_rig())
        good = np.zeros((HEIGHT, WIDTH), np.uint8)
        with pytest.raises(CalibrationError) as info:
            rect.rectify_pair(np.zeros((HEIGHT, WIDTH + 2), np.uint8), good)
        assert info.value.key == "image_width"
        with pytest.raises(CalibrationError) as info:
            rect.rectify_pair(good, np.zeros((HEIGHT // 2, WIDTH), np.uint8))
        assert info.value.key == "image_height"
        with pytest.raises(ShapeError):
            rect.rectify_pair(good.tolist(), good)
        with pytest.raises(ShapeError):
            rect.rectify_pair(good, np.zeros((HEIGHT, WIDTH, 2), np.uint8))
        with pytest.raises(ValueError):
            rect.rectify_image(good, side="middle")
        ideal = rectify(paper_rig(WIDTH, HEIGHT))
        with pytest.raises(CalibrationError):  # the shortcut still checks sizes
            ideal.rectify_pair(np.zeros((960, 1280), np.uint8), np.zeros((960, 1280), np.uint8))


class TestRectifyArguments:
    @pytest.mark.parametrize("alpha", [1.5, -0.5, float("nan")])
    def test_bad_alpha(self, alpha):
        with pytest.raises(ValueError, match="alpha"):
            rectify(paper_rig(), alpha)

    def test_not_a_rig(self):
        with pytest.raises(TypeError):
            rectify({"M1": np.eye(3)})

    @pytest.mark.parametrize("T", [[0.1, 0, 0], [0.01, -0.1, 0], [0.0, 0, 0.1]], ids=["swapped", "vertical", "forward"])
    def test_rig_that_is_not_left_right(self, T):
        K = np.diag([800.0, 800.0, 1.0])
        rig = StereoRig(K, np.zeros(5), K, np.zeros(5), np.eye(3), T, (640, 480))
        with pytest.raises(CalibrationError) as info:
            rectify(rig)
        assert info.value.key == "T"
