import cv2
import numpy as np
import pytest

from spacepose import roi
from spacepose.errors import ShapeError
from spacepose.geometry import crop_intrinsics, resize_intrinsics


class TestSquareWindow:
    def test_holds_target_and_shifted_copy(self):
        bbox, d_min, d_max = (200, 100, 300, 180), 20.0, 40.0
        w = roi.square_window(bbox, d_min, d_max, margin=1.2)
        x0, y0, x1, y1 = w.bbox
        assert x1 - x0 == y1 - y0 == w.side
        assert x0 <= 200 - 40 and x1 >= 300 and y0 <= 100 and y1 >= 180

    def test_min_side_and_max_disp(self):
        w = roi.square_window((10, 10, 14, 14), 0.0, 2.0, 1.0, min_side=32)
        assert w.side == 32
        w2 = roi.square_window((0, 0, 50, 50), 90.0, 100.0, 1.0, out_side=256, max_disp=96)
        assert 100.0 * 256 / w2.side <= 0.9 * 96 + 1e-6

    def test_bad_input(self):
        with pytest.raises(ValueError, match="empty bbox"):
            roi.square_window((5, 5, 5, 9), 0, 1)
        with pytest.raises(ValueError, match="d_min"):
            roi.square_window((0, 0, 5, 5), 3, 1)
        with pytest.raises(ValueError, match="margin"):
            roi.square_window((0, 0, 5, 5), 0, 1, margin=0.5)


class TestCropResize:
    def test_zero_padding_and_values(self):
        img = np.arange(100 * 120, dtype=np.float32).reshape(100, 120)
        view, t = roi.crop_resize(img, roi.Window(-10, -10, 40), (40, 40))
        assert view.shape == (40, 40) and t.scale == 1.0
        assert np.all(view[:10] == 0) and np.all(view[:, :10] == 0)
        np.testing.assert_array_equal(view[10:, 10:], img[:30, :30])

    def test_transform_matches_geometry_intrinsics(self):
        K = np.array([[800.0, 0, 319.5], [0, 800.0, 239.5], [0, 0, 1]])
        w = roi.Window(100, 50, 200)
        t = roi.window_transform(w, (256, 256))
        s = 256 / 200
        ref = resize_intrinsics(crop_intrinsics(K, 100, 50), s, s)
        np.testing.assert_allclose(t.intrinsics(K), ref, atol=1e-9)

    def test_pixel_mapping_roundtrip(self):
        t = roi.window_transform(roi.Window(30, 40, 128), (256, 256))
        p = np.array([[30.0, 40.0], [100.5, 77.25]])
        np.testing.assert_allclose(t.to_full(t.to_net(p)), p)
        # pixel centre 30 of the window's first column maps to net u' = (0 + 0.5) * 2 - 0.5
        np.testing.assert_allclose(t.to_net(p[:1]), [[0.5, 0.5]])

    def test_upsample_a_point_lands_where_mapped(self):
        img = np.zeros((64, 64), np.float32)
        img[20, 33] = 1.0
        view, t = roi.crop_resize(img, roi.Window(16, 8, 32), (128, 128), nearest=True)
        u, v = t.to_net(np.array([[33.0, 20.0]]))[0]
        ys, xs = np.nonzero(view)
        assert abs(xs.mean() - u) < 0.6 and abs(ys.mean() - v) < 0.6

    def test_rejects_non_image(self):
        with pytest.raises(ShapeError):
            roi.crop_resize(np.zeros(5), roi.Window(0, 0, 4), (8, 8))


class TestLetterbox:
    @pytest.mark.parametrize("size", [(640, 480), (1280, 960), (320, 240), (300, 200)])
    def test_aspect_kept_and_centred(self, size):
        img = np.full((size[1], size[0], 3), 200, np.uint8)
        view, t = roi.letterbox(img, (256, 256))
        assert view.shape == (256, 256, 3) and view.dtype == np.uint8
        assert abs(t.sx - t.sy) < 0.02
        rows = np.flatnonzero(view[:, 128, 0] > 0)
        assert abs((rows[0] + rows[-1]) / 2 - 127.5) <= 1.0
        assert view[0, 0, 0] == 0

    def test_disparity_roundtrip(self):
        disp = np.zeros((480, 640), np.float32)
        disp[100:300, 200:400] = 40.0
        view, t = roi.letterbox(disp, (256, 256), nearest=True)
        assert np.isclose(view.max(), 40.0)
        back = roi.warp_to_full(view * t.scale, t, (640, 480), nearest=True) / t.scale
        assert np.isclose(back[200, 300], 40.0) and back[50, 50] == 0.0


class TestWarpToFull:
    def test_outside_window_is_zero(self):
        t = roi.window_transform(roi.Window(50, 50, 100), (64, 64))
        full = roi.warp_to_full(np.ones((64, 64), np.float32), t, (200, 200))
        assert full[100, 100] == 1.0 and full[10, 10] == 0.0 and full[100, 160] == 0.0

    @pytest.mark.parametrize("window, nearest", [(roi.Window(50, 40, 100), False), (roi.Window(-30, 150, 77), True),
                                                  (roi.Window(170, -5, 45), False)])
    def test_equals_whole_frame_warp(self, window, nearest):
        """Resampling only the window's box gives the whole-frame warp with the outside zeroed (to 1e-4)."""
        t = roi.window_transform(window, (64, 64))
        net = np.random.default_rng(0).uniform(1, 9, (64, 64)).astype(np.float32)
        flags = (cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR) | cv2.WARP_INVERSE_MAP
        ref = cv2.warpAffine(net, t.matrix, (200, 180), flags=flags, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        u = np.arange(200) * t.sx + t.tx
        v = np.arange(180) * t.sy + t.ty
        ref[~((v >= -0.5) & (v <= 63.5)), :] = 0.0
        ref[:, ~((u >= -0.5) & (u <= 63.5))] = 0.0
        out = roi.warp_to_full(net, t, (200, 180), nearest=nearest)
        assert out.dtype == np.float32 and out.shape == (180, 200)
        # OpenCV's fixed-point bilinear weights round a little differently for a shifted output box
        np.testing.assert_allclose(out, ref, atol=1e-3)
        assert np.count_nonzero(out) > 0

    def test_window_outside_the_frame_gives_zeros(self):
        t = roi.window_transform(roi.Window(500, 500, 50), (64, 64))
        assert not roi.warp_to_full(np.ones((64, 64), np.float32), t, (200, 180)).any()

    def test_shape_check(self):
        t = roi.window_transform(roi.Window(0, 0, 10), (64, 64))
        with pytest.raises(ShapeError):
            roi.warp_to_full(np.ones((32, 32)), t, (100, 100))


class TestBBoxFromDisparity:
    def test_finds_target_ignores_speckle(self):
        d = np.zeros((100, 120), np.float32)
        d[30:60, 40:90] = 10.0
        d[5, 5] = 10.0  # a lone speckle pixel
        assert roi.bbox_from_disparity(d, 2.0) == (40, 30, 90, 60)

    def test_none_when_empty(self):
        assert roi.bbox_from_disparity(np.zeros((50, 50), np.float32), 1.0) is None
        assert roi.bbox_from_mask(np.zeros((4, 4), bool)) is None

    def test_disparity_range(self):
        d = np.zeros((10, 10), np.float32)
        d[2:8, 2:8] = np.linspace(5, 15, 36).reshape(6, 6)
        lo, hi = roi.disparity_range(d, threshold=1.0, percentiles=(0, 100))
        assert lo == pytest.approx(5.0) and hi == pytest.approx(15.0)
