"""PoseNet: shapes, variants, the offset sign convention, batching, and ONNX export parity."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import torch

from spacepose.models.pose_config import PoseNetConfig
from spacepose.models.pose_loss import centre_offset_targets, keypoint_offset_targets
from spacepose.models.pose_net import PoseNet, count_parameters, keypoint_votes
from spacepose.pose_inputs import build_pose_inputs

TINY = dict(crop_size=(64, 64), n_points=256, k=8, n_levels=2, rgb_stem=8, rgb_widths=(16, 32), rgb_bottleneck=32,
            rgb_out=16, point_stem=8, point_widths=(16, 32), point_bottleneck=32, head_width=32, n_keypoints=4)


@pytest.fixture(autouse=True)
def one_thread():
    """Small graphs run faster on one thread, and the test machine is shared."""
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(previous)


def _sample(cfg: PoseNetConfig, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    w, h = cfg.crop_size
    rgb = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    pixels = np.column_stack([rng.integers(0, w, cfg.n_points), rng.integers(0, h, cfg.n_points)])
    xyz = rng.normal(size=(cfg.n_points, 3)) + np.array([0.0, 0.0, 20.0])
    inputs, _ = build_pose_inputs(rgb, xyz, pixels, cfg.input_spec())
    return inputs


@pytest.mark.parametrize("fusion", ["both", "rgb2pt", "pt2rgb", "none"])
@pytest.mark.parametrize("attention", ["ecaa", "vanilla"])
def test_output_shapes(fusion, attention):
    cfg = PoseNetConfig(**TINY, fusion=fusion, attention=attention)
    torch.manual_seed(0)
    net = PoseNet(cfg).eval()
    with torch.no_grad():
        out = net.forward_dict(_sample(cfg))
    assert out["seg_logits"].shape == (1, 256, 2)
    assert out["kp_offsets"].shape == (1, 4, 256, 3)
    assert out["ctr_offsets"].shape == (1, 256, 3)
    assert all(torch.isfinite(v).all() for v in out.values())


def test_fusion_none_has_no_ecft_and_fewer_parameters():
    both = PoseNet(PoseNetConfig(**TINY))
    none = PoseNet(PoseNetConfig(**TINY, fusion="none"))
    assert none.fuse_encoder is None and none.fuse_decoder is None
    assert count_parameters(none) < count_parameters(both)


def test_offset_sign_convention():
    """offset = keypoint - point, vote = point + offset."""
    points = torch.tensor([[[0.0, 0.0, 10.0], [1.0, 2.0, 12.0]]])
    keypoints = torch.tensor([[[1.0, 0.0, 10.0]]])
    offsets = keypoint_offset_targets(points, keypoints)
    torch.testing.assert_close(offsets[0, 0, 0], torch.tensor([1.0, 0.0, 0.0]))  # points TO the keypoint
    torch.testing.assert_close(keypoint_votes(points, offsets), keypoints.unsqueeze(2).expand(1, 1, 2, 3))
    centre = torch.tensor([[0.5, 1.0, 11.0]])
    torch.testing.assert_close(keypoint_votes(points, centre_offset_targets(points, centre)), centre.unsqueeze(1).expand(1, 2, 3))


def test_batch_elements_are_independent():
    cfg = PoseNetConfig(**TINY)
    torch.manual_seed(0)
    net = PoseNet(cfg).eval()
    a, b = _sample(cfg, 0), _sample(cfg, 1)
    batch = {k: np.concatenate([a[k], b[k]]) for k in a}
    with torch.no_grad():
        out_ab, out_b = net.forward_dict(batch), net.forward_dict(b)
    for key in out_b:
        torch.testing.assert_close(out_ab[key][1:], out_b[key], atol=1e-5, rtol=1e-5)


def test_bad_inputs():
    net = PoseNet(PoseNetConfig(**TINY))
    inputs = _sample(net.cfg)
    with pytest.raises(KeyError, match="pix2pt_1"):
        net.forward_dict({k: v for k, v in inputs.items() if k != "pix2pt_1"})
    with pytest.raises(ValueError, match="index tensors"):
        net(*[torch.as_tensor(inputs[n]) for n in net.input_names[:-1]])


def test_configs():
    cpu, paper = PoseNetConfig.cpu(), PoseNetConfig.paper()
    assert (cpu.n_points, cpu.k, cpu.n_levels, cpu.crop_size, cpu.n_keypoints) == (1024, 16, 3, (128, 128), 8)
    assert paper.n_points == 12800 and paper.point_channels == 9 and paper.input_spec().level_sizes[-1] == 50
    assert PoseNetConfig.from_dict(json.loads(json.dumps(dataclasses.asdict(paper)))) == paper
    with pytest.raises(ValueError, match="fusion"):
        PoseNetConfig(fusion="rgb2rgb")
    with pytest.raises(ValueError, match="attention"):
        PoseNetConfig(attention="softmax")
    with pytest.raises(ValueError, match="per level"):
        PoseNetConfig(rgb_widths=(32, 64))


@pytest.mark.slow
def test_onnx_export_matches_torch(tmp_path):
    ort = pytest.importorskip("onnxruntime")
    cfg = PoseNetConfig.cpu()
    torch.manual_seed(0)
    net = PoseNet(cfg).eval()
    inputs = _sample(cfg)
    args = tuple(torch.as_tensor(inputs[n]) for n in net.input_names)
    path = tmp_path / "pose.onnx"
    with torch.no_grad():
        expected = net(*args)
        torch.onnx.export(net, args, str(path), input_names=net.input_names, output_names=list(net.output_names),
                          opset_version=17, dynamo=False)
    assert [p.name for p in tmp_path.iterdir()] == ["pose.onnx"]
    import onnx
    ops = {node.op_type for node in onnx.load(str(path)).graph.node}
    assert not ops & {"ScatterND", "ScatterElements", "Scatter", "Loop", "If", "TopK"}
    options = ort.SessionOptions()
    options.intra_op_num_threads = 2
    session = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
    got = session.run(list(net.output_names), inputs)
    for g, e in zip(got, expected):
        np.testing.assert_allclose(g, e.numpy(), atol=1e-4, rtol=0)


@pytest.mark.parametrize("fusion, attention, reads_pix2pt",
                         [("both", "ecaa", True), ("pt2rgb", "ecaa", True), ("rgb2pt", "ecaa", False),
                          ("both", "vanilla", False), ("none", "ecaa", False)])
def test_used_input_names(fusion, attention, reads_pix2pt):
    """Only pix2pt_* can go unused; the traced graph's inputs are exactly used_input_names."""
    net = PoseNet(PoseNetConfig(**TINY, fusion=fusion, attention=attention)).eval()
    assert any(n.startswith("pix2pt_") for n in net.used_input_names) == reads_pix2pt
    inputs = _sample(net.cfg)
    args = tuple(torch.as_tensor(inputs[n]) for n in net.input_names)
    with torch.no_grad():
        graph = torch.jit.trace(net, args).graph
    used = [name for name, value in zip(net.input_names, list(graph.inputs())[1:]) if value.uses()]
    assert used == net.used_input_names
