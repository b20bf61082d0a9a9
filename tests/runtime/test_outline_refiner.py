"""Tests of spacepose.outline_refiner and the estimator's polish against the refined outline."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))  # --import-mode=importlib: find the helpers

from spacepose.bundle import load_bundle  # noqa: E402
from spacepose.errors import BundleError, ShapeError  # noqa: E402
from spacepose.outline_refiner import (OutlineRefiner, OutlineRefinerConfig, parse_outline_refiner,  # noqa: E402
                                       refined_outline, refiner_planes)


def make_outline_graph(path: Path, metadata: dict | None = None, gain: float = 10.0) -> None:
    """logit = gain * (grey - 1/2): the refined outline is the bright part of the stereo outline's neighbourhood."""
    import onnx
    from onnx import TensorProto, helper

    from spacepose.onnx_session import write_metadata

    nodes = [
        helper.make_node("Split", ["planes", "split"], ["g", "o", "d"], axis=1),
        helper.make_node("Sub", ["g", "half"], ["c"]),
        helper.make_node("Mul", ["c", "gain"], ["logit"]),
    ]
    graph = helper.make_graph(
        nodes, "outline", [helper.make_tensor_value_info("planes", TensorProto.FLOAT, [1, 3, "H", "W"])],
        [helper.make_tensor_value_info("logit", TensorProto.FLOAT, [1, 1, "H", "W"])],
        initializer=[helper.make_tensor("split", TensorProto.INT64, [3], [1, 1, 1]),
                     helper.make_tensor("half", TensorProto.FLOAT, [], [0.5]),
                     helper.make_tensor("gain", TensorProto.FLOAT, [], [gain])])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    write_metadata(model, metadata if metadata is not None else
                   {"kind": "outline", "planes": 3, "multiple": 4, "target": "tiny"})
    onnx.checker.check_model(model)
    onnx.save(model, str(path))


@pytest.mark.parametrize("section, match", [
    ([], "must be an object"), ({"bogus": 1}, "unknown keys"), ({"file": 3}, "string"), ({"file": ""}, "string"),
    ({"keep_centre": 2}, "keep_centre"), ({"keep_centre": 0.5}, "integer"),
    ({"grow_px": 1.5}, "integer"), ({"grow_px": True}, "integer"), ({"grow_px": -1}, "grow_px"),
    ({"grow_px": 9}, "grow_px"),
])
def test_bad_sections_are_refused(section, match):
    with pytest.raises(BundleError, match=match):
        parse_outline_refiner(section)


def test_a_section_defaults_and_none():
    assert parse_outline_refiner({}) == OutlineRefinerConfig()
    assert parse_outline_refiner(None) is None
    assert parse_outline_refiner({"grow_px": 0}).grow_px == 0


def test_planes_are_relative_to_the_outline_and_clipped():
    rng = np.random.default_rng(0)
    grey = rng.uniform(0.0, 0.2, (40, 40)).astype(np.float32)
    obs = np.zeros((40, 40), np.uint8)
    obs[10:30, 10:30] = 1
    grey[10:30, 10:30] = np.linspace(0.1, 0.5, 400).reshape(20, 20)
    disp = np.where(obs > 0, 1.5, 0.2).astype(np.float32)
    disp[0, 0], disp[1, 1] = np.nan, 9.0
    p = refiner_planes(grey, obs, disp)
    assert p.shape == (3, 40, 40) and p.dtype == np.float32
    ref = np.percentile(grey[obs > 0], 90)
    np.testing.assert_allclose(p[0], np.clip(grey / ref, 0.0, 2.0), rtol=1e-6)
    np.testing.assert_array_equal(p[1], obs.astype(np.float32))
    assert p[2, 0, 0] == 0.0 and p[2, 1, 1] == 3.0 and p[2, 20, 20] == pytest.approx(1.5)
    # the same scene at another exposure gives the same grey plane
    np.testing.assert_allclose(refiner_planes(grey * 3, obs, disp)[0], p[0], rtol=1e-5, atol=1e-6)
    empty = refiner_planes(grey, np.zeros_like(obs), disp)
    assert np.all(np.isfinite(empty)) and empty[1].max() == 0.0
    with pytest.raises(ShapeError):
        refiner_planes(grey, obs[:, :39], disp)
    with pytest.raises(ShapeError):
        refiner_planes(grey.tolist(), obs, disp)


def test_the_refined_outline_stays_near_the_stereo_outline():
    obs = np.zeros((30, 30), np.uint8)
    obs[10:20, 10:20] = 1
    logit = np.ones((30, 30), np.float32)
    for grow in (0, 1, 3):
        out = refined_outline(logit, obs, grow)
        assert out.dtype == np.uint8
        ys, xs = np.nonzero(out)
        assert (ys.min(), ys.max(), xs.min(), xs.max()) == (10 - grow, 19 + grow, 10 - grow, 19 + grow)
    cut = logit.copy()
    cut[:, 14:16] = -1.0                        # a gap the stereo outline filled
    out = refined_outline(cut, obs, 2)
    assert out[15, 14] == 0 and out[15, 13] == 1 and out[15, 16] == 1
    with pytest.raises(ShapeError):
        refined_outline(logit[:, :29], obs, 2)


