"""Index arrays of the pose graph, built in numpy (checked against scipy's cKDTree)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from spacepose.errors import ShapeError
from spacepose.pose_inputs import (PoseInputSpec, build_point_indices, build_pose_inputs, choose_from_pixels,
                                   estimate_normals, farthest_point_sampling, knn_indices, pix2pt_indices,
                                   pose_input_names, random_subsampling)

SPEC = PoseInputSpec(n_points=256, k=8, n_levels=2, ratio=4, crop_size=(64, 64))


def _cloud(n: int = 256, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).normal(size=(n, 3)) + np.array([0.0, 0.0, 20.0])


class TestKnn:
    def test_matches_ckdtree(self):
        rng = np.random.default_rng(1)
        ref, query = rng.normal(size=(500, 3)), rng.normal(size=(300, 3))
        idx = knn_indices(query, ref, 16, chunk=64)
        d_ref, i_ref = cKDTree(ref).query(query, k=16)
        np.testing.assert_array_equal(idx, i_ref)
        np.testing.assert_allclose(np.linalg.norm(ref[idx] - query[:, None], axis=-1), d_ref, atol=1e-9)

    def test_self_first_and_padding(self):
        xyz = _cloud(5)
        idx = knn_indices(xyz, xyz, 8)
        assert idx.shape == (5, 8)
        np.testing.assert_array_equal(idx[:, 0], np.arange(5))
        np.testing.assert_array_equal(idx[:, 5:], np.repeat(idx[:, 4:5], 3, axis=1))

    @staticmethod
    def _reference(query, ref, k):
        d2 = ((query[:, None, :] - ref[None, :, :]) ** 2).sum(-1)
        return np.argsort(d2, axis=1, kind="stable")[:, :k]  # by distance, then index

    def test_exact_on_a_stereo_like_cloud_with_outliers(self):
        rng = np.random.default_rng(3)
        surface = rng.uniform(-2, 2, (1000, 3)) * [1, 1, 0.05] + [0, 0, 20]
        outliers = rng.uniform(-30, 30, (24, 3)) + [0, 0, 40]
        xyz = np.concatenate([surface, outliers])
        np.testing.assert_array_equal(knn_indices(xyz, xyz, 16), self._reference(xyz, xyz, 16))
        np.testing.assert_array_equal(knn_indices(xyz, xyz[::4], 1), self._reference(xyz, xyz[::4], 1))

    def test_float32_cannot_separate_then_float64_decides(self):
        """Far from the origin, steps of 1e-6 m vanish in float32: those rows are searched in float64."""
        rng = np.random.default_rng(4)
        ref = np.array([1e4, 0.0, 0.0]) + np.column_stack([np.arange(40) * 1e-6, np.zeros(40), np.zeros(40)])
        ref = np.concatenate([ref, rng.normal(size=(40, 3))])
        query = ref[rng.permutation(len(ref))[:30]] + 1e-7
        np.testing.assert_array_equal(knn_indices(query, ref, 8), self._reference(query, ref, 8))
        np.testing.assert_array_equal(knn_indices(query, ref, 1), self._reference(query, ref, 1))

    @pytest.mark.parametrize("dim", [2, 3, 6])
    def test_exact_on_grids_full_of_ties(self, dim):
        """Points on a coarse grid tie everywhere: OpenCV's float32 search (up to 4 coordinates) and the
        matrix product (more) both end in the float64 answer, ties by index, up to which of the points
        tied at the k-th place is kept (the docstring)."""
        rng = np.random.default_rng(dim)
        ref = np.round(rng.normal(size=(700, dim)) * 8.0) / 8.0 + 5.0
        query = np.concatenate([ref[:200], np.round(rng.normal(size=(100, dim)) * 16.0) / 16.0 + 5.0])
        d2 = ((query[:, None, :] - ref[None, :, :]) ** 2).sum(-1)
        ranked = np.sort(d2, axis=1)
        for k in (1, 5, 16):
            idx, want = knn_indices(query, ref, k, chunk=128), self._reference(query, ref, k)
            np.testing.assert_array_equal(np.take_along_axis(d2, idx, axis=1), ranked[:, :k])
            untied = ranked[:, k - 1] < ranked[:, k]   # tied at the k-th place: any of the tied may be kept
            assert untied.sum() > 60 and (~untied).any() or k == 1
            np.testing.assert_array_equal(idx[untied], want[untied])

    def test_ties_go_to_lower_index(self):
        ref = np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0]])
        np.testing.assert_array_equal(knn_indices(np.zeros((1, 3)), ref, 3), [[0, 1, 2]])

    def test_bad_input(self):
        with pytest.raises(ShapeError, match="ref"):
            knn_indices(np.zeros((3, 3)), np.zeros((4, 2)), 2)
        with pytest.raises(ShapeError, match="query"):
            knn_indices(np.zeros((3, 3), dtype=np.int64), np.zeros((4, 3)), 2)
        with pytest.raises(ValueError):
            knn_indices(np.zeros((3, 3)), np.zeros((4, 3)), 0)


class TestSubsampling:
    def test_fps_deterministic_unique_and_spread(self):
        xyz = _cloud(400)
        a, b = farthest_point_sampling(xyz, 50), farthest_point_sampling(xyz, 50)
        np.testing.assert_array_equal(a, b)
        assert a[0] == 0 and len(np.unique(a)) == 50
        rand = random_subsampling(400, 50, seed=3)
        spread = lambda ids: cKDTree(xyz[ids]).query(xyz[ids], k=2)[0][:, 1].min()  # noqa: E731
        assert spread(a) > spread(rand)

    def test_random_seeded(self):
        np.testing.assert_array_equal(random_subsampling(100, 10, 7), random_subsampling(100, 10, 7))
        assert not np.array_equal(random_subsampling(100, 10, 7), random_subsampling(100, 10, 8))
        with pytest.raises(ValueError):
            random_subsampling(10, 11, 0)


class TestBuildPointIndices:
    @pytest.mark.parametrize("sampling", ["fps", "random"])
    def test_levels(self, sampling):
        spec = PoseInputSpec(n_points=256, k=8, n_levels=2, crop_size=(64, 64), sampling=sampling)
        xyz = _cloud()
        idx = build_point_indices(xyz, spec)
        sizes = spec.level_sizes
        assert sizes == (256, 64, 16)
        level_xyz = xyz
        for lv in range(2):
            assert idx["nbr"][lv].shape == (sizes[lv], 8) and idx["nbr"][lv].dtype == np.int64
            assert idx["sub"][lv].shape == (sizes[lv + 1],)
            assert idx["up"][lv].shape == (sizes[lv],)
            next_xyz = level_xyz[idx["sub"][lv]]
            _, nn = cKDTree(level_xyz).query(level_xyz, k=8)
            np.testing.assert_array_equal(idx["nbr"][lv], nn)
            _, up = cKDTree(next_xyz).query(level_xyz, k=1)
            np.testing.assert_array_equal(idx["up"][lv], up)
            np.testing.assert_array_equal(idx["up"][lv][idx["sub"][lv]], np.arange(sizes[lv + 1]))
            np.testing.assert_array_equal(xyz[idx["level_ids"][lv + 1]], next_xyz)
            level_xyz = next_xyz
        again = build_point_indices(xyz, spec)
        for key in idx:
            for a, b in zip(idx[key], again[key]):
                np.testing.assert_array_equal(a, b)

    def test_bad_input(self):
        with pytest.raises(ShapeError, match="xyz"):
            build_point_indices(_cloud(100), SPEC)
        bad = _cloud()
        bad[3, 1] = np.nan
        with pytest.raises(ShapeError, match="finite"):
            build_point_indices(bad, SPEC)


class TestPixels:
    def test_choose(self):
        np.testing.assert_array_equal(choose_from_pixels(np.array([[0, 0], [3, 2], [63, 63]]), (64, 64)),
                                      [0, 2 * 64 + 3, 64 * 64 - 1])
        with pytest.raises(ShapeError, match="inside"):
            choose_from_pixels(np.array([[64, 0]]), (64, 64))
        with pytest.raises(ShapeError, match="pixels"):
            choose_from_pixels(np.array([[1.0, 2.0]]), (64, 64))

    def test_pix2pt_matches_ckdtree(self):
        pixels = np.random.default_rng(2).integers(0, 64, (200, 2))
        idx = pix2pt_indices(pixels, (64, 64), 4)
        assert idx.shape == (16 * 16,)
        jj, ii = np.meshgrid(np.arange(16), np.arange(16))
        centres = np.stack([(jj.ravel() + 0.5) * 4 - 0.5, (ii.ravel() + 0.5) * 4 - 0.5], axis=1)
        d_ref, _ = cKDTree(pixels.astype(float)).query(centres, k=1)
        np.testing.assert_allclose(np.linalg.norm(pixels[idx] - centres, axis=1), d_ref, atol=1e-9)
        with pytest.raises(ValueError, match="stride"):
            pix2pt_indices(pixels, (64, 64), 3)

    @pytest.mark.parametrize("stride", [2, 4, 8])
    def test_pix2pt_equals_float64_search_ties_included(self, stride):
        """The float32 fast path gives the float64 search's answer, lowest index on exact ties."""
        rng = np.random.default_rng(stride)
        pixels = np.concatenate([rng.integers(0, 128, (300, 2)), rng.integers(0, 128, (50, 2)).repeat(2, axis=0)])
        w = 128 // stride
        jj, ii = np.meshgrid(np.arange(w), np.arange(w))
        centres = np.stack([(jj.ravel() + 0.5) * stride - 0.5, (ii.ravel() + 0.5) * stride - 0.5], axis=1)
        d2 = ((centres[:, None, :] - pixels[None].astype(float)) ** 2).sum(-1)
        np.testing.assert_array_equal(pix2pt_indices(pixels, (128, 128), stride), np.argmin(d2, axis=1))
        # sub-pixel coordinates take the general path and agree too
        frac = pixels + 0.25
        d2f = ((centres[:, None, :] - frac[None]) ** 2).sum(-1)
        np.testing.assert_array_equal(pix2pt_indices(frac, (128, 128), stride), np.argmin(d2f, axis=1))


