"""The 2-D form of grouped / strided Conv3d layers computes what nn.Conv3d computes, in torch and in onnxruntime."""

import io
import sys
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
onnx = pytest.importorskip("onnx")
ort = pytest.importorskip("onnxruntime")

from torch import nn  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))  # --import-mode=importlib: find the helpers
from _export_fixtures import randomise_batchnorm  # noqa: E402

from spacepose.export.conv3d_as_2d import (WINOGRAD_AT, WINOGRAD_BT, WINOGRAD_G,  # noqa: E402
                                            Conv3dAs2d, ConvTranspose3dAs2d, NarrowConv3dAs2d,
                                            PolyphaseConvTranspose3dAs2d, WinogradConv3dAs2d,
                                            polyphase_kernel_index, rewrite_conv3d, wants_narrow_rewrite,
                                            wants_polyphase_rewrite, wants_rewrite, wants_transposed_rewrite,
                                            wants_winograd_rewrite, winograd_depth_transforms)

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


def _assert_same_in_torch(conv, rewritten, x):
    """``rewritten`` (a 2-D form of ``conv``) computes what ``conv`` computes on ``x``, shape included."""
    with torch.no_grad():
        want, got = conv(x), rewritten(x)
    assert got.shape == want.shape
    assert float(torch.max(torch.abs(got - want))) < 1e-5


def _assert_same_in_onnxruntime(conv, rewritten, x):
    """``rewritten`` exported to ONNX computes in onnxruntime what ``conv`` computes in torch; returns
    the exported graph (for the callers' checks of its operators)."""
    buf = io.BytesIO()
    torch.onnx.export(rewritten, (x,), buf, opset_version=17, dynamo=False, input_names=["x"])
    (got,) = ort.InferenceSession(buf.getvalue(), providers=["CPUExecutionProvider"]).run(None, {"x": x.numpy()})
    with torch.no_grad():
        want = conv(x).numpy()
    assert got.shape == want.shape and np.max(np.abs(got - want)) < 1e-5
    return onnx.load_from_string(buf.getvalue())


def _kernels(proto, op_type):
    return [list(next(a.ints for a in n.attribute if a.name == "kernel_shape"))
            for n in proto.graph.node if n.op_type == op_type]


@pytest.mark.parametrize("case", CASES, ids=lambda c: f"k{c[2]}s{c[3]}g{c[5]}")
def test_matches_conv3d_in_torch(case):
    *args, shape = case
    conv = _conv(*args)
    _assert_same_in_torch(conv, Conv3dAs2d(conv), torch.randn(shape))


@pytest.mark.parametrize("case", CASES[:3], ids=lambda c: f"k{c[2]}s{c[3]}g{c[5]}")
def test_matches_conv3d_in_onnxruntime(case):
    *args, shape = case
    conv = _conv(*args, seed=1)
    proto = _assert_same_in_onnxruntime(conv, Conv3dAs2d(conv), torch.randn(shape))
    kernels = _kernels(proto, "Conv")
    assert kernels and all(len(k) == 2 for k in kernels)                    # only 2-D convolutions left


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
    randomise_batchnorm(model, 3)
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


TRANSPOSED = [  # (in, out, kernel, stride, padding, output padding, groups, bias, input shape)
    (16, 8, 4, 2, 1, 0, 1, False, (1, 16, 6, 10, 12)),               # the regulariser's decoder upsampler
    (8, 8, 3, 2, 1, 1, 1, True, (2, 8, 5, 7, 6)),                    # odd kernel, output padding, batch 2
    (6, 4, (3, 2, 4), (3, 2, 1), (1, 0, 2), (2, 1, 0), 2, True, (1, 6, 4, 5, 7)),  # anisotropic, 2 groups
    (4, 4, 2, 2, 0, 0, 4, True, (1, 4, 3, 4, 4)),                    # depthwise, kernel = stride
    (4, 6, 3, 1, 1, 0, 1, True, (1, 4, 5, 5, 5)),                    # stride 1
    (4, 4, 5, 2, 0, 0, 1, False, (1, 4, 3, 3, 3)),                   # kernel > 2 strides, no padding
]


