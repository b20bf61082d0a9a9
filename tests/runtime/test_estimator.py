"""Tests of spacepose.estimator.PoseEstimator with the tiny test bundle (plumbing, no trained net)."""

import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))  # --import-mode=importlib: find the helpers
from _bundle_fixtures import make_bundle, synthetic_pair  # noqa: E402

from spacepose.bundle import load_bundle  # noqa: E402
from spacepose.calibration.rig import StereoRig, paper_rig, save_rig  # noqa: E402
from spacepose.errors import BundleError, ShapeError  # noqa: E402
from spacepose.estimator import PoseEstimator, PoseResult, refine_icp, rotation_to_quaternion  # noqa: E402

STAGES = ["validate", "rectify", "stereo", "pose_inputs", "pose_net", "voting"]


@pytest.fixture(scope="module")
def bundle(tmp_path_factory):
    return load_bundle(make_bundle(tmp_path_factory.mktemp("bundle") / "tiny"))


@pytest.fixture()
def estimator(bundle):
    return PoseEstimator(paper_rig(640, 480), bundle=bundle, threads=1)


def test_end_to_end_valid_pose(estimator):
    left, right = synthetic_pair()
    res = estimator.estimate(left, right)
    assert isinstance(res, PoseResult)
    assert res.valid and res.status == "ok" and res.detail == ""
    # the tiny graphs vote for (cloud mean + model point): R = I, t = cloud mean - centre
    np.testing.assert_allclose(res.R, np.eye(3), atol=1e-5)
    assert res.t[2] > 0 and np.all(np.abs(res.t[:2]) < 1.0)
    np.testing.assert_allclose(res.q_wxyz, [1, 0, 0, 0], atol=1e-5)
    assert 0.0 < res.confidence <= 1.0
    assert list(res.timings_ms) == STAGES
    # the graphs' own time is part of the stereo and pose_net stages, never more than them
    assert 0.0 < res.network_ms <= res.timings_ms["stereo"] + res.timings_ms["pose_net"]
    assert res.n_points > 32 and res.roi is not None
    record = res.to_dict("000001.png")
    assert record["frame"] == "000001.png" and record["valid"] is True and record["tracked"] is False
    assert set(record) >= {"frame", "valid", "status", "R", "t", "q_wxyz", "confidence", "timings_ms"}
    # both graphs have fixed input sizes: their sessions keep onnxruntime's memory arena
    assert estimator.stereo.session.get_session_options().enable_cpu_mem_arena
    assert estimator.pose_session.get_session_options().enable_cpu_mem_arena


def test_calib_from_file_and_grey_uint16(bundle, tmp_path):
    save_rig(paper_rig(640, 480), tmp_path / "rig.yaml")
    est = PoseEstimator(tmp_path / "rig.yaml", bundle=bundle.path, threads=1)
    left, right = synthetic_pair(dtype=np.uint16, colour=False)
    assert est.estimate(left, right).valid
    left, right = synthetic_pair(colour=False)
    assert est.estimate(left[..., None], right[..., None]).valid
    left, right = synthetic_pair()
    assert est.estimate(left.astype(np.float32), right.astype(np.float32)).valid


@pytest.fixture()
def windowed(bundle):
    """An estimator whose frame after a valid pose takes its window from that pose (``prior_window``)."""
    return PoseEstimator(paper_rig(640, 480), bundle=bundle, threads=1, prior_window=True)


@pytest.fixture()
def stereo_hints(windowed, monkeypatch):
    """The ROI hint of every stereo pass the ``windowed`` estimator runs, in order."""
    hints = []
    estimator = windowed
    original = estimator.stereo.match

    def spy(left, right, roi_hint=None):
        hints.append(roi_hint)
        return original(left, right, roi_hint=roi_hint)

    monkeypatch.setattr(estimator.stereo, "match", spy)
    return hints


def test_prior_skips_coarse_pass(windowed, stereo_hints):
    estimator, hints = windowed, stereo_hints
    left, right = synthetic_pair()
    assert estimator.estimate(left, right).valid
    estimator.estimate(left, right)
    assert hints[0] is None and hints[1] is not None
    d_min, d_max = hints[1].d_min, hints[1].d_max
    assert 0 < d_min < d_max
    estimator.reset()
    estimator.estimate(left, right)
    assert hints[2] is None


