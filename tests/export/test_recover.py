"""Weights recovered from an exported graph reproduce it, and fine-tune with frozen BatchNorms."""

import dataclasses
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
from spacepose.export.recover import (checkpoint_from_graph, freeze_batchnorm,  # noqa: E402
                                      recover_state_dict)
from spacepose.models.pose_config import PoseNetConfig  # noqa: E402
from spacepose.models.pose_net import PoseNet  # noqa: E402
from spacepose.models.stereo_config import StereoConfig  # noqa: E402
from spacepose.models.tsca_stereo import TSCAStereo  # noqa: E402

SIZE, ITERS = (64, 32), 2


def _export_stereo(model, path):
    return onnx_stereo.export_stereo(model, path, size=SIZE, iters=ITERS, metadata={}, force=True)


@pytest.fixture(scope="module")
def stereo_graph(tmp_path_factory):
    torch.manual_seed(0)
    cfg = StereoConfig.cpu()
    model = randomise_batchnorm(TSCAStereo(cfg), 1)
    path = tmp_path_factory.mktemp("rec") / "stereo.onnx"
    meta = stereo_metadata(input_size=SIZE, iters=ITERS, stereo_config=cfg.to_dict(), dataset={"seed": 1, "size": 4},
                           extra={"training": {"step": 33}})
    onnx_stereo.export_stereo(model, path, size=SIZE, iters=ITERS, metadata=meta)
    return path, model, cfg


def test_stereo_weights_come_back(stereo_graph):
    path, original, cfg = stereo_graph
    torch.manual_seed(123)                                   # other random weights
    model = TSCAStereo(cfg).eval()
    report = recover_state_dict(model, path, _export_stereo, prefix="model.")
    assert report.folded_bn                                  # the exporter folded BatchNorms into convs
    assert any(".up.1" in name for name in report.folded_bn)  # ... and into the rewritten ConvTranspose3d
    # only the training-time upsampler of the initial disparity is absent from an inference graph
    assert all(k.startswith("init_mask.") for k in report.missing)
    left, right = (torch.from_numpy(a) for a in onnx_stereo.parity_inputs(SIZE))
    with torch.no_grad():
        want = original(left, right, iters=ITERS, test_mode=True)
        got = model(left, right, iters=ITERS, test_mode=True)
    assert float(torch.max(torch.abs(got - want))) < 1e-3
    assert onnx_stereo.parity_check(model, path, size=SIZE, iters=ITERS) < 1e-3
    # the folded BatchNorm is an identity carrying the folded bias
    bn = dict(model.named_modules())[report.folded_bn[0]]
    assert torch.allclose(bn.weight, torch.ones_like(bn.weight))
    assert torch.allclose(bn.running_mean, torch.zeros_like(bn.running_mean))


def test_recover_rejects_another_architecture(stereo_graph):
    path, _, cfg = stereo_graph
    other = TSCAStereo(cfg.replace(variant="igev")).eval()
    with pytest.raises(SpaceposeError, match="structure differs|other node inputs"):
        recover_state_dict(other, path, _export_stereo, prefix="model.")


def test_pose_weights_come_back(tmp_path):
    torch.manual_seed(0)
    original = randomise_batchnorm(PoseNet(TINY_POSE_NET), 2)
    path = onnx_pose.export_pose(original, tmp_path / "pose.onnx", metadata={})
    torch.manual_seed(5)
    model = PoseNet(TINY_POSE_NET).eval()
    report = recover_state_dict(model, path, lambda m, p: onnx_pose.export_pose(m, p, metadata={}, force=True))
    assert report.missing == () and report.folded_bn
    assert onnx_pose.parity_check(model, path)["max"] < 1e-4


