"""spacepose.flip: the flipped pose, and which of a pose and its flip the stereo points support."""

import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _bundle_fixtures import make_bundle, manifest, synthetic_pair  # noqa: E402

from spacepose.bundle import load_bundle  # noqa: E402
from spacepose.calibration.rig import paper_rig  # noqa: E402
from spacepose.errors import BundleError  # noqa: E402
from spacepose.estimator import PoseEstimator  # noqa: E402
from spacepose.flip import flip_matrix, flipped_pose, resolve_flip  # noqa: E402

RNG = np.random.default_rng(0)


def _asymmetric_surface(n=3000):
    """A 5 x 3 x 1 m box with a 1 m post on one end: a half turn about z moves the post."""
    box = RNG.uniform([-2.5, -1.5, -0.5], [2.5, 1.5, 0.5], size=(n, 3))
    face = RNG.integers(0, 3, n)
    box[np.arange(n), face] = np.sign(RNG.normal(size=n)) * np.array([2.5, 1.5, 0.5])[face]
    post = RNG.uniform([1.8, 0.8, 0.5], [2.2, 1.2, 1.5], size=(n // 5, 3))
    return np.concatenate([box, post])


@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_flipped_pose_turns_the_target_about_its_axis_through_the_centre(axis):
    R = Rotation.random(random_state=1).as_matrix()
    t = np.array([0.3, -0.2, 25.0])
    c = np.array([0.1, -0.05, 0.35])
    R_f, t_f = flipped_pose(R, t, c, axis)
    S = flip_matrix(axis)
    X = RNG.normal(size=(20, 3))
    np.testing.assert_allclose(X @ R_f.T + t_f, (c + (X - c) @ S.T) @ R.T + t, atol=1e-12)
    np.testing.assert_allclose(R_f @ R_f.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R_f) == pytest.approx(1.0)
    R_ff, t_ff = flipped_pose(R_f, t_f, c, axis)                 # two half turns: back where it was
    np.testing.assert_allclose(R_ff, R, atol=1e-12)
    np.testing.assert_allclose(t_ff, t, atol=1e-12)
    np.testing.assert_allclose(X[:1] @ S.T, X[:1] @ Rotation.from_rotvec(np.pi * np.eye(3)["xyz".index(axis)]).as_matrix().T,
                               atol=1e-12)
    with pytest.raises(ValueError):
        flip_matrix("q")


def test_the_points_pick_the_true_pose_over_its_flip():
    surface = _asymmetric_surface()
    c = np.zeros(3)
    R = Rotation.random(random_state=3).as_matrix()
    t = np.array([0.5, 0.2, 30.0])
    seen = surface[RNG.choice(len(surface), 800, replace=False)]
    points = seen @ R.T + t + RNG.normal(scale=0.03, size=seen.shape)
    R_f, t_f = flipped_pose(R, t, c, "z")
    for start, flipped in (((R, t), False), ((R_f, t_f), True)):
        d = resolve_flip(*start, points, surface, c, "z", tolerance=0.1)
        assert d.flipped is flipped
        np.testing.assert_allclose(d.R, R, atol=1e-12)
        np.testing.assert_allclose(d.t, t, atol=1e-12)
        assert d.margin > 0.05 and d.fitness > 0.9


def test_a_symmetric_target_leaves_no_margin_and_keeps_the_input_pose():
    half = _asymmetric_surface()[:3000]                          # the box alone
    surface = np.concatenate([half, half @ flip_matrix("z").T])    # exactly symmetric about z
    R, t = np.eye(3), np.array([0.0, 0.0, 20.0])
    d = resolve_flip(R, t, surface[::7] + t, surface, np.zeros(3), "z", tolerance=0.05)
    assert d.margin == 0.0 and not d.flipped


def test_bundle_flip_settings_are_checked(tmp_path):
    with pytest.raises(BundleError, match="flip_axis"):
        load_bundle(make_bundle(tmp_path / "a", manifest_overrides={"voting": {"min_points": 32, "flip_axis": "w"}}))
    with pytest.raises(BundleError, match="min_flip_margin"):
        load_bundle(make_bundle(tmp_path / "b", manifest_overrides={"voting": {"min_points": 32, "flip_axis": "z",
                                                                               "min_flip_margin": 1.5}}))


@pytest.mark.parametrize("margin, valid", [(0.0, True), (0.99, False)])
def test_estimator_resolves_the_flip_and_gates_on_its_margin(tmp_path, margin, valid):
    surface = np.stack(np.meshgrid(*[np.arange(-4.0, 4.01, 0.3)] * 3, indexing="ij"), -1).reshape(-1, 3)
    target = dict(manifest()["target"], surface_points=surface.tolist())
    folder = make_bundle(tmp_path / "b", manifest_overrides={
        "target": target, "voting": {"min_points": 32, "flip_axis": "z", "min_flip_margin": margin}})
    est = PoseEstimator(paper_rig(640, 480), bundle=load_bundle(folder), threads=1)
    res = est.estimate(*synthetic_pair())
    assert res.valid is valid and "verify" in res.timings_ms
    if valid:
        assert np.isfinite(res.flip_margin) and res.flip_margin >= 0.0
        assert "flip_margin" not in res.to_dict()
    else:
        assert res.status == "weak_votes" and "flip" in res.detail and np.isnan(res.flip_margin)


def test_no_flip_axis_no_flip_stage(tmp_path):
    est = PoseEstimator(paper_rig(640, 480), bundle=load_bundle(make_bundle(tmp_path / "c")), threads=1)
    res = est.estimate(*synthetic_pair())
    assert res.valid and np.isnan(res.flip_margin)


def test_flip_stage_refines_both_poses_when_refine_is_on(tmp_path, monkeypatch):
    from spacepose import estimator as est_mod

    calls = []
    real = est_mod.refine_icp

    def spy(R, t, *args, **kwargs):
        calls.append(np.array(R))
        return real(R, t, *args, **kwargs)

    monkeypatch.setattr(est_mod, "refine_icp", spy)
    surface = np.stack(np.meshgrid(*[np.arange(-4.0, 4.01, 0.3)] * 3, indexing="ij"), -1).reshape(-1, 3)
    target = dict(manifest()["target"], surface_points=surface.tolist())
    folder = make_bundle(tmp_path / "b", manifest_overrides={"target": target, "voting": {"min_points": 32, "flip_axis": "z"}})
    res = PoseEstimator(paper_rig(640, 480), bundle=load_bundle(folder), threads=1, refine=True).estimate(*synthetic_pair())
    assert res.valid and "refine" in res.timings_ms and len(calls) == 2
    np.testing.assert_allclose(calls[1], calls[0] @ flip_matrix("z"), atol=1e-9)   # the pose and its flip