@pytest.mark.parametrize("gap", [0, 1, 3])
def test_prior_outlives_up_to_gap_frames_without_a_valid_pose(bundle, gap):
    """An eclipse (dark frames, no_target) ages the prior; it expires after ``prior_max_gap`` such frames. A
    bad frame (bad_input) leaves it as it was."""
    est = PoseEstimator(paper_rig(640, 480), bundle=bundle, threads=1, prior_max_gap=gap, prior_window=True)
    left, right = synthetic_pair()
    dark = (np.zeros_like(left), np.zeros_like(right))
    assert est.estimate(left, right).valid
    assert est._roi_hint() is not None                              # the frame right after: its window
    for k in range(gap):
        assert est.estimate(*dark).status == "no_target"
        assert est._valid_prior() is not None, f"prior lost after {k + 1} of {gap} frames"
        assert est._roi_hint() is None                              # but the coarse pass looks again
    bad = est.estimate(left, right[:, :-1])                          # a bad frame does not count
    assert bad.status == "bad_input" and est._valid_prior() is not None
    assert est.estimate(*dark).status == "no_target"                # one frame more than the gap: gone
    assert est._roi_hint() is None and est._valid_prior() is None
    assert est.estimate(left, right).valid and est._valid_prior() is not None   # a valid pose restarts it


def test_a_bad_frame_keeps_the_window(windowed):
    estimator = windowed
    left, right = synthetic_pair()
    assert estimator.estimate(left, right).valid
    assert estimator.estimate(left, right[:, :-1]).status == "bad_input"
    assert estimator._roi_hint() is not None                         # as before session 13


def test_prior_conflict_clears_the_prior(estimator, monkeypatch):
    """A pose decided on its own but half turned from the prior: neither is trusted, the prior goes."""
    left, right = synthetic_pair()
    assert estimator.estimate(left, right).valid and estimator._valid_prior() is not None
    from spacepose.estimator import _stage_invalid

    real = estimator._pose_from_pair

    def conflicting(left_r, right_r, hint, timer):
        status, stage, window, detail = real(left_r, right_r, hint, timer)
        return "weak_votes", _stage_invalid(stage, "weak_votes", {"prior_conflict": 1.0}), window, "turned"

    monkeypatch.setattr(estimator, "_pose_from_pair", conflicting)
    assert not estimator.estimate(left, right).valid
    assert estimator._valid_prior() is None


def test_prior_max_gap_is_checked(bundle):
    with pytest.raises(ValueError, match="prior_max_gap"):
        PoseEstimator(paper_rig(640, 480), bundle=bundle, threads=1, prior_max_gap=-1)


def test_prior_that_lost_the_target_falls_back_to_the_coarse_pass(windowed, stereo_hints, monkeypatch):
    """Frames that are not a sequence: a stale prior window must not cost the pose."""
    estimator, hints = windowed, stereo_hints
    left, right = synthetic_pair()
    assert estimator.estimate(left, right).valid
    # a stale prior: the previous pose put the target in the bottom-right corner, where this frame
    # holds only black sky
    from spacepose.stereo_stage import RoiHint

    monkeypatch.setattr(estimator, "_roi_hint", lambda: RoiHint((560, 400, 640, 480), 20.0, 40.0))
    result = estimator.estimate(left, right)
    assert hints[1] == RoiHint((560, 400, 640, 480), 20.0, 40.0) and hints[2] is None  # prior, then coarse
    assert result.valid and result.status == "ok"
    assert result.timings_ms["stereo"] > 0


@pytest.mark.parametrize("status, passes", [("weak_votes", 1), ("no_target", 2), ("fit_residual", 2),
                                            ("too_few_points", 2), ("out_of_range", 2)])