def test_normals_of_a_plane_face_the_camera():
    rng = np.random.default_rng(0)
    xyz = np.column_stack([rng.uniform(-1, 1, 200), rng.uniform(-1, 1, 200), np.full(200, 10.0)])
    normals = estimate_normals(xyz, knn_indices(xyz, xyz, 8))
    np.testing.assert_allclose(normals, np.tile([0.0, 0.0, -1.0], (200, 1)), atol=1e-6)


class TestBuildPoseInputs:
    def _sample(self, spec=SPEC):
        rng = np.random.default_rng(4)
        rgb = rng.integers(0, 256, (64, 64, 3), dtype=np.uint8)
        return rgb, _cloud(spec.n_points), rng.integers(0, 64, (spec.n_points, 2))

    @pytest.mark.parametrize("use_normals", [False, True])
    def test_shapes_and_normalisation(self, use_normals):
        spec = PoseInputSpec(n_points=256, k=8, n_levels=2, crop_size=(64, 64), use_normals=use_normals)
        rgb, xyz, pixels = self._sample(spec)
        inputs, mean = build_pose_inputs(rgb, xyz, pixels, spec)
        assert list(inputs) == pose_input_names(2)
        assert inputs["rgb"].shape == (1, 3, 64, 64) and inputs["rgb"].dtype == np.float32
        assert inputs["points"].shape == (1, 256, 9 if use_normals else 6) and inputs["points"].dtype == np.float32
        np.testing.assert_allclose(inputs["points"][0, :, :3] * spec.xyz_scale + mean, xyz, atol=1e-5)
        np.testing.assert_allclose(inputs["points"][0, :, 3:6], rgb[pixels[:, 1], pixels[:, 0]] / 255.0, atol=1e-6)
        assert inputs["pix2pt_0"].shape == (1, 16 * 16) and inputs["pix2pt_1"].shape == (1, 8 * 8)
        assert inputs["pix2pt_1"].max() < spec.level_sizes[1]
        assert all(v.dtype == np.int64 for k, v in inputs.items() if k not in ("rgb", "points"))

    def test_bad_input(self):
        rgb, xyz, pixels = self._sample()
        with pytest.raises(ShapeError, match="rgb_crop"):
            build_pose_inputs(rgb[:32], xyz, pixels, SPEC)
        with pytest.raises(ShapeError, match="pixels"):
            build_pose_inputs(rgb, xyz, pixels[:10], SPEC)
        with pytest.raises(ShapeError, match="inside"):
            build_pose_inputs(rgb, xyz, pixels + 64, SPEC)

    def test_spec_validation(self):
        with pytest.raises(ValueError, match="divisible"):
            PoseInputSpec(crop_size=(100, 128))
        with pytest.raises(ValueError, match="sampling"):
            PoseInputSpec(sampling="grid")
        with pytest.raises(ValueError, match="too small"):
            PoseInputSpec(n_points=16, n_levels=3)
