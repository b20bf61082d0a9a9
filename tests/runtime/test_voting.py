"""Tests of spacepose.voting: seeded non-blurring mean shift and FFB6D centre-first voting."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.cluster import MeanShift

from spacepose.errors import ShapeError
from spacepose.voting import (
    CentreInliers,
    KeypointVotes,
    MeanShiftResult,
    centre_first_inliers,
    mean_shift,
    vote_keypoints,
)

BANDWIDTH = 0.05


def clustered_votes(n_big: int = 240, n_small: int = 90, n_outliers: int = 70, seed: int = 0,
                    z: float = 8.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two blobs (sigma = bandwidth/3, 0.4 m apart) plus uniform outliers, ~z metres away."""
    rng = np.random.default_rng(seed)
    big_c = np.array([0.1, -0.2, z])
    small_c = np.array([0.5, -0.2, z])
    pts = np.concatenate([
        rng.normal(big_c, BANDWIDTH / 3, (n_big, 3)),
        rng.normal(small_c, BANDWIDTH / 3, (n_small, 3)),
        rng.uniform(-1.0, 1.0, (n_outliers, 3)) + [0.0, 0.0, z],
    ])
    return pts, big_c, small_c


class TestMeanShift:
    def test_smoke_types_and_shapes(self) -> None:
        pts, _, _ = clustered_votes()
        res = mean_shift(pts, BANDWIDTH)
        assert isinstance(res, MeanShiftResult)
        assert res.modes.dtype == np.float64 and res.modes.ndim == 2 and res.modes.shape[1] == 3
        assert res.support.dtype == np.int64 and res.support.shape == (len(res.modes),)
        assert res.labels.dtype == np.int64 and res.labels.shape == (len(pts),)
        assert res.converged and res.n_iter >= 1
        with pytest.raises(AttributeError):
            res.modes = res.modes  # type: ignore[misc]  # frozen

    @pytest.mark.parametrize("kernel", ["flat", "gaussian"])
    def test_finds_known_clusters_sorted_by_support(self, kernel: str) -> None:
        pts, big_c, small_c = clustered_votes()
        res = mean_shift(pts, BANDWIDTH, kernel=kernel)
        assert np.all(np.diff(res.support) <= 0)
        np.testing.assert_allclose(res.modes[0], big_c, atol=BANDWIDTH / 5)
        np.testing.assert_allclose(res.modes[1], small_c, atol=BANDWIDTH / 5)
        assert res.support[0] >= 200 and 60 <= res.support[1] <= 120

    def test_support_and_labels_definition(self) -> None:
        pts, _, _ = clustered_votes()
        res = mean_shift(pts, BANDWIDTH)
        d = np.linalg.norm(pts[:, None, :] - res.modes[None, :, :], axis=2)
        np.testing.assert_array_equal(res.support, (d <= BANDWIDTH).sum(axis=0))
        want = np.where(d.min(axis=1) <= BANDWIDTH, d.argmin(axis=1), -1)
        np.testing.assert_array_equal(res.labels, want)

    def test_modes_are_merged(self) -> None:
        pts, _, _ = clustered_votes()
        res = mean_shift(pts, BANDWIDTH, n_seeds=None)
        pair = np.linalg.norm(res.modes[:, None] - res.modes[None], axis=2)
        pair[np.diag_indices_from(pair)] = np.inf
        assert pair.min() > BANDWIDTH

    def test_deterministic_for_a_seed(self) -> None:
        pts, _, _ = clustered_votes()
        a = mean_shift(pts, BANDWIDTH, n_seeds=8, seed=3)
        b = mean_shift(pts, BANDWIDTH, n_seeds=8, seed=3)
        np.testing.assert_array_equal(a.modes, b.modes)
        np.testing.assert_array_equal(a.labels, b.labels)

    def test_fewer_points_than_seeds(self) -> None:
        pts = np.array([[0.0, 0.0, 1.0], [0.01, 0.0, 1.0], [1.0, 1.0, 1.0]])
        res = mean_shift(pts, BANDWIDTH, n_seeds=32)
        assert len(res.modes) == 2
        np.testing.assert_allclose(res.modes[0], [0.005, 0.0, 1.0], atol=1e-12)
        np.testing.assert_array_equal(res.support, [2, 1])
        np.testing.assert_array_equal(res.labels, [0, 0, 1])

    def test_single_point(self) -> None:
        res = mean_shift(np.array([[1.0, 2.0, 3.0]]), BANDWIDTH)
        np.testing.assert_array_equal(res.modes, [[1.0, 2.0, 3.0]])
        np.testing.assert_array_equal(res.labels, [0])

    def test_nan_rows_are_dropped_and_labelled_minus_one(self) -> None:
        pts, big_c, _ = clustered_votes()
        pts = pts.copy()
        pts[::7, 1] = np.nan
        pts[3, 2] = np.inf
        res = mean_shift(pts, BANDWIDTH)
        assert np.all(res.labels[::7] == -1) and res.labels[3] == -1
        assert np.all(np.isfinite(res.modes))
        np.testing.assert_allclose(res.modes[0], big_c, atol=BANDWIDTH / 5)

    def test_given_seeds(self) -> None:
        pts, big_c, small_c = clustered_votes()
        res = mean_shift(pts, BANDWIDTH, seeds=np.array([small_c + 0.02, [50.0, 50.0, 50.0]]))
        assert len(res.modes) == 1  # the far seed reaches no point and is dropped
        np.testing.assert_allclose(res.modes[0], small_c, atol=BANDWIDTH / 5)

    def test_float32_and_2d_input(self) -> None:
        rng = np.random.default_rng(5)
        pts = rng.normal([3.0, -1.0], 0.01, (100, 2)).astype(np.float32)
        res = mean_shift(pts, BANDWIDTH)
        assert res.modes.shape == (1, 2) and res.modes.dtype == np.float64
        np.testing.assert_allclose(res.modes[0], pts.astype(np.float64).mean(axis=0), atol=0.01)

    def test_max_iter_reported(self) -> None:
        pts, _, _ = clustered_votes()
        res = mean_shift(pts, BANDWIDTH, kernel="gaussian", max_iter=1, tol=0.0)
        assert res.n_iter == 1 and not res.converged

    def test_bad_input(self) -> None:
        pts, _, _ = clustered_votes()
        with pytest.raises(ShapeError, match="points must have shape"):
            mean_shift(pts[:, 0], BANDWIDTH)
        with pytest.raises(ShapeError, match="points must have a float or integer dtype"):
            mean_shift(pts > 0, BANDWIDTH)
        with pytest.raises(ShapeError, match="no finite rows"):
            mean_shift(np.zeros((0, 3)), BANDWIDTH)
        with pytest.raises(ShapeError, match="no finite rows"):
            mean_shift(np.full((10, 3), np.nan), BANDWIDTH)
        with pytest.raises(ValueError, match="bandwidth must be a positive"):
            mean_shift(pts, 0.0)
        with pytest.raises(ValueError, match="bandwidth must be a positive"):
            mean_shift(pts, -1.0)
        with pytest.raises(ValueError, match="unknown kernel 'epanechnikov'"):
            mean_shift(pts, BANDWIDTH, kernel="epanechnikov")
        with pytest.raises(ValueError, match="n_seeds must be"):
            mean_shift(pts, BANDWIDTH, n_seeds=0)
        with pytest.raises(ValueError, match="max_iter must be"):
            mean_shift(pts, BANDWIDTH, max_iter=0)
        with pytest.raises(ShapeError, match="seeds must have shape"):
            mean_shift(pts, BANDWIDTH, seeds=np.zeros((2, 2)))
        with pytest.raises(ShapeError, match="no seed has any point"):
            mean_shift(pts, BANDWIDTH, seeds=np.array([[100.0, 0.0, 0.0]]))


