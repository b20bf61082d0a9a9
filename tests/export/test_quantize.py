"""Tests of spacepose.export.quantize: int8 (static QDQ) and fp16 copies of graphs and bundles."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")
onnx = pytest.importorskip("onnx")

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "runtime"))  # the tiny-bundle helpers
from _bundle_fixtures import make_bundle, synthetic_pair  # noqa: E402

from spacepose.bundle import load_bundle  # noqa: E402
from spacepose.calibration.rig import paper_rig, save_rig  # noqa: E402
from spacepose.errors import SpaceposeError  # noqa: E402
from spacepose.estimator import PoseEstimator  # noqa: E402
from spacepose.export.onnx_stereo import export_random_stereo, parity_inputs  # noqa: E402
from spacepose.export.quantize import (convert_fp16, polyphase_nodes, quantize_bundle, quantize_int8,  # noqa: E402
                                       record_calibration_feeds, winograd_nodes)
from spacepose.imageio import write_image  # noqa: E402
from spacepose.onnx_session import make_session, session_metadata  # noqa: E402


@pytest.fixture(scope="module")
def stereo_graph(tmp_path_factory):
    path, _ = export_random_stereo(tmp_path_factory.mktemp("q") / "stereo.onnx", size=(64, 64), iters=2)
    return path


def _run(path, left, right):
    session = make_session(path, threads=1)
    return session.run(["disparity"], {"left": left, "right": right})[0], session_metadata(session)


def test_int8_graph_is_quantized_close_and_keeps_the_contract(stereo_graph, tmp_path):
    feeds = [dict(zip(("left", "right"), parity_inputs((64, 64), seed=s, disparity=4 + 3 * s))) for s in range(4)]
    dst = tmp_path / "stereo_int8.onnx"
    quantize_int8(stereo_graph, dst, feeds)
    ops = {n.op_type for n in onnx.load(str(dst)).graph.node}
    assert {"QuantizeLinear", "DequantizeLinear"} <= ops
    left, right = parity_inputs((64, 64), seed=9, disparity=6)
    ref, meta_ref = _run(stereo_graph, left, right)
    got, meta = _run(dst, left, right)
    assert got.shape == ref.shape and np.all(np.isfinite(got))
    # an untrained graph gives small disparities; int8 must stay within a few percent of their spread
    assert np.abs(got - ref).mean() < 0.1 * (np.abs(ref).mean() + 1e-3) + 0.05
    assert meta["precision"]["precision"] == "int8" and meta["precision"]["calibration_inputs"] == 4
    # the Winograd depth form (two dense stem layers, one 1/4-resolution decoder layer) and the polyphase
    # convolutions of the three decoder upsamplers stay float32
    graph = onnx.load(str(stereo_graph))
    assert [n.split("/")[-1].rstrip("_1") for n in winograd_nodes(graph)] == ["MatMul", "Conv", "MatMul"] * 3
    polyphase = polyphase_nodes(graph)
    assert len(polyphase) == 3 and all("/decoders." in n and "/up/" in n and n.endswith("/Conv") for n in polyphase)
    kept = winograd_nodes(graph) + polyphase
    assert meta["precision"]["float32_nodes"] == 12
    quantized = onnx.load(str(dst))
    produced_by = {o: n.op_type for n in quantized.graph.node for o in n.output}
    for node in quantized.graph.node:
        if node.name in kept:
            assert all(produced_by.get(x) != "DequantizeLinear" for x in node.input[1:2]), node.name
    assert {k: v for k, v in meta.items() if k != "precision"} == meta_ref
    with pytest.raises(SpaceposeError, match="no calibration"):
        quantize_int8(stereo_graph, tmp_path / "x.onnx", [])


def test_fp16_graph_matches(stereo_graph, tmp_path):
    dst = tmp_path / "stereo_fp16.onnx"
    convert_fp16(stereo_graph, dst)
    left, right = parity_inputs((64, 64), seed=3, disparity=5)
    ref, _ = _run(stereo_graph, left, right)
    got, meta = _run(dst, left, right)
    assert got.dtype == np.float32  # float32 graph inputs and outputs are kept
    np.testing.assert_allclose(got, ref, atol=0.05 + 0.01 * float(np.abs(ref).max()))
    assert meta["precision"] == {"precision": "fp16"}
    assert dst.stat().st_size < 0.7 * Path(stereo_graph).stat().st_size


def _tiny_dataset(root: Path, frames: int = 3) -> Path:
    for sub in ("left", "right"):
        (root / sub).mkdir(parents=True)
    save_rig(paper_rig(640, 480), root / "rig.yaml")
    lines = []
    for i in range(frames):
        left, right = synthetic_pair(shift=30 + 5 * i)
        write_image(root / "left" / f"{i:06d}.png", left)
        write_image(root / "right" / f"{i:06d}.png", right)
        lines.append(json.dumps({"frame": f"{i:06d}", "split": "train", "regime": "sun"}))
    (root / "labels.jsonl").write_text("\n".join(lines) + "\n")
    return root


def test_bundle_copies_record_real_pipeline_inputs_and_never_touch_the_source(tmp_path):
    src = make_bundle(tmp_path / "src")
    before = {p.name: p.read_bytes() for p in src.iterdir()}
    data = _tiny_dataset(tmp_path / "data")
    stereo_feeds, pose_feeds = record_calibration_feeds(src, data, frames=2)
    assert len(stereo_feeds) >= 4 and len(pose_feeds) == 2  # coarse + fine pass per frame, one pose run
    assert set(stereo_feeds[0]) == {"left", "right"} and stereo_feeds[0]["left"].shape[-2:] == (256, 256)

    for precision in ("int8", "fp16"):
        out = quantize_bundle(src, tmp_path / precision, precision, dataset=data, calib_frames=2)
        copy = load_bundle(out)
        assert "float32 source" in (out / "MODEL_CARD.md").read_text()
        res = PoseEstimator(paper_rig(640, 480), bundle=copy, threads=1).estimate(*synthetic_pair())
        assert res.valid, res.status
    assert {p.name: p.read_bytes() for p in src.iterdir()} == before

    with pytest.raises(SpaceposeError, match="not empty"):
        quantize_bundle(src, tmp_path / "fp16", "fp16")
    with pytest.raises(SpaceposeError, match="differ"):
        quantize_bundle(src, src, "fp16", force=True)
    with pytest.raises(SpaceposeError, match="calibrate"):
        quantize_bundle(src, tmp_path / "int8b", "int8")
    with pytest.raises(SpaceposeError, match="precision"):
        quantize_bundle(src, tmp_path / "x", "int4")
