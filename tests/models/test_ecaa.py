"""ECAA (paper eqs. 15-18): hand computation and linear cost in the number of tokens."""

from __future__ import annotations

import math

import pytest
import torch
from torch.utils.flop_counter import FlopCounterMode

from spacepose.models.ecaa import ECAA
from spacepose.models.vanilla_attention import VanillaCrossAttention


def _identity_ecaa() -> ECAA:
    m = ECAA(2, 2, 2)
    with torch.no_grad():
        for lin in (m.to_query, m.to_key, m.transform, m.proj):
            lin.weight.copy_(torch.eye(2))
            lin.bias.zero_()
        m.w_g.copy_(torch.tensor([1.0, 0.0]))
    return m


def test_matches_hand_computation():
    x_q = torch.tensor([[[3.0, 4.0], [1.0, 0.0], [0.0, 2.0]]])
    x_k = torch.tensor([[[0.0, 1.0], [1.0, 1.0], [2.0, 0.0]]])
    q_hat = [[0.6, 0.8], [1.0, 0.0], [0.0, 1.0]]                 # rows L2-normalised
    k_hat = [[0.0, 1.0], [0.5 ** 0.5, 0.5 ** 0.5], [1.0, 0.0]]
    g = [row[0] / math.sqrt(2) for row in q_hat]                  # Q̂ . l_g / sqrt(d), l_g = (1, 0)
    norm = math.sqrt(sum(v * v for v in g))
    g = [v / norm for v in g]                                     # L2 over tokens
    q = [sum(g[i] * q_hat[i][c] for i in range(3)) for c in range(2)]
    expected = [[q_hat[i][c] + k_hat[i][c] * q[c] for c in range(2)] for i in range(3)]
    out = _identity_ecaa()(x_q, x_k)
    torch.testing.assert_close(out, torch.tensor([expected]), atol=1e-6, rtol=0)
    torch.testing.assert_close(out[0, 0], torch.tensor([0.6, 0.8 + 0.4116]), atol=1e-4, rtol=0)


def _flops(module: torch.nn.Module, n: int) -> int:
    x = torch.randn(1, n, 32)
    with FlopCounterMode(display=False) as counter, torch.no_grad():
        module(x, x)
    return counter.get_total_flops()


def test_flops_linear_in_tokens():
    ecaa = ECAA(32, 32, 32)
    f1, f4 = _flops(ecaa, 256), _flops(ecaa, 1024)
    assert f1 > 0
    assert f4 == pytest.approx(4 * f1, rel=1e-6)


def test_vanilla_flops_quadratic_in_tokens():
    vanilla = VanillaCrossAttention(32, 32, 32, heads=4)
    assert _flops(vanilla, 1024) > 10 * _flops(vanilla, 256)


def test_shapes_and_token_equivariance():
    torch.manual_seed(0)
    m = ECAA(8, 12, 16).eval()
    x_q, x_k = torch.randn(2, 20, 8), torch.randn(2, 20, 12)
    out = m(x_q, x_k)
    assert out.shape == (2, 20, 16)
    perm = torch.randperm(20)
    torch.testing.assert_close(m(x_q[:, perm], x_k[:, perm]), out[:, perm], atol=1e-5, rtol=1e-5)