def test_the_graph_is_checked_and_padded_to_a_multiple_of_four(tmp_path):
    make_outline_graph(tmp_path / "outline.onnx")
    r = OutlineRefiner(tmp_path, OutlineRefinerConfig(), "tiny")
    fed = []

    class Recording:
        def __init__(self, session):
            self.session = session

        def run(self, names, feed):
            fed.append(feed["planes"].shape)
            return self.session.run(names, feed)

    r.session = Recording(r.session)
    rng = np.random.default_rng(1)
    planes = rng.uniform(0.0, 1.0, (3, 30, 30)).astype(np.float32)
    logit = r.logits(planes)
    assert fed == [(1, 3, 32, 32)] and logit.shape == (30, 30)
    np.testing.assert_allclose(logit, 10.0 * (planes[0] - 0.5), atol=1e-5)
    obs = np.zeros((30, 30), np.uint8)
    obs[5:25, 5:25] = 1
    grey = np.full((30, 30), 0.05, np.float32)
    grey[5:25, 5:15] = 0.8                       # the left half of the outline is lit, the right half dark
    out = r.refine(grey, obs, np.ones((30, 30), np.float32))
    assert out[5:25, 5:15].all() and not out[:, 15:].any()
    with pytest.raises(ValueError, match="square"):
        r.logits(planes[:, :, :28])
    for meta, name in (({"kind": "flip", "planes": 3, "multiple": 4, "target": "tiny"}, "kind"),
                       ({"kind": "outline", "planes": 2, "multiple": 4, "target": "tiny"}, "planes"),
                       ({"kind": "outline", "planes": 3, "multiple": 4, "target": "other"}, "target")):
        make_outline_graph(tmp_path / "bad.onnx", metadata=meta)
        with pytest.raises(BundleError, match=name):
            OutlineRefiner(tmp_path, OutlineRefinerConfig(file="bad.onnx"), "tiny")


def _refiner_estimator(tmp_path, polish=1):
    from test_silhouette import _estimator

    from spacepose.calibration.rig import paper_rig
    from spacepose.estimator import PoseEstimator

    est = _estimator(tmp_path, {"min_margin": 0.99}, {"max_chamfer_px": 100.0, "min_margin_px": 0.0,
                                                      "polish": polish})
    data = json.loads((est.bundle.path / "bundle.json").read_text())
    data["outline_refiner"] = {"grow_px": 1}
    (est.bundle.path / "bundle.json").write_text(json.dumps(data))
    return est, PoseEstimator


def test_a_bundle_with_a_refiner_needs_the_polish_and_the_graph(tmp_path):
    est, _ = _refiner_estimator(tmp_path / "off", polish=0)
    with pytest.raises(BundleError, match="polish"):
        load_bundle(est.bundle.path)
    est, _ = _refiner_estimator(tmp_path / "on")
    with pytest.raises(BundleError, match="missing outline.onnx"):
        load_bundle(est.bundle.path)
    make_outline_graph(est.bundle.path / "outline.onnx")
    assert load_bundle(est.bundle.path).outline_refiner == OutlineRefinerConfig(grow_px=1)


def test_the_polish_reads_the_refined_outline_and_the_decision_the_stereo_one(tmp_path, monkeypatch):
    import spacepose.estimator as estimator_module
    from _bundle_fixtures import synthetic_pair

    from spacepose.calibration.rig import paper_rig

    left, right = synthetic_pair()
    est, PoseEstimator = _refiner_estimator(tmp_path)
    make_outline_graph(est.bundle.path / "outline.onnx", metadata={"kind": "outline", "planes": 3, "multiple": 4,
                                                                   "target": est.bundle.target_name})
    with_refiner = PoseEstimator(paper_rig(640, 480), bundle=load_bundle(est.bundle.path), threads=1)
    seen = {}
    decide, polish = estimator_module.decide_outline, estimator_module.polish_pose

    def recording_decide(*args, **kwargs):
        seen["decision"] = decide(*args, **kwargs)
        return seen["decision"]

    def recording_polish(decision, *args, **kwargs):
        seen["polished_against"] = decision.observed.copy()
        return polish(decision, *args, **kwargs)

    monkeypatch.setattr(estimator_module, "decide_outline", recording_decide)
    monkeypatch.setattr(estimator_module, "polish_pose", recording_polish)
    res = with_refiner.estimate(left, right)
    assert res.valid and res.decided_by == "outline", res.detail
    decision = seen["decision"]
    assert decision.min_disparity > 0.0
    stereo = decision.observed
    refined = seen["polished_against"]
    assert refined.shape == stereo.shape and not np.array_equal(refined, stereo)
    # what the graph gives on the same planes
    from spacepose.image_vote import window_grey
    fr = decision.frame
    grey = window_grey(left, fr.x0, fr.y0, fr.side, fr.size)
    assert "outline_net" in res.timings_ms and res.network_ms > 0.0
    want = refined_outline(10.0 * (refiner_planes(grey, stereo, np.ones_like(grey))[0] - 0.5), stereo, 1)
    np.testing.assert_array_equal(refined, want)
    # without the refiner the polish reads the stereo outline
    seen.clear()
    est.estimate(left, right)
    np.testing.assert_array_equal(seen["polished_against"], seen["decision"].observed)


