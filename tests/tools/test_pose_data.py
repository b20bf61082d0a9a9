"""PoseDataset / stereo_like_noise / point_labels / predict_disparity on a tiny rendered dataset."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))  # --import-mode=importlib: find the helpers
from _pose_fixtures import pose_dataset, tiny_net_config  # noqa: E402

from spacepose.errors import DatasetError  # noqa: E402
from spacepose.imageio import read_pfm  # noqa: E402
from spacepose.pose_inputs import pose_input_names  # noqa: E402
from spacepose.tools.pose_data import (NoiseModel, PoseDataConfig, PoseDataset, read_pose_labels,  # noqa: E402
                                       stereo_like_noise)

pytest.importorskip("torch")


@pytest.fixture(scope="module")
def ds_root(tmp_path_factory) -> Path:
    return pose_dataset(tmp_path_factory)


def make(root, **kw):
    spec = tiny_net_config().input_spec()
    return PoseDataset(root, kw.pop("split", "train"), spec, kw.pop("config", PoseDataConfig()), radius_m=2.6, **kw)


class TestStereoLikeNoise:
    def test_noise_statistics(self):
        d = np.zeros((120, 160), np.float32)
        d[20:100, 30:130] = 12.0
        rng = np.random.default_rng(0)
        noisy = stereo_like_noise(d, rng, NoiseModel(edge_width=0, p_missing=0.0, p_blob=0.0))
        inner = noisy[20:100, 30:130]
        assert abs(float(inner.std()) - 0.3) < 0.03 and abs(float(inner.mean()) - 12.0) < 0.02
        assert np.all(noisy[d == 0] == 0)

    def test_edges_and_holes(self):
        d = np.zeros((120, 160), np.float32)
        d[20:100, 30:130] = 12.0
        noisy = stereo_like_noise(d, np.random.default_rng(1), NoiseModel())
        assert np.any((noisy > 0) & (d == 0))            # fattening outside the silhouette
        assert np.any((noisy == 0) & (d > 0))            # holes
        assert np.any((d > 0) & (noisy > 0) & (noisy < 10.0))  # flying pixels
        again = stereo_like_noise(d, np.random.default_rng(1), NoiseModel())
        np.testing.assert_array_equal(noisy, again)


class TestPoseDataset:
    def test_item_contents_and_labels(self, ds_root):
        ds = make(ds_root)
        spec = ds.spec
        item = ds[0]
        for name in pose_input_names(spec.n_levels):
            assert name in item
        assert tuple(item["points"].shape) == (spec.n_points, 6)
        assert tuple(item["kp_targets"].shape) == (8, spec.n_points, 3)
        assert tuple(item["ctr_targets"].shape) == (spec.n_points, 3)
        labels = item["labels"].numpy()
        assert set(np.unique(labels)) <= {0, 1} and labels.mean() > 0.3
        # offsets: keypoint - point, in the camera frame
        rec = ds.records[item["index"]]
        kp_cam = ds.keypoints @ rec.R.T + rec.t
        np.testing.assert_allclose(item["kp_targets"].numpy(), kp_cam[:, None] - item["xyz"].numpy()[None], atol=1e-4)
        ctr = rec.R @ ds.centre + rec.t
        np.testing.assert_allclose(item["ctr_targets"].numpy(), ctr - item["xyz"].numpy(), atol=1e-4)
        # target points lie near the object: centre offsets bounded by the radius (+ noise)
        on = labels > 0
        assert np.all(np.linalg.norm(item["ctr_targets"].numpy()[on], axis=1) < 2.6 + 1.5)

    def test_randomness_per_epoch_and_deterministic_mode(self, ds_root):
        ds = make(ds_root)
        a = ds[1]["xyz"].numpy()
        b = ds[1]["xyz"].numpy()
        np.testing.assert_array_equal(a, b)
        ds.set_epoch(1)
        assert not np.array_equal(ds[1]["xyz"].numpy(), a)
        val = make(ds_root, deterministic=True)
        val.set_epoch(5)
        x = val[0]
        val.set_epoch(6)
        np.testing.assert_array_equal(x["rgb"].numpy(), val[0]["rgb"].numpy())

    def test_labels_file(self, ds_root):
        recs = read_pose_labels(ds_root)
        assert len(recs) == 8 and {r.split for r in recs} <= {"train", "test"}
        assert all(r.R.shape == (3, 3) and 10.0 <= r.distance_m <= 20.0 for r in recs)

    def test_stereo_source_needs_cache(self, ds_root):
        with pytest.raises(DatasetError, match="pred_disparity"):
            make(ds_root, config=PoseDataConfig(depth_source="stereo"))
        with pytest.raises(ValueError):
            PoseDataConfig(depth_source="lidar")


def test_predict_disparity_resumable_and_feeds_stereo_source(ds_root, tmp_path, tiny_bundle):
    import shutil

    from spacepose.tools.predict_disparity import predict_disparity

    root = tmp_path / "ds"
    shutil.copytree(ds_root, root)
    first = predict_disparity(root, tiny_bundle / "stereo.onnx", limit=3)
    assert first["written"] == 3 and first["skipped"] == 0
    again = predict_disparity(root, tiny_bundle / "stereo.onnx", limit=3)
    assert again["written"] == 0 and again["skipped"] == 3
    disp = read_pfm(root / "pred_disparity" / "000000.pfm")
    assert disp.shape == (120, 160) and disp.dtype == np.float32 and np.all(disp >= 0)
    # a random-weight stereo graph: the dataset either builds samples or says why not
    predict_disparity(root, tiny_bundle / "stereo.onnx")
    ds = make(root, config=PoseDataConfig(depth_source="stereo", min_points=1))
    try:
        item = ds[0]
        assert tuple(item["xyz"].shape) == (ds.spec.n_points, 3)
    except DatasetError as err:
        assert "too few" in str(err)
