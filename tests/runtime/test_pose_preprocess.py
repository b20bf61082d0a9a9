"""prepare_pose_inputs: the shared training / flight preprocessing of the pose graph."""

from __future__ import annotations

import numpy as np
import pytest

from spacepose import roi
from spacepose.errors import ShapeError
from spacepose.pose_inputs import PoseInputSpec, pose_input_names
from spacepose.pose_preprocess import (POSE_CROP_MARGIN, PreparedPose, depth_window, pose_crop_window,
                                       prepare_pose_inputs, to_rgb_uint8)

SPEC = PoseInputSpec(n_points=128, k=8, n_levels=2, ratio=4, crop_size=(64, 64), xyz_scale=2.5)
W, H = 160, 120
F, B = 200.0, 1.0
K = np.array([[F, 0.0, 79.5], [0.0, F, 59.5], [0.0, 0.0, 1.0]])


def scene(d: float = 10.0, box=(50, 40, 90, 70)):
    """A textured image and a constant-disparity rectangle (Z = f B / d = 20 m at d = 10)."""
    rng = np.random.default_rng(0)
    image = rng.integers(0, 255, size=(H, W, 3), dtype=np.uint8)
    disp = np.zeros((H, W), np.float32)
    x0, y0, x1, y1 = box
    disp[y0:y1, x0:x1] = d
    return image, disp