def _transposed(c_in, c_out, k, s, p, op, g, bias, seed=0):
    torch.manual_seed(seed)
    return nn.ConvTranspose3d(c_in, c_out, k, s, p, op, groups=g, bias=bias).eval()


@pytest.mark.parametrize("case", TRANSPOSED, ids=lambda c: f"k{c[2]}s{c[3]}p{c[4]}g{c[6]}")
def test_matches_conv_transpose3d_in_torch(case):
    *args, shape = case
    conv = _transposed(*args)
    _assert_same_in_torch(conv, ConvTranspose3dAs2d(conv), torch.randn(shape))


@pytest.mark.parametrize("case", TRANSPOSED[:3], ids=lambda c: f"k{c[2]}s{c[3]}p{c[4]}g{c[6]}")
def test_matches_conv_transpose3d_in_onnxruntime(case):
    *args, shape = case
    conv = _transposed(*args, seed=2)
    proto = _assert_same_in_onnxruntime(conv, ConvTranspose3dAs2d(conv), torch.randn(shape))
    kernels = _kernels(proto, "ConvTranspose")
    assert kernels and all(len(k) == 2 for k in kernels)                    # only 2-D ones left


def test_transposed_rewrite_is_opt_in_and_folds_batchnorm():
    torch.manual_seed(4)
    model = nn.Sequential(nn.ConvTranspose3d(8, 6, 4, 2, 1, groups=2, bias=False), nn.BatchNorm3d(6),
                          nn.LeakyReLU(0.2), nn.Conv3d(6, 8, 3, 1, 1)).eval()
    randomise_batchnorm(model, 4)
    kinds = lambda m: [type(c) for c in m]  # noqa: E731
    assert kinds(rewrite_conv3d(model)) == [nn.ConvTranspose3d, nn.BatchNorm3d, nn.LeakyReLU, Conv3dAs2d]
    assert kinds(rewrite_conv3d(model, convs=False, transposed=True)) == [ConvTranspose3dAs2d, nn.Identity,
                                                                          nn.LeakyReLU, nn.Conv3d]
    both = rewrite_conv3d(model, transposed=True)
    assert kinds(both) == [ConvTranspose3dAs2d, nn.Identity, nn.LeakyReLU, Conv3dAs2d]
    assert type(model[0]) is nn.ConvTranspose3d and type(model[1]) is nn.BatchNorm3d   # original untouched
    x = torch.randn(1, 8, 4, 6, 5)
    with torch.no_grad():
        assert float(torch.max(torch.abs(both(x) - model(x)))) < 1e-5
    assert wants_transposed_rewrite(model[0]) and not wants_transposed_rewrite(nn.ConvTranspose2d(4, 4, 2))


def test_transposed_rejects_what_it_cannot_express():
    with pytest.raises(ValueError, match="dilation"):
        ConvTranspose3dAs2d(nn.ConvTranspose3d(2, 2, 3, dilation=2))
    assert not wants_transposed_rewrite(nn.ConvTranspose3d(2, 2, 3, dilation=2))


NARROW = [  # (in, out, kernel, stride, padding, bias, input shape)
    (16, 1, 3, 1, 1, True, (1, 16, 6, 8, 8)),                          # the disparity classifier
    (8, 3, (3, 1, 3), (2, 1, 2), (1, 0, 1), False, (2, 8, 7, 6, 9)),   # strided, anisotropic, batch 2
    (4, 2, 5, 1, 0, True, (1, 4, 7, 5, 5)),                            # no padding
]


@pytest.mark.parametrize("case", NARROW, ids=lambda c: f"o{c[1]}k{c[2]}s{c[3]}")
def test_narrow_matches_conv3d_in_torch_and_onnxruntime(case):
    c_in, c_out, k, s, p, bias, shape = case
    torch.manual_seed(5)
    conv = nn.Conv3d(c_in, c_out, k, s, p, bias=bias).eval()
    x = torch.randn(shape)
    _assert_same_in_torch(conv, NarrowConv3dAs2d(conv), x)
    kernels = _kernels(_assert_same_in_onnxruntime(conv, NarrowConv3dAs2d(conv), x), "Conv")
    assert len(kernels) == 1 and len(kernels[0]) == 2                      # one 2-D convolution


