import numpy as np
import torch

from spacepose.models.triplet_attention import TripletAttention, z_pool


def _conv2d_same(x, w, b):
    """x (2, H, W), w (1, 2, k, k), b (1,) -> (H, W), zero padding, naive loops."""
    k = w.shape[-1]
    p = k // 2
    xp = np.pad(x, ((0, 0), (p, p), (p, p)))
    out = np.zeros(x.shape[1:])
    for i in range(x.shape[1]):
        for j in range(x.shape[2]):
            out[i, j] = (xp[:, i : i + k, j : j + k] * w[0]).sum() + b[0]
    return out


def _gate(x, conv):
    """x (C', A, B) numpy: pool over axis 0 and gate the (A, B) plane."""
    pooled = np.stack([x.max(axis=0), x.mean(axis=0)])
    logits = _conv2d_same(pooled, conv.weight.detach().numpy(), conv.bias.detach().numpy())
    return x * (1.0 / (1.0 + np.exp(-logits)))[None]


def test_matches_hand_computation():
    torch.manual_seed(0)
    ta = TripletAttention(kernel_size=3).eval()
    x = torch.randn(1, 3, 4, 5)
    got = ta(x).detach().numpy()[0]
    xn = x.numpy()[0].astype(np.float64)  # (C, H, W)
    y1 = _gate(xn.transpose(1, 0, 2), ta.gate_cw.conv).transpose(1, 0, 2)  # pool over H
    y2 = _gate(xn.transpose(2, 1, 0), ta.gate_hc.conv).transpose(2, 1, 0)  # pool over W
    y3 = _gate(xn, ta.gate_hw.conv)  # pool over C
    np.testing.assert_allclose(got, (y1 + y2 + y3) / 3.0, atol=1e-5)


def test_shapes_and_zpool():
    x = torch.randn(2, 8, 6, 10)
    assert TripletAttention()(x).shape == x.shape
    zp = z_pool(x)
    assert zp.shape == (2, 2, 6, 10)
    torch.testing.assert_close(zp[:, 0], x.max(dim=1).values)
