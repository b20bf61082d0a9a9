"""Tests of spacepose.bundle: loading, schema errors, graph metadata checks, check_fits."""

import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))  # --import-mode=importlib: find the helpers
from _bundle_fixtures import KEYPOINTS, make_bundle, manifest  # noqa: E402

from spacepose.bundle import ModelBundle, load_bundle
from spacepose.calibration.rig import StereoRig, paper_rig
from spacepose.errors import BundleError


@pytest.fixture(scope="module")
def bundle_dir(tmp_path_factory):
    return make_bundle(tmp_path_factory.mktemp("bundle") / "tiny")


def _copy(bundle_dir, tmp_path):
    return shutil.copytree(bundle_dir, tmp_path / "copy")


def _rewrite(folder, **overrides):
    (folder / "bundle.json").write_text(json.dumps(manifest(**overrides)))


class TestLoad:
    def test_loads_everything(self, bundle_dir):
        b = load_bundle(bundle_dir)
        assert isinstance(b, ModelBundle)
        assert b.target_name == "tiny"
        np.testing.assert_array_equal(b.keypoints, KEYPOINTS)
        assert b.keypoints.flags.writeable is False
        assert b.stereo.input_size == (256, 256) and b.stereo.iters == 1
        assert b.pose.input_spec.n_points == 256 and b.pose.n_keypoints == 8
        assert b.voting.min_points == 32 and b.voting.kernel == "gaussian"
        assert b.rig.focal_px == 800.0 and b.distance_range_m == (2.0, 200.0)
        assert b.graph_metadata["stereo"]["kind"] == "stereo"
        assert b.bbox_corners.shape == (8, 3)
        assert b.stereo_path.is_file() and b.pose_path.is_file()

    def test_shipped_default_bundle_loads_and_fits_the_paper_rig(self):
        from spacepose.calibration.rig import load_rig, PAPER_RIG_PATH

        b = load_bundle()
        assert b.path.name == "default" and b.target_name == "tdrs"
        assert b.stereo_path.is_file() and b.pose_path.is_file()
        assert b.keypoints.shape == (8, 3) and b.distance_range_m == (10.0, 50.0)
        b.check_fits(load_rig(PAPER_RIG_PATH))  # the paper rig at 1280x960: no BundleError
        # a rig we never trained on: half the baseline; the coarse pass still sees >= 3 px at 50 m
        base = load_rig(PAPER_RIG_PATH)
        half, fifth, tenth = (StereoRig(base.M1, base.D1, base.M2, base.D2, base.R, base.T / k, base.image_size)
                              for k in (2.0, 5.0, 10.0))
        b.check_fits(half)
        assert b.coarse_tiles_for(base) == 1 and b.coarse_tiles_for(half) == 1
        # a fifth of it: in one letterboxed run the target would vanish at 50 m (1.3 px); 3x3 tiles find it
        b.check_fits(fifth)
        assert b.coarse_tiles_for(fifth) == 3
        with pytest.raises(BundleError, match="coarse"):  # a tenth: not even with the most tiles
            b.check_fits(tenth)

    def test_a_long_baseline_fits_through_a_wider_fine_window(self):
        """B = 2 m at 800x600, f = 1000 px (session 23's rig B): the fine window's disparity would reach
        122 px at the target's narrowest, but the window widens to keep it at 0.9 max_disp (roi), so the
        rig is not refused; the coarse pass sees 13-64 px, inside the trained range."""
        from spacepose.bundle import expected_disparity_px
        from spacepose.roi import WINDOW_DISPARITY_FILL, square_window

        b = load_bundle()
        K = np.array([[1000.0, 0.0, 399.5], [0.0, 1000.0, 299.5], [0.0, 0.0, 1.0]])
        rig = StereoRig(K, np.zeros(5), K, np.zeros(5), np.eye(3), np.array([-2.0, 0.0, 0.0]), (800, 600))
        b.check_fits(rig)
        cap = WINDOW_DISPARITY_FILL * b.stereo.max_disp
        fine = expected_disparity_px(b, 1000.0, 2.0, (800, 600))["fine"]
        assert fine[1] == pytest.approx(cap) and fine[0] < cap
        # what the cap stands for: the window square_window gives such a target holds its largest
        # disparity at the cap (target 2.0 m wide at 10 m: 200 px box, disparity 200 px)
        win = square_window((300, 200, 500, 400), 170.0, 200.0, b.stereo.window_margin,
                            out_side=b.stereo.input_size[0], max_disp=b.stereo.max_disp)
        assert 200.0 * b.stereo.input_size[0] / win.side <= cap + 1e-9
        assert 200.0 * b.stereo.input_size[0] / (b.stereo.window_margin * (200.0 + 200.0)) > cap  # widened

    def test_missing_folder(self, tmp_path):
        with pytest.raises(BundleError, match="does not exist"):
            load_bundle(tmp_path / "nope")

    @pytest.mark.parametrize("name", ["bundle.json", "MODEL_CARD.md", "stereo.onnx", "pose.onnx"])
    def test_missing_file(self, bundle_dir, tmp_path, name):
        folder = _copy(bundle_dir, tmp_path)
        (folder / name).unlink()
        with pytest.raises(BundleError, match="missing"):
            load_bundle(folder)

    def test_corrupt_json(self, bundle_dir, tmp_path):
        folder = _copy(bundle_dir, tmp_path)
        (folder / "bundle.json").write_text("{not json")
        with pytest.raises(BundleError, match="not JSON"):
            load_bundle(folder)

    def test_corrupt_graph(self, bundle_dir, tmp_path):
        folder = _copy(bundle_dir, tmp_path)
        (folder / "pose.onnx").write_bytes(b"\x00garbage")
        with pytest.raises(BundleError):
            load_bundle(folder)

    @pytest.mark.parametrize("overrides, match", [
        ({"schema": "other/9"}, "schema"),
        ({"target": {"name": "x"}}, "target.keypoints"),
        ({"distance_range_m": [50, 10]}, "low < high"),
        ({"stereo": {"file": "stereo.onnx", "input_size": [256], "iters": 1, "normalisation": "x", "max_disp": 192}},
         "input_size"),
        ({"voting": {"kernel": "box"}}, "kernel"),
        ({"voting": {"bandwidth": 1.0}}, "unknown keys"),
        ({"voting": {"min_photo_consistency": 1.0}}, "min_photo_consistency"),
        ({"voting": {"min_photo_consistency": -1.5}}, "min_photo_consistency"),
        ({"pose": {**manifest()["pose"], "n_pointz": 512}}, "unknown keys in pose"),
        ({"pose": {**manifest()["pose"], "crop_size": [100, 100]}}, "invalid pose input spec"),
        ({"rig": {"image_size": [640, 480], "focal_px": -1, "baseline_m": 1.0}}, "focal_px"),
    ])
    def test_schema_errors(self, bundle_dir, tmp_path, overrides, match):
        folder = _copy(bundle_dir, tmp_path)
        _rewrite(folder, **overrides)
        with pytest.raises(BundleError, match=match):
            load_bundle(folder)

    def test_keypoint_count_must_match(self, bundle_dir, tmp_path):
        folder = _copy(bundle_dir, tmp_path)
        data = manifest()
        data["target"]["keypoints"] = KEYPOINTS[:5].tolist()
        (folder / "bundle.json").write_text(json.dumps(data))
        with pytest.raises(BundleError, match="n_keypoints"):
            load_bundle(folder)

    @pytest.mark.parametrize("which, meta, match", [
        ("stereo", {"iters": 12}, "iters"),
        ("stereo", {"input_size": [320, 256]}, "input_size"),
        ("pose", {"n_points": 512}, "n_points"),
        ("pose", {"keypoints": (KEYPOINTS + 0.1).tolist()}, "keypoints"),
        ("pose", {"target": "mro"}, "target"),
        ("pose", {"kind": "stereo"}, "kind"),
    ])
    def test_graph_metadata_disagrees(self, tmp_path, which, meta, match):
        kwargs = {"stereo_meta": meta} if which == "stereo" else {"pose_meta": meta}
        folder = make_bundle(tmp_path / "b", **kwargs)
        with pytest.raises(BundleError, match=match):
            load_bundle(folder)
        load_bundle(folder, verify_graphs=False)  # the manifest itself is fine