class TestAgainstSklearn:
    """Flat kernel, same bandwidth, bin_seeding=False: top modes agree within bandwidth / 10."""

    @staticmethod
    def assert_top_modes_agree(ours: np.ndarray, theirs: np.ndarray, k: int) -> None:
        for i in range(k):
            dist = np.linalg.norm(theirs - ours[i], axis=1).min()
            assert dist <= BANDWIDTH / 10, f"mode {i}: {dist} from sklearn's nearest"
        np.testing.assert_allclose(ours[:k], theirs[:k], atol=BANDWIDTH / 10)

    def test_default_seeding_vs_sklearn_all_points(self) -> None:
        pts, _, _ = clustered_votes()
        ours = mean_shift(pts, BANDWIDTH, kernel="flat")
        theirs = MeanShift(bandwidth=BANDWIDTH, bin_seeding=False).fit(pts)
        self.assert_top_modes_agree(ours.modes, theirs.cluster_centers_, k=2)

    def test_all_points_as_seeds_vs_sklearn(self) -> None:
        pts, _, _ = clustered_votes(n_big=150, n_small=60, n_outliers=30, seed=2)
        ours = mean_shift(pts, BANDWIDTH, kernel="flat", n_seeds=None)
        theirs = MeanShift(bandwidth=BANDWIDTH, bin_seeding=False).fit(pts)
        self.assert_top_modes_agree(ours.modes, theirs.cluster_centers_, k=2)

    def test_same_seeds_as_sklearn(self) -> None:
        pts, _, _ = clustered_votes(seed=4)
        seeds = pts[::10]
        ours = mean_shift(pts, BANDWIDTH, kernel="flat", seeds=seeds)
        theirs = MeanShift(bandwidth=BANDWIDTH, seeds=seeds, bin_seeding=False).fit(pts)
        self.assert_top_modes_agree(ours.modes, theirs.cluster_centers_, k=2)


