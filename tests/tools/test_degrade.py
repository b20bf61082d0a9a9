"""Degradations: speckle noise, Gaussian blur, motion blur (paper Fig. 10)."""

from __future__ import annotations

import numpy as np
import pytest

from spacepose.errors import ShapeError
from spacepose.tools.degrade import DEGRADATIONS, apply_degradations, motion_kernel, sample_degradations, to_uint8


class TestSample:
    def test_every_frame_gets_at_least_one_and_all_occur(self):
        seen = {name: 0 for name in DEGRADATIONS}
        for i in range(400):
            params = sample_degradations(np.random.default_rng(i), 640)
            assert params and set(params) <= set(DEGRADATIONS)
            for name in params:
                seen[name] += 1
        assert all(count > 120 for count in seen.values())

    def test_blur_scales_with_width(self):
        a = sample_degradations(np.random.default_rng(1), 640)
        b = sample_degradations(np.random.default_rng(1), 1280)
        assert set(a) == set(b)
        if "gaussian_blur" in a:
            assert b["gaussian_blur"]["sigma_px"] == pytest.approx(2 * a["gaussian_blur"]["sigma_px"], rel=1e-2)


class TestMotionKernel:
    @pytest.mark.parametrize("length, angle", [(3.0, 0.0), (9.5, 30.0), (13.0, 90.0)])
    def test_normalised_and_oriented(self, length, angle):
        k = motion_kernel(length, angle)
        assert k.sum() == pytest.approx(1.0, abs=1e-6)
        ys, xs = np.nonzero(k > 1e-3)
        c = (k.shape[0] - 1) / 2
        if angle == 0.0:
            assert np.all(ys == c) and xs.max() - xs.min() >= length - 2
        if angle == 90.0:
            assert np.all(xs == c) and ys.max() - ys.min() >= length - 2

    def test_rejects_bad_length(self):
        with pytest.raises(ValueError):
            motion_kernel(0.0, 10.0)


class TestApply:
    def _image(self):
        img = np.zeros((64, 80, 3), np.float32)
        img[20:40, 30:50] = 0.8
        return img

    def test_blurs_keep_mean_and_spread_edges(self):
        img = self._image()
        for params in ({"gaussian_blur": {"sigma_px": 1.5}}, {"motion_blur": {"length_px": 9.0, "angle_deg": 0.0}}):
            out = apply_degradations(img, params, np.random.default_rng(0))
            assert out.shape == img.shape and out.dtype == np.float32
            assert out.mean() == pytest.approx(img.mean(), rel=1e-3)
            assert 0 < out[30, 28, 0] < 0.8  # energy spread across the edge
        vertical = apply_degradations(img, {"motion_blur": {"length_px": 9.0, "angle_deg": 0.0}}, np.random.default_rng(0))
        np.testing.assert_array_equal(vertical[10, :, 0], 0.0)  # horizontal motion does not spread vertically

    def test_speckle_is_multiplicative_noise(self):
        img = self._image()
        out = apply_degradations(img, {"speckle": {"sigma": 0.1, "read_sigma": 0.0}}, np.random.default_rng(0))
        patch = out[20:40, 30:50, 0]
        assert patch.std() == pytest.approx(0.08, rel=0.2)
        np.testing.assert_array_equal(out[:10], 0.0)  # no signal, no read noise -> stays black
        again = apply_degradations(img, {"speckle": {"sigma": 0.1, "read_sigma": 0.0}}, np.random.default_rng(0))
        np.testing.assert_array_equal(out, again)

    def test_output_clipped_and_quantised(self):
        out = apply_degradations(np.full((8, 8, 3), 0.99, np.float32), {"speckle": {"sigma": 0.5}}, np.random.default_rng(0))
        assert out.max() <= 1.0 and out.min() >= 0.0
        q = to_uint8(out)
        assert q.dtype == np.uint8 and q.max() == 255

    def test_bad_shape(self):
        with pytest.raises(ShapeError):
            apply_degradations(np.zeros((4, 4, 3, 2), np.float32), {}, np.random.default_rng(0))
