import numpy as np
import pytest

from spacepose.errors import BundleError, ShapeError
from spacepose.stereo_stage import RoiHint, StereoMatcher, to_net_input, validate_stereo_metadata


def _oracle(target_disp: float):
    """A fake graph: disparity = target_disp * (left view brightness > 0)."""

    def infer(left, right):
        return np.where(left[0].mean(axis=0) > 10, np.float32(target_disp), np.float32(0.0))

    return infer


class TestValidateMetadata:
    def test_ok(self):
        meta = {"kind": "stereo", "input_size": [64, 32], "iters": 2, "max_disp": 96}
        assert validate_stereo_metadata(meta, {"left": [1, 3, 32, 64], "right": [1, 3, 32, 64]}) == ((64, 32), 2, 96.0)

    @pytest.mark.parametrize("meta", [{"kind": "pose", "input_size": [64, 64], "iters": 2},
                                      {"kind": "stereo", "iters": 2},
                                      {"kind": "stereo", "input_size": [64, 64], "iters": 0}])
    def test_bad(self, meta):
        with pytest.raises(BundleError):
            validate_stereo_metadata(meta)

    def test_shape_mismatch(self):
        meta = {"kind": "stereo", "input_size": [64, 64], "iters": 2}
        with pytest.raises(BundleError, match="metadata says"):
            validate_stereo_metadata(meta, {"left": [1, 3, 32, 32], "right": [1, 3, 32, 32]})


def test_to_net_input():
    grey = np.full((4, 5), 7, np.uint8)
    x = to_net_input(grey)
    assert x.shape == (1, 3, 4, 5) and x.dtype == np.float32 and np.all(x == 7)
    x16 = to_net_input(np.full((4, 5, 3), 65535, np.uint16))
    assert np.allclose(x16, 255.0)


class TestMatcherGeometry:
    def _frame(self):
        # the letterbox scale of 160x120 into 64x64 is 0.4: the oracle's 10 net px are 25 frame px
        left = np.zeros((120, 160), np.uint8)
        left[40:80, 60:110] = 200
        right = np.zeros_like(left)
        right[40:80, 35:85] = 200
        return left, right

    def test_coarse_pass_drops_what_matches_at_infinity(self):
        # a textured patch seen identically by both cameras is at infinity (the Earth): a graph that
        # gives it 10 px does not make it the target
        rng = np.random.default_rng(0)
        left = np.zeros((120, 160), np.uint8)
        left[40:80, 60:110] = rng.integers(60, 250, (40, 50))
        m = StereoMatcher.from_callable(_oracle(10.0), (64, 64), iters=2)
        assert m.infinity_check
        res = m.match(left, left.copy())
        assert res.status == "no_target" and res.window is None
        off = StereoMatcher.from_callable(_oracle(10.0), (64, 64), iters=2, infinity_check=False)
        assert off.match(left, left.copy()).status == "fine"
        # the same patch really shifted by 25 px is kept
        right = np.zeros_like(left)
        right[40:80, 35:85] = left[40:80, 60:110]
        assert m.match(left, right).status == "fine"

    def test_coarse_then_fine_window_and_scale(self):
        left, right = self._frame()
        # the oracle outputs 10 net px everywhere it sees target: full-frame disparity is 10 / s
        m = StereoMatcher.from_callable(_oracle(10.0), (64, 64), iters=2, max_disp=96)
        res = m.match(left, right)
        assert res.status == "fine" and res.window is not None
        assert res.disparity.shape == (120, 160) and res.disparity.dtype == np.float32
        x0, y0, x1, y1 = res.coarse_bbox
        assert x0 <= 61 and y0 <= 41 and x1 >= 109 and y1 >= 79
        assert res.scale == pytest.approx(64 / res.window.side)
        assert res.disparity[60, 85] == pytest.approx(10.0 / res.scale, rel=1e-4)
        assert res.disparity[5, 5] == 0.0  # outside the window
        assert {"coarse_ms", "fine_ms", "total_ms"} <= set(res.timings_ms)

    def test_roi_hint_skips_coarse(self):
        left, right = self._frame()
        m = StereoMatcher.from_callable(_oracle(5.0), (64, 64), iters=2)
        res = m.match(left, right, roi_hint=RoiHint((60, 40, 110, 80), 0.0, 8.0))
        assert res.coarse_bbox is None and "coarse_ms" not in res.timings_ms
        w = res.window
        assert w.x0 <= 60 - 8 and w.x0 + w.side >= 110

    def test_no_target(self):
        blank = np.zeros((120, 160), np.uint8)
        m = StereoMatcher.from_callable(_oracle(10.0), (64, 64), iters=2)
        res = m.match(blank, blank)
        assert res.status == "no_target" and res.window is None and not res.disparity.any()

    def test_bad_input(self):
        m = StereoMatcher.from_callable(_oracle(1.0), (64, 64), iters=2)
        with pytest.raises(ShapeError, match="same shape"):
            m.match(np.zeros((40, 40), np.uint8), np.zeros((40, 41), np.uint8))
        with pytest.raises(ShapeError):
            m.match(np.zeros((40, 40, 2), np.uint8), np.zeros((40, 40, 2), np.uint8))