def test_frozen_batchnorm_keeps_running_statistics_in_training():
    torch.manual_seed(0)
    model = randomise_batchnorm(PoseNet(TINY_POSE_NET), 3)
    keys = list(model.state_dict())
    assert freeze_batchnorm(model) > 0
    model.train()
    bns = [m for m in model.modules() if isinstance(m, torch.nn.BatchNorm2d)]
    assert bns and all(not m.training for m in bns)
    before = [m.running_mean.clone() for m in bns]
    x = torch.randn(2, 3, 64, 64) * 50 + 100
    model.rgb.stem(model.rgb.normalise(x))
    assert all(torch.equal(a, m.running_mean) for a, m in zip(before, bns))   # no statistics update
    assert all(m.weight.requires_grad for m in bns)                           # affine still trains
    assert list(model.state_dict()) == keys


def test_checkpoint_from_graph_feeds_training(stereo_graph, tmp_path):
    path, _, cfg = stereo_graph
    ckpt = checkpoint_from_graph(path)
    assert ckpt["kind"] == "stereo" and ckpt["step"] == 33 and ckpt["parity"] < 1e-3 and ckpt["folded_bn"]
    assert StereoConfig.from_dict(ckpt["stereo_config"]) == cfg
    model = TSCAStereo(cfg)
    model.load_state_dict(ckpt["model"])


def _kernel_dims(node) -> int:
    return len(next(a.ints for a in node.attribute if a.name == "kernel_shape"))


@pytest.mark.parametrize("convs", [False, True], ids=["plain", "convs-only"])
def test_checkpoint_from_graph_without_conv_rewrite(tmp_path, convs):
    """Graphs exported before the Conv3d -> Conv2d rewrite (plain), or before the ConvTranspose3d one
    (convs-only: the shipped graphs of sessions 6-12), still recover."""
    torch.manual_seed(0)
    cfg = StereoConfig.cpu()
    model = randomise_batchnorm(TSCAStereo(cfg), 6)
    meta = stereo_metadata(input_size=SIZE, iters=ITERS, stereo_config=cfg.to_dict(), dataset={"seed": 1, "size": 4})
    path = onnx_stereo.export_stereo(model, tmp_path / "plain.onnx", size=SIZE, iters=ITERS, metadata=meta,
                                     rewrite_convs=convs, rewrite_transposed=False, rewrite_narrow=False,
                                     rewrite_winograd=False, rewrite_polyphase=False)
    nodes = onnx.load(str(path)).graph.node
    grouped_2d = any(n.op_type == "Conv" and any(a.name == "group" and a.i > 1 for a in n.attribute)
                     and _kernel_dims(n) == 2 for n in nodes)
    assert grouped_2d == convs
    assert all(_kernel_dims(n) == 3 for n in nodes if n.op_type == "ConvTranspose")
    kernels = [list(next(a.ints for a in n.attribute if a.name == "kernel_shape")) for n in nodes if n.op_type == "Conv"]
    assert [3, 3, 3] in kernels                                   # the classifier as a 3-D conv
    ckpt = checkpoint_from_graph(path)
    assert ckpt["parity"] < 1e-3
    again = TSCAStereo(cfg).eval()
    again.load_state_dict(ckpt["model"])
    left, right = (torch.from_numpy(a) for a in onnx_stereo.parity_inputs(SIZE))
    with torch.no_grad():
        diff = torch.max(torch.abs(again(left, right, iters=ITERS, test_mode=True)
                                   - model(left, right, iters=ITERS, test_mode=True)))
    assert float(diff) < 1e-3