def test_quantized_copies_keep_the_outline_graph_float32(tmp_path):
    from spacepose.export.quantize import quantize_bundle

    est, _ = _refiner_estimator(tmp_path)
    make_outline_graph(est.bundle.path / "outline.onnx")
    out = quantize_bundle(est.bundle.path, tmp_path / "fp16", "fp16")
    assert (out / "outline.onnx").read_bytes() == (est.bundle.path / "outline.onnx").read_bytes()
    assert load_bundle(out).outline_refiner == OutlineRefinerConfig(grow_px=1)


@pytest.mark.parametrize("keep_centre, refined_ok", [(1, True), (0, True), (1, False)])
def test_the_refined_polish_gives_the_rotation_and_the_stereo_polish_the_centre(tmp_path, monkeypatch, keep_centre,
                                                                                 refined_ok):
    import spacepose.estimator as estimator_module
    from _bundle_fixtures import synthetic_pair

    from spacepose.calibration.rig import paper_rig
    from spacepose.registration import exp_so3
    from spacepose.silhouette import OutlineFit

    left, right = synthetic_pair()
    est, PoseEstimator = _refiner_estimator(tmp_path)
    data = json.loads((est.bundle.path / "bundle.json").read_text())
    data["outline_refiner"]["keep_centre"] = keep_centre
    (est.bundle.path / "bundle.json").write_text(json.dumps(data))
    make_outline_graph(est.bundle.path / "outline.onnx", metadata={"kind": "outline", "planes": 3, "multiple": 4,
                                                                   "target": est.bundle.target_name})
    bundle = load_bundle(est.bundle.path)
    with_refiner = PoseEstimator(paper_rig(640, 480), bundle=bundle, threads=1)
    decide = estimator_module.decide_outline
    seen = {}

    def recording_decide(*args, **kwargs):
        seen["decision"] = decide(*args, **kwargs)
        return seen["decision"]

    turn_a, turn_b = exp_so3(np.radians([1.0, 0.0, 0.0])), exp_so3(np.radians([0.0, 1.5, 0.0]))

    def polish(decision, R, t, *args, **kwargs):
        if np.array_equal(decision.observed, seen["decision"].observed):       # the stereo outline
            return OutlineFit(turn_a @ R, np.asarray(t) + [0.01, 0.0, 0.05], 0.5)
        return OutlineFit(turn_b @ R, np.asarray(t) + [0.0, -0.02, 0.3], 0.5) if refined_ok else None

    monkeypatch.setattr(estimator_module, "decide_outline", recording_decide)
    monkeypatch.setattr(estimator_module, "polish_pose", polish)
    res = with_refiner.estimate(left, right)
    assert res.valid, res.detail
    R0, t0 = res.decided
    centre = np.asarray(bundle.centre)
    assert res.polish_deg == pytest.approx(1.0, abs=1e-6)     # the caps read the stereo polish's turn, not 1.5 deg
    assert res.polish_deg == pytest.approx(1.0, abs=1e-6)     # the caps read the stereo polish's turn, not 1.5 deg
    if not refined_ok:                                   # the stereo polish stands
        np.testing.assert_allclose(res.R, turn_a @ R0, atol=1e-9)
        np.testing.assert_allclose(res.t, t0 + [0.01, 0.0, 0.05], atol=1e-9)
        return
    np.testing.assert_allclose(res.R, turn_b @ R0, atol=1e-9)
    if keep_centre:
        np.testing.assert_allclose(res.R @ centre + res.t, turn_a @ R0 @ centre + t0 + [0.01, 0.0, 0.05], atol=1e-9)
    else:
        np.testing.assert_allclose(res.t, t0 + [0.0, -0.02, 0.3], atol=1e-9)


def test_the_shipped_bundle_refines_the_outline_for_the_polish():
    """reports/outline_s41/plan2.txt (met in session 41): the outline refiner, grow_px 2, keep_centre 1."""
    from spacepose.outline_refiner import OutlineRefiner

    bundle = load_bundle(None, verify_graphs=False)
    assert bundle.outline_refiner == OutlineRefinerConfig(file="outline.onnx", grow_px=2, keep_centre=1)
    graph = OutlineRefiner(bundle.path, bundle.outline_refiner, bundle.target_name)
    assert graph.metadata["config"] == {"width": 16, "prior": 4.0}
    obs = np.zeros((40, 40), np.uint8)
    obs[8:32, 8:32] = 1
    grey = np.where(obs > 0, 0.6, 0.0).astype(np.float32)
    out = graph.refine(grey, obs, np.where(obs > 0, 1.5, 0.1).astype(np.float32))
    assert out.shape == (40, 40) and out.dtype == np.uint8
    inter, union = (out & obs).sum(), (out | obs).sum()
    assert inter / union > 0.8           # a lit square with its own outline stays (near) itself