def test_narrow_rewrite_is_opt_in():
    model = nn.Sequential(nn.Conv3d(8, 8, 3, 1, 1), nn.Conv3d(8, 1, 3, 1, 1), nn.Conv3d(8, 1, 1),
                          nn.Conv3d(2, 2, 3, groups=2)).eval()
    assert [type(m) for m in rewrite_conv3d(model)] == [Conv3dAs2d, nn.Conv3d, nn.Conv3d, nn.Conv3d]
    assert [type(m) for m in rewrite_conv3d(model, narrow=True)] == [Conv3dAs2d, NarrowConv3dAs2d, nn.Conv3d,
                                                                     nn.Conv3d]     # not 1x1x1, not grouped
    assert wants_narrow_rewrite(model[1]) and not wants_narrow_rewrite(model[0]) and not wants_narrow_rewrite(model[3])
    with pytest.raises(ValueError, match="ungrouped"):
        NarrowConv3dAs2d(nn.Conv3d(2, 2, 3, groups=2))


def test_winograd_matrices_compute_a_three_tap_correlation():
    rng = np.random.default_rng(0)
    for _ in range(5):
        g, d = rng.normal(size=3), rng.normal(size=6)
        want = [sum(g[k] * d[i + k] for k in range(3)) for i in range(4)]
        np.testing.assert_allclose(WINOGRAD_AT @ ((WINOGRAD_G @ g) * (WINOGRAD_BT @ d)), want, atol=1e-12)


@pytest.mark.parametrize("depth,pad", [(24, 1), (12, 1), (6, 1), (7, 1), (5, 0), (3, 2), (1, 1)])
def test_winograd_depth_transforms_compute_the_padded_correlation(depth, pad):
    """T_out ((G g) * (T_in x)) per tile is the zero-padded 3-tap correlation along depth, any length."""
    t_in, t_out = winograd_depth_transforms(depth, pad)
    n = t_in.shape[0] // 6
    rng = np.random.default_rng(depth)
    g, x = rng.normal(size=3), rng.normal(size=depth)
    xp = np.concatenate([np.zeros(pad), x, np.zeros(pad)])
    want = [sum(g[k] * xp[i + k] for k in range(3)) for i in range(depth + 2 * pad - 2)]
    got = t_out @ (np.tile(WINOGRAD_G @ g, n) * (t_in @ x))
    np.testing.assert_allclose(got, want, atol=1e-5)
    assert not t_in.flags.writeable                                        # a cached constant


WINOGRAD = [  # (in, out, kernel, stride, padding, bias, groups, input shape)
    (16, 16, 3, 1, 1, False, 1, (1, 16, 24, 12, 12)),    # the regulariser's stem (depth 24: whole tiles)
    (8, 12, 3, 1, 1, True, 1, (2, 8, 7, 6, 9)),          # batch 2, depth 7: a partial last tile
    (8, 8, (3, 3, 1), (1, 2, 1), (0, 1, 0), True, 1, (1, 8, 9, 8, 5)),  # no depth padding, spatial stride
    (4, 8, 3, 1, 2, False, 1, (1, 4, 3, 5, 5)),          # depth padding 2, fewer slices than a tile
    (8, 4, 3, 1, 1, True, 2, (1, 8, 6, 5, 5)),           # 2 groups
]


