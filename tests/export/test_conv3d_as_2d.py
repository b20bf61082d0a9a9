"""The 2-D form of grouped / strided Conv3d layers computes what nn.Conv3d computes, in torch and in onnxruntime."""

import io

import numpy as np
import pytest

torch = pytest.importorskip("torch")
onnx = pytest.importorskip("onnx")
ort = pytest.importorskip("onnxruntime")

from torch import nn  # noqa: E402

from spacepose.export.conv3d_as_2d import Conv3dAs2d, rewrite_conv3d, wants_rewrite  # noqa: E402

CASES = [  # (in, out, kernel, stride, padding, groups, bias, input shape)
    (8, 8, 5, 1, 2, 8, True, (1, 8, 6, 9, 10)),        # SECA key: depthwise 5x5x5
    (8, 8, 3, 1, 1, 8, True, (2, 8, 5, 7, 6)),         # SECA query, batch 2
    (8, 8, 3, 2, 1, 8, False, (1, 8, 8, 12, 10)),      # strided depthwise (dwsep encoder)
    (6, 4, 3, 2, 1, 1, False, (1, 6, 7, 9, 9)),        # dense strided, odd sizes
    (4, 6, (3, 1, 3), (2, 1, 1), (1, 0, 1), 2, True, (1, 4, 6, 5, 7)),  # anisotropic, 2 groups
    (4, 4, 3, 1, 0, 4, True, (1, 4, 5, 6, 6)),         # no padding
]


def _conv(c_in, c_out, k, s, p, g, bias, seed=0):
    torch.manual_seed(seed)
    return nn.Conv3d(c_in, c_out, k, s, p, groups=g, bias=bias).eval()


@pytest.mark.parametrize("case", CASES, ids=lambda c: f"k{c[2]}s{c[3]}g{c[5]}")
def test_matches_conv3d_in_torch(case):
    *args, shape = case
    conv = _conv(*args)
    x = torch.randn(shape)
    with torch.no_grad():
        want, got = conv(x), Conv3dAs2d(conv)(x)
    assert got.shape == want.shape
    assert float(torch.max(torch.abs(got - want))) < 1e-5


@pytest.mark.parametrize("case", CASES[:3], ids=lambda c: f"k{c[2]}s{c[3]}g{c[5]}")
def test_matches_conv3d_in_onnxruntime(case):
    *args, shape = case
    conv = _conv(*args, seed=1)
    x = torch.randn(shape)
    buf = io.BytesIO()
    torch.onnx.export(Conv3dAs2d(conv), (x,), buf, opset_version=17, dynamo=False, input_names=["x"])
    proto = onnx.load_from_string(buf.getvalue())
    assert {n.op_type for n in proto.graph.node} >= {"Conv"}
    assert all(len(next(a.ints for a in n.attribute if a.name == "kernel_shape")) == 2
               for n in proto.graph.node if n.op_type == "Conv")          # only 2-D convolutions left
    (got,) = ort.InferenceSession(buf.getvalue(), providers=["CPUExecutionProvider"]).run(None, {"x": x.numpy()})
    with torch.no_grad():
        want = conv(x).numpy()
    assert np.max(np.abs(got - want)) < 1e-5


def test_rewrite_replaces_only_the_layers_it_speeds_up():
    model = nn.Sequential(
        nn.Conv3d(8, 8, 3, 1, 1, groups=8),      # depthwise -> rewritten
        nn.Conv3d(8, 8, 1),                      # pointwise -> kept
        nn.Conv3d(8, 8, 3, 1, 1),                # dense -> rewritten
        nn.Sequential(nn.Conv3d(8, 8, 3, 2, 1)),  # nested, strided -> rewritten
        nn.Conv3d(8, 8, 3, 1, 2, dilation=2, groups=8),  # dilated -> kept
        nn.Conv3d(8, 1, 3, 1, 1),                # one output channel (the classifier) -> kept
    ).eval()
    out = rewrite_conv3d(model)
    kinds = [type(m) for m in (out[0], out[1], out[2], out[3][0], out[4], out[5])]
    assert kinds == [Conv3dAs2d, nn.Conv3d, Conv3dAs2d, Conv3dAs2d, nn.Conv3d, nn.Conv3d]
    assert all(type(m) is nn.Conv3d for m in [model[0], model[2], model[3][0]])   # the original is untouched
    assert list(out.state_dict()) == list(model.state_dict())               # same keys and shapes
    assert all(out.state_dict()[k].shape == v.shape for k, v in model.state_dict().items())
    x = torch.randn(1, 8, 8, 8, 8)
    with torch.no_grad():
        assert float(torch.max(torch.abs(out(x) - model(x)))) < 1e-5
    assert wants_rewrite(nn.Conv3d(8, 8, 3, groups=2)) and not wants_rewrite(nn.Conv2d(8, 8, 3, groups=2))


def test_batchnorm_after_a_rewritten_layer_is_folded():
    torch.manual_seed(3)
    model = nn.Sequential(nn.Conv3d(8, 8, 3, 2, 1, groups=8, bias=False), nn.BatchNorm3d(8), nn.LeakyReLU(0.2),
                          nn.Conv3d(8, 8, 1), nn.BatchNorm3d(8)).eval()
    with torch.no_grad():
        for bn in (model[1], model[4]):
            bn.weight.uniform_(0.5, 1.5)
            bn.bias.normal_()
            bn.running_mean.normal_()
            bn.running_var.uniform_(0.5, 2.0)
    out = rewrite_conv3d(model)
    assert isinstance(out[0], Conv3dAs2d) and isinstance(out[1], nn.Identity)
    assert isinstance(out[4], nn.BatchNorm3d)                                # after a kept 1x1x1 conv: untouched
    x = torch.randn(1, 8, 6, 8, 8)
    with torch.no_grad():
        assert float(torch.max(torch.abs(out(x) - model(x)))) < 1e-5


def test_rejects_what_it_cannot_express():
    with pytest.raises(ValueError, match="dilation"):
        Conv3dAs2d(nn.Conv3d(2, 2, 3, dilation=2))
    with pytest.raises(ValueError, match="zero padding"):
        Conv3dAs2d(nn.Conv3d(2, 2, 3, padding=1, padding_mode="replicate"))