def test_only_a_window_that_lost_the_target_is_run_again(estimator, monkeypatch, status, passes):
    """A frame that found the target in the prior window but cannot tell its pose from the flip
    (weak_votes) would find the same target with the coarse pass, at twice the cost."""
    from spacepose.stereo_stage import RoiHint

    calls = []
    monkeypatch.setattr(estimator, "_roi_hint", lambda: RoiHint((200, 150, 440, 330), 20.0, 40.0))
    monkeypatch.setattr(estimator, "_pose_from_pair",
                        lambda left, right, hint, timer: calls.append(hint) or (status, None, None, "stub"))
    result = estimator.estimate(*synthetic_pair())
    assert len(calls) == passes and result.status == status and not result.valid
    assert calls[0] is not None and (passes == 1 or calls[1] is None)


@pytest.mark.parametrize("surface, valid", [
    # a dense grid filling the space around the object: every observed point lies "on" it
    (np.stack(np.meshgrid(*[np.arange(-4.0, 4.01, 0.3)] * 3, indexing="ij"), -1).reshape(-1, 3), True),
    # a surface far from where the fitted pose puts the target: the data contradict the pose
    (np.full((50, 3), 100.0) + np.arange(50)[:, None] * 0.01, False),
])
def test_surface_fitness_check_compares_the_pose_with_the_data(tmp_path, surface, valid):
    from _bundle_fixtures import manifest

    target = dict(manifest()["target"], surface_points=surface.tolist())
    folder = make_bundle(tmp_path / "b", manifest_overrides={
        "target": target, "voting": {"min_points": 32, "min_surface_fitness": 0.5}})
    est = PoseEstimator(paper_rig(640, 480), bundle=load_bundle(folder), threads=1)
    res = est.estimate(*synthetic_pair())
    assert res.valid is valid and "verify" in res.timings_ms
    if not valid:
        assert res.status == "fit_residual" and "target surface" in res.detail and np.all(np.isnan(res.t))


@pytest.mark.parametrize("score, valid", [(0.1, False), (0.9, True), (None, True)])
def test_photometric_check_rejects_poses_the_images_contradict(tmp_path, monkeypatch, score, valid):
    from _bundle_fixtures import manifest

    import spacepose.estimator as est_mod
    from spacepose.photometric import PhotoConsistency

    seen = []

    def fake(R, t, surface, left, right, K, baseline_m):
        seen.append((left.shape, right.shape, baseline_m))
        return PhotoConsistency(score, 0 if score is None else 500, 800)

    monkeypatch.setattr(est_mod, "photometric_consistency", fake)
    target = dict(manifest()["target"], surface_points=np.zeros((10, 3)).tolist())
    folder = make_bundle(tmp_path / "b", manifest_overrides={
        "target": target, "voting": {"min_points": 32, "min_photo_consistency": 0.3}})
    est = PoseEstimator(paper_rig(640, 480), bundle=load_bundle(folder), threads=1)
    res = est.estimate(*synthetic_pair())
    assert len(seen) == 1 and seen[0][0][:2] == (480, 640) and seen[0][2] == pytest.approx(est.baseline_m)
    assert res.valid is valid and "verify" in res.timings_ms
    if not valid:
        assert res.status == "fit_residual" and "disagree" in res.detail and np.all(np.isnan(res.R))


def test_photometric_check_off_by_default(bundle, monkeypatch):
    import spacepose.estimator as est_mod

    monkeypatch.setattr(est_mod, "photometric_consistency", lambda *a, **k: pytest.fail("check ran while disabled"))
    assert bundle.voting.min_photo_consistency == -1.0
    assert PoseEstimator(paper_rig(640, 480), bundle=bundle, threads=1).estimate(*synthetic_pair()).valid


@pytest.mark.parametrize("prior_window", [True, False])
def test_the_prior_window_option(bundle, monkeypatch, prior_window):
    """prior_window=False: the frame after a valid pose runs the coarse pass too, and the prior still stands
    (it decides a pose from its flip); True: that frame's window is the previous pose's."""
    est = PoseEstimator(paper_rig(640, 480), bundle=bundle, threads=1, prior_window=prior_window)
    hints = []
    original = est.stereo.match
    monkeypatch.setattr(est.stereo, "match", lambda l, r, roi_hint=None: hints.append(roi_hint) or original(l, r, roi_hint))
    left, right = synthetic_pair()
    assert est.estimate(left, right).valid and est._valid_prior() is not None
    assert est.estimate(left, right).valid and est._valid_prior() is not None
    assert hints[0] is None and (hints[1] is not None) == prior_window
    assert (est._roi_hint() is not None) == prior_window