def test_graph_from_older_export_code_pairs_by_node_name(tmp_path, monkeypatch):
    """A graph whose weight-free nodes differ from this code's export (e.g. exported before the lookup
    was rewritten) still recovers: weight-bearing nodes pair by name."""
    import spacepose.models.tsca_stereo as tsca
    from spacepose.models.stereo_lookup import GeometryLookup

    class OlderLookup(GeometryLookup):
        def __call__(self, disp):
            return super().__call__(disp) * torch.ones(1)        # one more (weight-free) node per iteration

    torch.manual_seed(0)
    cfg = StereoConfig.cpu()
    model = randomise_batchnorm(TSCAStereo(cfg), 7)
    with monkeypatch.context() as patch:
        patch.setattr(tsca, "GeometryLookup", OlderLookup)
        path = onnx_stereo.export_stereo(model, tmp_path / "older.onnx", size=SIZE, iters=ITERS, metadata={})
    torch.manual_seed(9)
    again = TSCAStereo(cfg).eval()
    report = recover_state_dict(again, path, _export_stereo, prefix="model.")
    assert report.folded_bn and all(k.startswith("init_mask.") for k in report.missing)
    assert onnx_stereo.parity_check(again, path, size=SIZE, iters=ITERS) < 1e-3


def test_checkpoint_from_pose_graph_keeps_target(tmp_path):
    torch.manual_seed(0)
    model = randomise_batchnorm(PoseNet(TINY_POSE_NET), 4)
    kp = np.random.default_rng(0).uniform(-2, 2, size=(8, 3))
    meta = onnx_pose.pose_metadata(TINY_POSE_NET, keypoints=kp, centre=np.zeros(3), target="tdrs", extra={"training": {"step": 9}})
    path = onnx_pose.export_pose(model, tmp_path / "pose.onnx", metadata=meta)
    ckpt = checkpoint_from_graph(path)
    assert ckpt["kind"] == "pose" and ckpt["target"] == "tdrs" and ckpt["step"] == 9
    assert np.allclose(ckpt["keypoints"], kp)
    assert PoseNetConfig.from_dict(ckpt["net_config"]) == TINY_POSE_NET
    assert dataclasses.asdict(TINY_POSE_NET) == ckpt["net_config"]


def test_checkpoint_from_graph_rejects_foreign_graph(tmp_path):
    from onnx import TensorProto, helper

    graph = helper.make_graph([helper.make_node("Relu", ["x"], ["y"])], "g",
                              [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1])],
                              [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1])])
    path = tmp_path / "foreign.onnx"
    onnx.save(helper.make_model(graph), str(path))
    with pytest.raises(SpaceposeError, match="no 'spacepose' metadata"):
        checkpoint_from_graph(path)


@pytest.mark.parametrize("winograd", [False, True], ids=["session13", "session14"])
def test_checkpoint_from_older_graph_forms(tmp_path, winograd):
    """Graphs with the transposed convolutions as per-tap 2-D ones (no polyphase form), with every 3-D
    convolution in the per-tap 2-D form (session 13) or the dense ones in the Winograd form (session 14),
    still recover, and re-exported in the current form they compute the same disparity."""
    torch.manual_seed(0)
    cfg = StereoConfig.cpu()
    model = randomise_batchnorm(TSCAStereo(cfg), 8)
    meta = stereo_metadata(input_size=SIZE, iters=ITERS, stereo_config=cfg.to_dict(), dataset={"seed": 1, "size": 4})
    path = onnx_stereo.export_stereo(model, tmp_path / "old.onnx", size=SIZE, iters=ITERS, metadata=meta,
                                     rewrite_winograd=winograd, rewrite_polyphase=False)
    nodes = onnx.load(str(path)).graph.node
    assert winograd == any(n.op_type == "MatMul" and "/regularizer/" in n.name for n in nodes)
    assert {_kernel_dims(n) for n in nodes if n.op_type == "ConvTranspose"} == {2}
    ckpt = checkpoint_from_graph(path)
    assert ckpt["parity"] < 1e-3
    again = TSCAStereo(cfg).eval()
    again.load_state_dict(ckpt["model"])
    new = onnx_stereo.export_stereo(again, tmp_path / "new.onnx", size=SIZE, iters=ITERS, metadata=meta)
    assert onnx_stereo.parity_check(model, new, size=SIZE, iters=ITERS) < 1e-3