def ffb6d_scene(seed: int = 0, n: int = 600, outlier_fraction: float = 0.3):
    """Object points with noisy centre and keypoint votes; a fraction of points vote elsewhere."""
    rng = np.random.default_rng(seed)
    centre = np.array([0.2, -0.1, 10.0])
    keypoints = centre + rng.uniform(-0.5, 0.5, (4, 3))
    n_out = int(n * outlier_fraction)
    centre_votes = rng.normal(centre, 0.01, (n, 3))
    centre_votes[:n_out] = centre + rng.uniform(-2.0, 2.0, (n_out, 3))
    kp_votes = rng.normal(keypoints[:, None, :], 0.01, (4, n, 3))
    kp_votes[:, :n_out] = rng.uniform(-3.0, 3.0, (4, n_out, 3)) + centre  # outliers vote anywhere
    truth_inliers = np.arange(n) >= n_out
    return centre_votes, kp_votes, centre, keypoints, truth_inliers


class TestCentreFirstInliers:
    @pytest.mark.parametrize("kernel", ["flat", "gaussian"])
    def test_known_scene(self, kernel: str) -> None:
        centre_votes, _, centre, _, truth = ffb6d_scene()
        out = centre_first_inliers(centre_votes, BANDWIDTH, kernel=kernel)
        assert isinstance(out, CentreInliers)
        c, inliers, support = out  # unpacks as a tuple
        assert c.shape == (3,) and inliers.shape == (len(centre_votes),) and inliers.dtype == bool
        np.testing.assert_allclose(c, centre, atol=0.005)
        assert support == int(inliers.sum())
        assert np.all(inliers[truth])  # 0.01 m noise, 0.05 m bandwidth: all true inliers kept
        assert inliers[~truth].sum() <= 2  # uniform outliers rarely fall inside the ball

    def test_inliers_definition_and_nan(self) -> None:
        centre_votes, _, _, _, _ = ffb6d_scene()
        centre_votes = centre_votes.copy()
        centre_votes[-1] = np.nan
        c, inliers, _ = centre_first_inliers(centre_votes, BANDWIDTH)
        with np.errstate(invalid="ignore"):
            want = np.linalg.norm(centre_votes - c, axis=1) <= BANDWIDTH
        np.testing.assert_array_equal(inliers, want)
        assert not inliers[-1]

    def test_bad_input(self) -> None:
        with pytest.raises(ShapeError, match=r"centre_votes must have shape \(\*, 3\)"):
            centre_first_inliers(np.zeros((10, 2)), BANDWIDTH)
        with pytest.raises(ShapeError, match="no finite rows"):
            centre_first_inliers(np.zeros((0, 3)), BANDWIDTH)
        with pytest.raises(ValueError, match="bandwidth must be a positive"):
            centre_first_inliers(np.zeros((10, 3)), 0.0)


class TestVoteKeypoints:
    @pytest.mark.parametrize("kernel", ["flat", "gaussian"])
    def test_known_scene(self, kernel: str) -> None:
        centre_votes, kp_votes, _, keypoints, _ = ffb6d_scene(seed=1)
        _, inliers, _ = centre_first_inliers(centre_votes, BANDWIDTH)
        out = vote_keypoints(kp_votes, inliers, BANDWIDTH, kernel=kernel)
        assert isinstance(out, KeypointVotes)
        kps, support = out
        assert kps.shape == (4, 3) and support.shape == (4,) and support.dtype == np.int64
        np.testing.assert_allclose(kps, keypoints, atol=0.005)
        assert np.all(support >= 0.9 * inliers.sum())

    def test_nan_keypoint_row(self) -> None:
        centre_votes, kp_votes, _, keypoints, _ = ffb6d_scene(seed=2)
        kp_votes = kp_votes.copy()
        kp_votes[2] = np.nan
        _, inliers, _ = centre_first_inliers(centre_votes, BANDWIDTH)
        kps, support = vote_keypoints(kp_votes, inliers, BANDWIDTH)
        assert np.all(np.isnan(kps[2])) and support[2] == 0
        np.testing.assert_allclose(kps[[0, 1, 3]], keypoints[[0, 1, 3]], atol=0.005)

    def test_bad_input(self) -> None:
        kp_votes = np.zeros((4, 10, 3))
        with pytest.raises(ShapeError, match=r"kp_votes must have shape \(\*, \*, 3\)"):
            vote_keypoints(np.zeros((10, 3)), np.ones(10, bool), BANDWIDTH)
        with pytest.raises(ShapeError, match=r"inliers must have shape \(10\)"):
            vote_keypoints(kp_votes, np.ones(9, bool), BANDWIDTH)
        with pytest.raises(ShapeError, match="inliers must have dtype"):
            vote_keypoints(kp_votes, np.ones(10), BANDWIDTH)
        with pytest.raises(ShapeError, match="selects no point"):
            vote_keypoints(kp_votes, np.zeros(10, bool), BANDWIDTH)
        with pytest.raises(ValueError, match="bandwidth must be a positive"):
            vote_keypoints(kp_votes, np.ones(10, bool), -0.1)