def test_no_prior_option(bundle, monkeypatch):
    est = PoseEstimator(paper_rig(640, 480), bundle=bundle, threads=1, use_prior=False)
    left, right = synthetic_pair()
    est.estimate(left, right)
    assert est._roi_hint() is None


class TestBadInput:
    @pytest.mark.parametrize("make, detail", [
        (lambda l, r: (l[..., :2], r[..., :2]), "shape"),
        (lambda l, r: (l[None], r[None]), "shape"),
        (lambda l, r: (l.astype(np.int32), r.astype(np.int32)), "dtype"),
        (lambda l, r: (l, r[:, :-1]), "differ"),
        (lambda l, r: (l, r.astype(np.uint16)), "differ"),
        (lambda l, r: (l[:-2, :-2], r[:-2, :-2]), "calibration"),
        (lambda l, r: (np.where(l > 0, np.nan, 0.0), r.astype(np.float64)), "NaN"),
        (lambda l, r: (np.full_like(l, 255), np.full_like(r, 255)), "saturated"),
        (lambda l, r: (np.full(l.shape, 65535, np.uint16), np.full(r.shape, 65535, np.uint16)), "saturated"),
        (lambda l, r: (np.full(l.shape, 255.0, np.float32), np.full(r.shape, 255.0, np.float32)), "saturated"),
        (lambda l, r: (l, np.where((np.arange(r.shape[1]) < 0.6 * r.shape[1])[None, :, None], 255, r).astype(np.uint8)),
         "saturated"),
    ])
    def test_bad_input_status(self, estimator, make, detail):
        left, right = make(*synthetic_pair())
        res = estimator.estimate(left, right)
        assert (res.valid, res.status, res.confidence) == (False, "bad_input", 0.0)
        assert detail in res.detail
        assert np.all(np.isnan(res.R)) and np.all(np.isnan(res.q_wxyz))
        assert "validate" in res.timings_ms

    def test_all_black_is_no_target(self, estimator):
        left, right = synthetic_pair()
        res = estimator.estimate(np.zeros_like(left), np.zeros_like(right))
        assert (res.valid, res.status) == (False, "no_target")

    def test_dim_frame_without_target_is_no_target(self, estimator):
        left, right = synthetic_pair()
        noise = np.random.default_rng(0).integers(0, 10, size=left.shape, dtype=np.uint8)
        res = estimator.estimate(np.maximum(noise, 6), noise)  # below the fake graph's threshold
        assert res.status == "no_target" and not res.valid

    @pytest.mark.parametrize("left", [None, [[0]], "image"])
    def test_not_an_array_raises(self, estimator, left):
        _, right = synthetic_pair()
        with pytest.raises(ShapeError):
            estimator.estimate(left, right)


def test_mismatched_calibration_refused(bundle):
    base = paper_rig(640, 480)
    rig = StereoRig(base.M1, base.D1, base.M2, base.D2, base.R, np.array([-0.05, 0.0, 0.0]), base.image_size)
    with pytest.raises(BundleError, match="does not fit"):
        PoseEstimator(rig, bundle=bundle, threads=1)


def test_the_json_line_carries_the_depth_tolerance_of_a_valid_pose():
    pose = dict(R=np.eye(3), t=np.array([0.0, 0.0, 20.0]), q_wxyz=np.array([1.0, 0.0, 0.0, 0.0]), confidence=0.8)
    assert PoseResult(valid=True, status="ok", depth_tolerance_m=0.61, **pose).to_dict()["depth_tolerance_m"] == 0.61
    assert PoseResult(valid=False, status="weak_votes", depth_tolerance_m=0.61, **pose).to_dict()[
        "depth_tolerance_m"] is None
    assert PoseResult(valid=True, status="ok", **pose).to_dict()["depth_tolerance_m"] is None   # no registration
    # a frame with only its position (the flip undecided) carries the tolerance too: it bounds the position
    line = PoseResult(valid=False, status="weak_votes", depth_tolerance_m=0.61, position=np.array([0.0, 0.1, 20.0]),
                      position_valid=True, **pose).to_dict()
    assert line["depth_tolerance_m"] == 0.61 and line["position"] == [0.0, 0.1, 20.0] and line["position_valid"] is True