class TestMatcherOnnx:
    def test_runs_real_graph(self, tiny_stereo_graph):
        m = StereoMatcher(tiny_stereo_graph, threads=1)
        assert m.input_size == (64, 64) and m.iters == 2
        rng = np.random.default_rng(0)
        left = (rng.random((96, 128, 3)) * 255).astype(np.uint8)
        res = m.match(left, np.roll(left, -4, axis=1))
        assert res.disparity.shape == (96, 128) and np.all(np.isfinite(res.disparity))
        assert np.all(res.disparity >= 0)
        # the memory arena is on by default (fixed input size: its blocks are reused), and results do
        # not depend on it
        assert m.session.get_session_options().enable_cpu_mem_arena
        plain = StereoMatcher(tiny_stereo_graph, threads=1, mem_arena=False)
        assert not plain.session.get_session_options().enable_cpu_mem_arena
        np.testing.assert_array_equal(plain.match(left, np.roll(left, -4, axis=1)).disparity, res.disparity)

    def test_refuses_other_kind(self, tiny_stereo_graph, tmp_path):
        onnx = pytest.importorskip("onnx")
        from spacepose.onnx_session import write_metadata

        model = onnx.load(str(tiny_stereo_graph))
        write_metadata(model, {"kind": "pose", "input_size": [64, 64], "iters": 2})
        path = tmp_path / "wrong.onnx"
        onnx.save(model, str(path))
        with pytest.raises(BundleError, match="kind"):
            StereoMatcher(path)


def _edge_oracle(calls):
    """A fake graph that measures the disparity of one bright box: per row, the left view's first bright
    column minus the right view's (their last ones where the box is cut by the view's left edge), on
    the left view's bright pixels (counts its calls)."""

    def infer(left, right):
        calls.append(left.shape)
        lb, rb = left[0, 0] > 60, right[0, 0] > 60
        out = np.zeros(lb.shape, np.float32)
        for r in range(lb.shape[0]):
            if lb[r].any() and rb[r].any():
                if lb[r, 0]:   # last bright columns: left minus right
                    out[r, lb[r]] = np.argmax(rb[r, ::-1]) - np.argmax(lb[r, ::-1])
                else:
                    out[r, lb[r]] = np.argmax(lb[r]) - np.argmax(rb[r])
        return out

    return infer


class TestTiledCoarsePass:
    def test_the_view_is_assembled_from_the_tiles(self):
        # a graph that returns each tile's column index shows which tile owns which column: the
        # left neighbour's where tiles overlap (their right-image matches lie left of the tile)
        calls = []

        def columns(left, right):
            calls.append(left.shape)
            return np.broadcast_to(np.arange(64, dtype=np.float32), (64, 64)).copy()

        m = StereoMatcher.from_callable(columns, (64, 64), iters=2, coarse_tiles=2, tile_overlap=8,
                                        infinity_check=False, coarse_threshold=-1.0)
        assert m.coarse_view_size == (120, 120)
        frame = np.full((120, 120), 100, np.uint8)
        disp, t = m.coarse(frame, frame)
        assert len(calls) == 4 and disp.shape == (120, 120) and t.scale == pytest.approx(1.0)
        np.testing.assert_array_equal(disp[:, :64], np.tile(np.arange(64), (120, 1)))     # tile 0 up to its right edge
        np.testing.assert_array_equal(disp[:, 64:], np.tile(np.arange(8, 64), (120, 1)))  # tile 1 past its overlap
        # a graph that echoes the left view: the tiles put together give back the whole view
        echo = StereoMatcher.from_callable(lambda lv, rv: lv[0, 0].copy(), (64, 64), iters=2, coarse_tiles=3,
                                           tile_overlap=8, infinity_check=False)
        rng = np.random.default_rng(1)
        img = rng.integers(0, 255, (176, 176)).astype(np.uint8)
        disp, _ = echo.coarse(img, img)
        np.testing.assert_array_equal(disp, img.astype(np.float32))

    def test_tiles_find_a_target_one_run_misses(self):
        # a 5 px disparity in a 160x120 frame is 2 px in one 64x64 letterbox (not above the 2 px
        # threshold: no target); 2x2 tiles make the view 120 px high, 3.75 px
        left = np.zeros((120, 160), np.uint8)
        left[40:80, 60:110] = 200
        right = np.zeros_like(left)
        right[40:80, 55:105] = 200
        calls = []
        one = StereoMatcher.from_callable(_edge_oracle(calls), (64, 64), iters=2, infinity_check=False)
        assert one.match(left, right).status == "no_target" and len(calls) == 1
        calls.clear()
        tiled = StereoMatcher.from_callable(_edge_oracle(calls), (64, 64), iters=2, infinity_check=False,
                                            coarse_tiles=2, tile_overlap=8)
        res = tiled.match(left, right)
        assert res.status == "fine" and len(calls) == 5   # four tiles, then the fine pass
        x0, y0, x1, y1 = res.coarse_bbox
        assert x0 <= 61 and y0 <= 41 and x1 >= 109 and y1 >= 79 and x1 - x0 < 80

    @pytest.mark.parametrize("tiles, overlap", [(0, 8), (1.5, 8), (2, 32), (2, -1)])
    def test_bad_tiling(self, tiles, overlap):
        with pytest.raises(ValueError):
            StereoMatcher.from_callable(_oracle(1.0), (64, 64), iters=2, coarse_tiles=tiles, tile_overlap=overlap)
