"""Gated FFN with SwiGLU (paper eq. 19)."""

from __future__ import annotations

import torch
import torch.nn.functional as F

from spacepose.models.gated_ffn import GatedFFN


def test_matches_formula():
    torch.manual_seed(0)
    m = GatedFFN(6, 10, 4)
    x = torch.randn(2, 5, 6)
    u, v, w = m.gate.weight, m.value.weight, m.out.weight
    h = (x @ u.T) * torch.sigmoid(x @ u.T) * (x @ v.T)
    y = h @ w.T
    ref = (y - y.mean(-1, keepdim=True)) / torch.sqrt(y.var(-1, unbiased=False, keepdim=True) + m.norm.eps)
    torch.testing.assert_close(m(x), ref * m.norm.weight + m.norm.bias, atol=1e-5, rtol=1e-5)


def test_closed_gate_gives_zero():
    m = GatedFFN(6, 10, 4)
    with torch.no_grad():
        m.gate.weight.zero_()  # SiLU(0) = 0 closes every channel
    assert torch.count_nonzero(m(torch.randn(1, 3, 6))) == 0


def test_no_biases_and_shape():
    m = GatedFFN(6, 10, 4)
    assert m.gate.bias is None and m.value.bias is None and m.out.bias is None
    assert m(torch.randn(3, 7, 6)).shape == (3, 7, 4)
    assert torch.allclose(F.silu(torch.tensor(1.0)), torch.sigmoid(torch.tensor(1.0)))