class TestCheckFits:
    @pytest.mark.parametrize("size", [(640, 480), (1280, 960), (320, 240)])
    def test_paper_rig_any_resolution_fits(self, bundle_dir, size):
        load_bundle(bundle_dir).check_fits(paper_rig(*size))

    @pytest.mark.parametrize("baseline, focal, match", [(0.1, 1600.0, "coarse"), (5.0, 1600.0, "coarse"),
                                                        (1.0, 400.0, "coarse")])
    def test_refuses_mismatched_rig(self, bundle_dir, baseline, focal, match):
        base = paper_rig(1280, 960)
        K = base.M1.copy()
        K[0, 0] = K[1, 1] = focal
        rig = StereoRig(K, base.D1, K, base.D2, base.R, np.array([-baseline, 0.0, 0.0]), base.image_size)
        with pytest.raises(BundleError, match=match) as info:
            load_bundle(bundle_dir).check_fits(rig)
        assert "trained for" in str(info.value) and "px" in str(info.value)

    def test_refuses_via_trained_range(self, bundle_dir, tmp_path):
        folder = _copy(bundle_dir, tmp_path)
        data = manifest()
        data["stereo"]["disparity_range_px"] = [20.0, 40.0]
        (folder / "bundle.json").write_text(json.dumps(data))
        with pytest.raises(BundleError, match="20.0-40.0"):
            load_bundle(folder).check_fits(paper_rig(640, 480))