@pytest.mark.parametrize("case", WINOGRAD, ids=lambda c: f"d{c[-1][2]}p{c[4]}g{c[-2]}")
def test_winograd_matches_conv3d_in_torch_and_onnxruntime(case):
    c_in, c_out, k, s, p, bias, groups, shape = case
    torch.manual_seed(7)
    conv = nn.Conv3d(c_in, c_out, k, s, p, groups=groups, bias=bias).eval()
    x = torch.randn(shape)
    _assert_same_in_torch(conv, WinogradConv3dAs2d(conv), x)
    proto = _assert_same_in_onnxruntime(conv, WinogradConv3dAs2d(conv), x)
    convs = [n for n in proto.graph.node if n.op_type == "Conv"]
    assert len(convs) == 1 and _kernels(proto, "Conv") == [list(conv.kernel_size[1:])]   # one 2-D convolution
    assert next(a.i for a in convs[0].attribute if a.name == "group") == 6 * groups  # a group per Winograd point
    assert sum(n.op_type == "MatMul" for n in proto.graph.node) == 2
    assert convs[0].input[1] in {i.name for i in proto.graph.initializer}          # kernels folded into one initializer


def test_winograd_rewrite_is_opt_in_takes_the_dense_layers_and_folds_batchnorm():
    torch.manual_seed(4)
    model = nn.Sequential(nn.Conv3d(8, 8, 3, 1, 1, bias=False), nn.BatchNorm3d(8), nn.LeakyReLU(0.2),
                          nn.Conv3d(8, 8, 3, 1, 1, groups=8),     # depthwise: per-tap form
                          nn.Conv3d(8, 8, 3, 2, 1),               # depth stride 2: per-tap form
                          nn.Conv3d(8, 8, 5, 1, 2),               # 5 depth taps: per-tap form
                          nn.Conv3d(8, 1, 3, 1, 1)).eval()        # narrow: kept
    randomise_batchnorm(model, 4)
    assert type(rewrite_conv3d(model)[0]) is Conv3dAs2d
    out = rewrite_conv3d(model, winograd=True)
    assert [type(m) for m in out] == [WinogradConv3dAs2d, nn.Identity, nn.LeakyReLU, Conv3dAs2d, Conv3dAs2d,
                                      Conv3dAs2d, nn.Conv3d]
    assert [wants_winograd_rewrite(m) for m in model] == [True, False, False, False, False, False, False]
    assert list(out.state_dict()) == list(rewrite_conv3d(model).state_dict())   # no keys of its own
    x = torch.randn(1, 8, 10, 8, 8)
    with torch.no_grad():
        assert float(torch.max(torch.abs(out(x) - model(x)))) < 1e-4
    with pytest.raises(ValueError, match="depth stride 1"):
        WinogradConv3dAs2d(nn.Conv3d(2, 2, 3, 2, 1))
    with pytest.raises(ValueError, match="3 depth taps"):
        WinogradConv3dAs2d(nn.Conv3d(2, 2, (5, 3, 3), 1, 1))


POLYPHASE = [  # (in, out, kernel, stride, padding, output padding, bias, input shape): kernel a multiple of stride
    (16, 16, 4, 2, 1, 0, False, (1, 16, 6, 10, 12)),                 # the regulariser's decoder upsampler
    (3, 5, 4, 2, 1, 0, True, (2, 3, 3, 5, 4)),                       # batch 2, odd sizes
    (3, 5, 2, 2, 0, 0, True, (1, 3, 3, 4, 5)),                       # kernel = stride: no overlap
    (3, 4, 6, 3, 2, 0, True, (1, 3, 3, 4, 4)),                       # stride 3
    (3, 4, (4, 2, 6), (2, 1, 3), (1, 0, 2), 0, True, (1, 3, 4, 5, 3)),  # anisotropic, no spatial stride in H
    (2, 3, 4, 2, 0, 1, True, (1, 2, 3, 4, 4)),                       # output padding
    (2, 3, 6, 2, (0, 1, 0), (1, 0, 1), True, (1, 2, 3, 3, 3)),       # output padding per axis
    (2, 3, 4, 2, 3, 0, True, (1, 2, 4, 4, 5)),                       # padding beyond one stride
    (2, 3, 3, 1, 1, 0, True, (1, 2, 4, 4, 5)),                       # stride 1: a plain convolution
    (2, 2, 4, 4, 0, 0, True, (1, 2, 2, 3, 3)),                       # kernel = stride = 4
]


