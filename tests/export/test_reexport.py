"""``spacepose reexport``: a graph from an older exporter comes back in the current form, same function."""

import sys
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
onnx = pytest.importorskip("onnx")

sys.path.insert(0, str(Path(__file__).resolve().parent))  # --import-mode=importlib: find the helpers
from _export_fixtures import TINY_POSE_NET, randomise_batchnorm  # noqa: E402

from spacepose.errors import SpaceposeError  # noqa: E402
from spacepose.export import onnx_pose, onnx_stereo  # noqa: E402
from spacepose.export.metadata import stereo_metadata  # noqa: E402
from spacepose.export.reexport import reexport_graph  # noqa: E402
from spacepose.models.pose_net import PoseNet  # noqa: E402
from spacepose.models.stereo_config import StereoConfig  # noqa: E402
from spacepose.models.tsca_stereo import TSCAStereo  # noqa: E402
from spacepose.onnx_session import make_session, read_metadata  # noqa: E402

SIZE, ITERS = (64, 32), 2



@pytest.fixture(scope="module")
def old_stereo(tmp_path_factory):
    """A stereo graph as sessions 6-12 exported it: 3-D ConvTranspose layers and their BatchNorms."""
    torch.manual_seed(0)
    cfg = StereoConfig.cpu()
    model = randomise_batchnorm(TSCAStereo(cfg), 3)
    meta = stereo_metadata(input_size=SIZE, iters=ITERS, stereo_config=cfg.to_dict(), dataset={"seed": 5, "size": 9},
                           metrics={"epe": 1.25}, extra={"training": {"step": 77}})
    path = tmp_path_factory.mktemp("old") / "stereo.onnx"
    onnx_stereo.export_stereo(model, path, size=SIZE, iters=ITERS, metadata=meta, rewrite_transposed=False,
                              rewrite_narrow=False, rewrite_polyphase=False)
    return path, model


def _transposed_dims(path):
    return sorted({len(next(a.ints for a in n.attribute if a.name == "kernel_shape"))
                   for n in onnx.load(str(path)).graph.node if n.op_type == "ConvTranspose"})


def test_stereo_graph_comes_back_in_the_new_form(old_stereo, tmp_path):
    path, model = old_stereo
    before = path.read_bytes()
    out = tmp_path / "new.onnx"
    result = reexport_graph(path, out)
    assert path.read_bytes() == before                                    # the old graph is untouched
    assert _transposed_dims(path) == [3] and _transposed_dims(out) == [2]
    assert result["kind"] == "stereo" and result["export"] == {"conv3d_as_2d": True, "conv_transpose3d_as_2d": True,
                                                               "narrow_conv3d_as_2d": True,
                                                               "conv3d_depth_winograd": True,
                                                               "conv_transpose3d_polyphase": True}
    assert max(result["recovery_parity"], result["torch_parity"], result["graph_parity"]) < 1e-3
    old_meta, new_meta = read_metadata(path), read_metadata(out)
    for key in ("dataset", "metrics", "training", "config", "input_size", "iters", "max_disp", "training_commit"):
        assert new_meta[key] == old_meta[key], key
    assert new_meta["exported_utc"] >= old_meta["exported_utc"]
    assert new_meta["reexported"] == {"from": "stereo.onnx", "first_exported_utc": old_meta["exported_utc"],
                                      "previous_export": old_meta["export"]}
    # the two graphs agree on another pair than the checks' own
    rng = np.random.default_rng(4)
    left = (rng.random((1, 3, SIZE[1], SIZE[0])) * 255).astype(np.float32)
    feeds = {"left": left, "right": np.roll(left, -5, axis=3)}
    a = make_session(path).run(None, feeds)[0]
    b = make_session(out).run(None, feeds)[0]
    assert np.max(np.abs(a - b)) < 1e-3


def test_refuses_to_overwrite(old_stereo, tmp_path):
    path, _ = old_stereo
    with pytest.raises(SpaceposeError, match="being re-exported"):
        reexport_graph(path, path, force=True)
    existing = tmp_path / "taken.onnx"
    existing.write_bytes(b"keep me")
    with pytest.raises(SpaceposeError, match="exists"):
        reexport_graph(path, existing)
    assert existing.read_bytes() == b"keep me"


def test_pose_graph_comes_back(tmp_path):
    net = TINY_POSE_NET
    torch.manual_seed(0)
    model = randomise_batchnorm(PoseNet(net), 4)
    kp = np.random.default_rng(0).uniform(-2, 2, size=(8, 3))
    meta = onnx_pose.pose_metadata(net, keypoints=kp, centre=np.zeros(3), target="tdrs")
    path = onnx_pose.export_pose(model, tmp_path / "pose.onnx", metadata=meta)
    result = reexport_graph(path, tmp_path / "again.onnx")
    assert result["kind"] == "pose" and result["graph_parity"] < 1e-3
    assert np.allclose(read_metadata(tmp_path / "again.onnx")["keypoints"], kp)


def test_cli_reexport(old_stereo, tmp_path, capsys):
    from spacepose.cli import main

    path, _ = old_stereo
    assert main(["reexport", str(path), "--out", str(tmp_path / "cli.onnx")]) == 0
    assert "old vs new graph" in capsys.readouterr().out and (tmp_path / "cli.onnx").is_file()
