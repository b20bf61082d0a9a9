import pytest

torch = pytest.importorskip("torch")
onnx = pytest.importorskip("onnx")

from spacepose.errors import SpaceposeError  # noqa: E402
from spacepose.export.metadata import stereo_metadata  # noqa: E402
from spacepose.export.onnx_stereo import export_stereo, forbidden_ops, parity_check  # noqa: E402
from spacepose.models.stereo_config import StereoConfig  # noqa: E402
from spacepose.models.tsca_stereo import TSCAStereo  # noqa: E402
from spacepose.onnx_session import read_metadata  # noqa: E402


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    torch.manual_seed(0)
    cfg = StereoConfig.cpu()
    model = TSCAStereo(cfg).eval()
    meta = stereo_metadata(input_size=(64, 32), iters=2, stereo_config=cfg.to_dict(), dataset={"seed": 7, "size": 10})
    path = tmp_path_factory.mktemp("exp") / "stereo.onnx"
    export_stereo(model, path, size=(64, 32), iters=2, metadata=meta)
    return path, model, meta


def test_single_file_no_forbidden_ops(exported):
    path, _, _ = exported
    assert sorted(p.name for p in path.parent.iterdir()) == ["stereo.onnx"]
    proto = onnx.load(str(path))
    assert forbidden_ops(proto) == set()
    assert proto.opset_import[0].version == 17
    shapes = {i.name: [d.dim_value for d in i.type.tensor_type.shape.dim] for i in proto.graph.input}
    assert shapes == {"left": [1, 3, 32, 64], "right": [1, 3, 32, 64]}


def test_metadata_roundtrip(exported):
    path, _, meta = exported
    got = read_metadata(path)
    assert got["kind"] == "stereo" and got["input_size"] == [64, 32] and got["iters"] == 2
    assert got["variant"] == "full" and got["max_disp"] == 96 and got["dataset"] == {"seed": 7, "size": 10}
    assert "training_commit" in got and got["config"]["variant"] == "full"
    assert got["export"] == {"conv3d_as_2d": True, "conv_transpose3d_as_2d": True, "narrow_conv3d_as_2d": True,
                             "conv3d_depth_winograd": True, "conv_transpose3d_polyphase": True}


def test_grouped_3d_convs_are_exported_as_2d(exported):
    """The rewrites of :mod:`spacepose.export.conv3d_as_2d` are applied: the only 3-D Convs left are
    1x1x1 (the 1-channel classifier is a 2-D Conv with its 3 depth taps as outputs)."""
    path, _, _ = exported
    proto = onnx.load(str(path))
    weights = {i.name: list(i.dims) for i in proto.graph.initializer}
    convs = [({a.name: onnx.helper.get_attribute_value(a) for a in n.attribute}, weights.get(n.input[1]))
             for n in proto.graph.node if n.op_type == "Conv"]
    conv3d = [(a, w) for a, w in convs if len(a["kernel_shape"]) == 3]
    assert conv3d and all(a["kernel_shape"] == [1, 1, 1] for a, _ in conv3d)
    assert any(len(a["kernel_shape"]) == 2 and w[0] == 3 for a, w in convs)        # the stacked classifier
    assert any(len(a["kernel_shape"]) == 2 and a.get("group", 1) > 1 for a, _ in convs)
    transposed = [{a.name: onnx.helper.get_attribute_value(a) for a in n.attribute}
                  for n in proto.graph.node if n.op_type == "ConvTranspose"]
    # the decoder upsamplers in the polyphase form: only their 0/1 pixel shuffles are transposed convolutions
    assert len(transposed) == 3 and all(a["kernel_shape"] == [2, 2] and a["strides"] == [2, 2] and a["group"] > 1
                                        for a in transposed)
    assert not any(n.op_type == "BatchNormalization" for n in proto.graph.node)    # folded into them
    winograd = [n for n in proto.graph.node if n.op_type == "MatMul" and "/regularizer/stem/" in n.name]
    assert len(winograd) == 4                                  # the two dense stem convs: T_in and T_out each


def test_parity_torch_vs_onnxruntime(exported):
    path, model, _ = exported
    diff = parity_check(model, path, size=(64, 32), iters=2)
    assert diff < 1e-3


def test_never_overwrites(exported):
    path, model, meta = exported
    with pytest.raises(SpaceposeError, match="exists"):
        export_stereo(model, path, size=(64, 32), iters=2, metadata=meta)


def test_rejects_bad_size(exported, tmp_path):
    _, model, meta = exported
    with pytest.raises(SpaceposeError, match="multiples of 32"):
        export_stereo(model, tmp_path / "x.onnx", size=(60, 32), iters=2, metadata=meta)


def test_forbidden_ops_detects_gridsample():
    from onnx import helper

    node = helper.make_node("GridSample", ["x", "g"], ["y"])
    graph = helper.make_graph([node], "g", [], [])
    assert forbidden_ops(helper.make_model(graph)) == {"GridSample"}


def test_write_stereo_manifest_merges_and_reads_training_rig(tmp_path):
    import json

    from spacepose.calibration.rig import paper_rig, save_rig
    from spacepose.export.onnx_stereo import write_stereo_manifest

    save_rig(paper_rig(640, 480), tmp_path / "rig.yaml")
    bundle = tmp_path / "bundle"
    bundle.mkdir()
    (bundle / "bundle.json").write_text(json.dumps({"pose": {"file": "pose.onnx"}, "metrics": {"pose": {"e_t": 1}}}))
    path = write_stereo_manifest(bundle, input_size=(256, 256), iters=4, max_disp=96, rig_path=tmp_path / "rig.yaml",
                                 metrics={"epe": 0.5})
    data = json.loads(path.read_text())
    assert data["pose"] == {"file": "pose.onnx"}                      # the pose side is kept
    assert data["metrics"] == {"pose": {"e_t": 1}, "stereo": {"epe": 0.5}}
    assert data["stereo"]["input_size"] == [256, 256] and data["stereo"]["normalisation"] == "rgb_0_255"
    assert data["rig"] == {"image_size": [640, 480], "focal_px": 800.0, "baseline_m": 1.0}


def test_git_commit_names_the_tree_and_its_changes(tmp_path, monkeypatch):
    import subprocess

    from spacepose.export.metadata import COMMIT_ENV, git_commit

    monkeypatch.delenv(COMMIT_ENV, raising=False)
    assert git_commit(tmp_path) is None                       # not a repository
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@t", "-C", str(tmp_path)]
    subprocess.run(git + ["init", "-q"], check=True)
    (tmp_path / "a.txt").write_text("1")
    subprocess.run(git + ["add", "a.txt"], check=True)
    subprocess.run(git + ["commit", "-qm", "one"], check=True)
    head = subprocess.run(git + ["rev-parse", "HEAD"], capture_output=True, text=True, check=True).stdout.strip()
    (tmp_path / "untracked.txt").write_text("x")
    assert git_commit(tmp_path) == head                       # untracked files do not count
    (tmp_path / "a.txt").write_text("2")
    assert git_commit(tmp_path) == head + "+dirty"
    monkeypatch.setenv(COMMIT_ENV, "abc123")
    assert git_commit(tmp_path) == "abc123"