class TestPreparePoseInputs:
    def test_ok_feeds_and_geometry(self):
        image, disp = scene()
        out = prepare_pose_inputs(image, disp, K, B, SPEC, seed=3)
        assert isinstance(out, PreparedPose) and out.ok and out.status == "ok"
        assert out.n_valid == 40 * 30
        assert list(out.feeds) == pose_input_names(SPEC.n_levels)
        assert out.feeds["rgb"].shape == (1, 3, 64, 64) and out.feeds["rgb"].dtype == np.float32
        assert out.feeds["points"].shape == (1, 128, 6)
        assert out.xyz_cam.shape == (128, 3) and out.xyz_cam.dtype == np.float64
        np.testing.assert_allclose(out.xyz_cam[:, 2], F * B / 10.0, rtol=1e-6)
        # each point back-projects from its pixel
        u, v = out.pixels[:, 0], out.pixels[:, 1]
        np.testing.assert_allclose(out.xyz_cam[:, 0], (u - K[0, 2]) * 20.0 / F, atol=1e-4)
        np.testing.assert_allclose(out.xyz_cam[:, 1], (v - K[1, 2]) * 20.0 / F, atol=1e-4)
        assert np.all(disp[v, u] > 0)
        # documented normalisation: (xyz - mean of sampled points) / xyz_scale
        mean = out.xyz_cam.mean(axis=0)
        np.testing.assert_allclose(out.xyz_mean, mean, atol=1e-6)
        np.testing.assert_allclose(out.feeds["points"][0, :, :3], (out.xyz_cam - mean) / SPEC.xyz_scale, atol=1e-5)
        # colours are the crop's at each point's crop pixel
        cu, cv = out.crop_pixels[:, 0], out.crop_pixels[:, 1]
        assert np.all((cu >= 0) & (cu < 64) & (cv >= 0) & (cv < 64))
        crop = out.feeds["rgb"][0].transpose(1, 2, 0)
        np.testing.assert_allclose(out.feeds["points"][0, :, 3:6], crop[cv, cu] / 255.0, atol=1e-6)
        np.testing.assert_array_equal(out.feeds["choose"][0], cv * 64 + cu)

    def test_crop_window_covers_all_valid_pixels(self):
        image, disp = scene(box=(50, 40, 90, 70))
        out = prepare_pose_inputs(image, disp, K, B, SPEC)
        assert out.window == pose_crop_window(np.array([[50, 40], [89, 69]]))
        assert out.window.side == int(np.ceil(40 * POSE_CROP_MARGIN))
        np.testing.assert_allclose(out.transform.to_net(out.pixels), out.crop_pixels, atol=0.5 + 1e-9)

    def test_deterministic_per_seed(self):
        image, disp = scene()
        a = prepare_pose_inputs(image, disp, K, B, SPEC, seed=1)
        b = prepare_pose_inputs(image, disp, K, B, SPEC, seed=1)
        c = prepare_pose_inputs(image, disp, K, B, SPEC, seed=2)
        for name in a.feeds:
            np.testing.assert_array_equal(a.feeds[name], b.feeds[name])
        assert not np.array_equal(a.pixels, c.pixels)

    def test_too_few_points_and_no_target(self):
        image, disp = scene(box=(50, 40, 55, 45))  # 25 px
        few = prepare_pose_inputs(image, disp, K, B, SPEC, min_points=64)
        assert few.status == "too_few_points" and not few.ok and few.n_valid == 25 and few.feeds == {}
        none = prepare_pose_inputs(image, np.zeros_like(disp), K, B, SPEC)
        assert none.status == "no_target" and none.n_valid == 0 and none.window is None
        # fewer points than n_points but >= min_points: sampled with repetition
        pad = prepare_pose_inputs(image, disp, K, B, SPEC, min_points=10)
        assert pad.ok and pad.xyz_cam.shape == (128, 3)

    def test_depth_range_filters_points(self):
        image, disp = scene(d=10.0)
        disp[40:50, 50:90] = 2.0  # Z = 100 m: outside the window
        z_lo, z_hi = depth_window((10.0, 50.0), radius_m=3.0, depth_margin=0.2)
        assert (z_lo, z_hi) == pytest.approx((5.0, 63.0))
        out = prepare_pose_inputs(image, disp, K, B, SPEC, depth_range_m=(z_lo, z_hi))
        assert out.n_valid == 40 * 20
        assert np.all(out.xyz_cam[:, 2] < z_hi)

    def test_window_hint_restricts_pixels(self):
        image, disp = scene()
        out = prepare_pose_inputs(image, disp, K, B, SPEC, window_hint=roi.Window(40, 30, 30))  # x,y < 70, 60
        assert out.n_valid == 20 * 20
        assert np.all(out.pixels < [70, 60])
        out2 = prepare_pose_inputs(image, disp, K, B, SPEC, window_hint=(0, 0, 70, 60))
        np.testing.assert_array_equal(out.pixels, out2.pixels)

    def test_same_points_as_the_whole_frame(self):
        # depth and back-projection only run on the box of positive disparities: the points, their
        # order and hence the sample must be those of the whole frame (scattered, NaN, negative values)
        from spacepose.geometry import backproject, disparity_to_depth
        from spacepose.pose_preprocess import sample_indices

        rng = np.random.default_rng(5)
        image = rng.integers(0, 255, size=(H, W, 3), dtype=np.uint8)
        disp = np.where(rng.random((H, W)) < 0.3, rng.uniform(5, 15, (H, W)), 0.0).astype(np.float32)
        disp[:13] = 0.0
        disp[:, 140:] = 0.0
        disp[20, 30], disp[50, 60], disp[70, 20] = np.nan, -3.0, np.inf
        for hint in (None, (25, 18, 120, 100)):
            out = prepare_pose_inputs(image, disp, K, B, SPEC, window_hint=hint, seed=7)
            depth = disparity_to_depth(disp, F, B)
            mask = depth > 0
            if hint is not None:
                box = np.zeros_like(mask)
                box[hint[1]:hint[3], hint[0]:hint[2]] = True
                mask &= box
            ref = backproject(depth, K, mask)
            assert out.n_valid == len(ref)
            idx = sample_indices(len(ref), SPEC.n_points, 7)
            np.testing.assert_array_equal(out.pixels, ref.pixels[idx])
            np.testing.assert_allclose(out.xyz_cam, ref.points[idx], rtol=1e-6, atol=1e-6)
        empty = prepare_pose_inputs(image, np.zeros((H, W), np.float32), K, B, SPEC)
        assert empty.status == "no_target"

    def test_rgb_transform_changes_colours(self):
        image, disp = scene()
        plain = prepare_pose_inputs(image, disp, K, B, SPEC)
        dark = prepare_pose_inputs(image, disp, K, B, SPEC, rgb_transform=lambda c: (c // 2).astype(np.uint8))
        np.testing.assert_allclose(dark.feeds["rgb"], plain.feeds["rgb"] // 2)
        np.testing.assert_array_equal(dark.feeds["points"][..., :3], plain.feeds["points"][..., :3])
        with pytest.raises(ShapeError, match="rgb_transform"):
            prepare_pose_inputs(image, disp, K, B, SPEC, rgb_transform=lambda c: c[:10])

    def test_grey_and_uint16_images(self):
        image, disp = scene()
        grey = image[..., 0]
        out = prepare_pose_inputs(grey, disp, K, B, SPEC)
        assert out.ok
        rgb = out.feeds["rgb"][0]
        np.testing.assert_array_equal(rgb[0], rgb[1])
        np.testing.assert_array_equal(to_rgb_uint8(grey.astype(np.uint16) << 8), to_rgb_uint8(grey))

    def test_shape_errors(self):
        image, disp = scene()
        with pytest.raises(ShapeError):
            prepare_pose_inputs(image, disp[:, :10], K, B, SPEC)
        with pytest.raises(ShapeError):
            prepare_pose_inputs(image, disp.astype(np.int32), K, B, SPEC)
        with pytest.raises(ShapeError):
            prepare_pose_inputs(image[..., :2], disp, K, B, SPEC)
        with pytest.raises(ShapeError, match="window_hint"):
            prepare_pose_inputs(image, disp, K, B, SPEC, window_hint="everywhere")
        with pytest.raises(ValueError):
            depth_window((50.0, 10.0), 3.0)