def test_a_valid_pose_reports_its_centre_as_the_position(estimator):
    left, right = synthetic_pair()
    res = estimator.estimate(left, right)
    assert res.valid and res.position_valid
    np.testing.assert_allclose(res.position, res.R @ estimator.bundle.centre + res.t, atol=1e-12)
    record = res.to_dict()
    assert record["position_valid"] is True and len(record["position"]) == 3


def test_a_short_baseline_gets_the_tiled_coarse_pass():
    """The shipped bundle on the paper rig runs one letterboxed coarse pass; with a 0.3 m baseline the
    target would fall below the detection floor at 50 m there, and the estimator tiles it 2x2."""
    base = paper_rig(1280, 960)
    short = StereoRig(base.M1, base.D1, base.M2, base.D2, base.R, np.array([-0.3, 0.0, 0.0]), base.image_size)
    assert PoseEstimator(base, threads=1).stereo.coarse_tiles == 1
    est = PoseEstimator(short, threads=1)
    assert est.stereo.coarse_tiles == 2 and est.stereo.coarse_view_size == (480, 480)


def test_bad_calib_type(bundle):
    with pytest.raises(TypeError):
        PoseEstimator(42, bundle=bundle)


def test_threads_share_one_estimator(estimator):
    left, right = synthetic_pair()
    results, errors = [], []

    def work():
        try:
            for _ in range(2):
                results.append(estimator.estimate(left, right))
        except Exception as err:  # pragma: no cover - reported below
            errors.append(err)

    threads = [threading.Thread(target=work) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    assert len(results) == 6 and all(r.status in ("ok", "too_few_points", "no_target") for r in results)


def test_quaternion_matches_rotation():
    rng = np.random.default_rng(0)
    for _ in range(20):
        w, x, y, z = (q := rng.normal(size=4)) / np.linalg.norm(q)
        R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                      [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                      [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
        expected = np.array([w, x, y, z]) * (1 if w >= 0 else -1)
        np.testing.assert_allclose(rotation_to_quaternion(R), expected, atol=1e-9)
    assert np.all(np.isnan(rotation_to_quaternion(np.full((3, 3), np.nan))))


def test_refine_icp_recovers_small_offset():
    rng = np.random.default_rng(0)
    # a box surface: samples and normals on its six faces
    pts, nrm = [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            p = rng.uniform(-1, 1, size=(150, 3)) * np.array([2.0, 1.5, 1.0])
            p[:, axis] = sign * [2.0, 1.5, 1.0][axis]
            n = np.zeros((150, 3))
            n[:, axis] = sign
            pts.append(p)
            nrm.append(n)
    model, normals = np.vstack(pts), np.vstack(nrm)
    R_true, t_true = np.eye(3), np.array([0.0, 0.0, 20.0])
    scene = model[model[:, 2] < 0] @ R_true.T + t_true  # the visible (camera-facing) side
    angle = np.radians(2.0)
    R0 = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    t0 = t_true + np.array([0.05, -0.05, 0.08])
    R1, t1 = refine_icp(R0, t0, scene, model, normals, max_distance=0.5, iterations=10)
    assert np.linalg.norm(t1 - t_true) < np.linalg.norm(t0 - t_true)


def test_import_does_not_pull_torch():
    code = ("import sys, spacepose.estimator, spacepose.cli_estimate, spacepose.cli_profile, spacepose.cli_demo; "
            "bad = [m for m in ('torch', 'scipy', 'sklearn', 'trimesh') if m in sys.modules]; "
            "print(bad); sys.exit(1 if bad else 0)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stdout + proc.stderr