@pytest.mark.parametrize("case", POLYPHASE, ids=lambda c: f"k{c[2]}s{c[3]}p{c[4]}op{c[5]}")
def test_polyphase_matches_conv_transpose3d_in_torch_and_onnxruntime(case):
    *args, bias, shape = case
    conv = _transposed(*args, 1, bias, seed=7)
    x = torch.randn(shape)
    _assert_same_in_torch(conv, PolyphaseConvTranspose3dAs2d(conv), x)
    proto = _assert_same_in_onnxruntime(conv, PolyphaseConvTranspose3dAs2d(conv), x)
    assert len(_kernels(proto, "Conv")) == 1                                 # one 2-D convolution
    assert all(len(k) == 2 for k in _kernels(proto, "ConvTranspose"))       # the pixel shuffle, if any
    initializers = {i.name for i in proto.graph.initializer}
    conv_node = next(n for n in proto.graph.node if n.op_type == "Conv")
    assert conv_node.input[1] in initializers                              # the kernel folded into one initializer
    assert not any(n.op_type in ("Gather", "GatherElements") for n in proto.graph.node)


def test_polyphase_kernel_is_a_permutation_of_the_weight():
    """The kernel the module builds is ``weight.flat[polyphase_kernel_index]``, and the index holds every
    weight value exactly once (how recovery reads the weight back)."""
    for k, s in [(4, 2), ((4, 2, 6), (2, 1, 3)), (6, 3), (2, 2), (3, 1)]:
        conv = nn.ConvTranspose3d(3, 5, k, s)
        index = polyphase_kernel_index(tuple(conv.weight.shape), conv.stride)
        assert np.array_equal(np.sort(index.reshape(-1)), np.arange(conv.weight.numel()))
        kernel = PolyphaseConvTranspose3dAs2d(conv)._kernel2d()
        assert torch.equal(kernel, conv.weight.detach().reshape(-1)[torch.from_numpy(index)])
    with pytest.raises(ValueError, match="multiple of stride"):
        polyphase_kernel_index((3, 5, 4, 4, 4), (3, 2, 2))


def test_polyphase_rewrite_takes_ungrouped_transposed_layers_and_folds_batchnorm():
    torch.manual_seed(4)
    model = nn.Sequential(nn.ConvTranspose3d(8, 6, 4, 2, 1, bias=False), nn.BatchNorm3d(6), nn.LeakyReLU(0.2),
                          nn.ConvTranspose3d(6, 6, 4, 2, 1, groups=2),   # grouped: per-tap form
                          nn.ConvTranspose3d(6, 6, 3, 2, 1)).eval()      # kernel not a multiple: per-tap form
    randomise_batchnorm(model, 4)
    assert [type(m) for m in rewrite_conv3d(model, transposed=True)][0] is ConvTranspose3dAs2d
    out = rewrite_conv3d(model, transposed=True, polyphase=True)
    assert [type(m) for m in out] == [PolyphaseConvTranspose3dAs2d, nn.Identity, nn.LeakyReLU, ConvTranspose3dAs2d,
                                      ConvTranspose3dAs2d]
    assert [type(m) for m in rewrite_conv3d(model, polyphase=True)][3:] == [nn.ConvTranspose3d, nn.ConvTranspose3d]
    assert [wants_polyphase_rewrite(m) for m in model] == [True, False, False, False, False]
    assert list(out.state_dict()) == list(rewrite_conv3d(model, transposed=True).state_dict())  # no keys of its own
    x = torch.randn(1, 8, 3, 4, 5)
    with torch.no_grad():
        assert float(torch.max(torch.abs(out(x) - model(x)))) < 1e-4
    with pytest.raises(ValueError, match="ungrouped"):
        PolyphaseConvTranspose3dAs2d(nn.ConvTranspose3d(2, 2, 4, 2, groups=2))
    with pytest.raises(ValueError, match="multiple of the stride"):
        PolyphaseConvTranspose3dAs2d(nn.ConvTranspose3d(2, 2, 3, 2))
    with pytest.raises(ValueError, match="dilation"):
        PolyphaseConvTranspose3dAs2d(nn.ConvTranspose3d(2, 2, 4, 2, dilation=2))
