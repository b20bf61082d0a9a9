"""Efficient Cross-modal Additive Attention (ECAA), paper eqs. 15-18 (SwiftFormer-style).

Linear in the number of tokens: the only token-token interaction is a weighted sum that pools
the queries into ONE global query vector, so no n x n matrix is ever formed.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["ECAA"]


class ECAA(nn.Module):
    """Cross-modal additive attention.

    ``forward(x_query (B, n, c_query), x_key (B, n, c_key)) -> (B, n, dim)``; the two token sets are
    aligned (token i of ``x_key`` is the other modality's feature at token i of ``x_query``).

    Q = x_query W_Q, K = x_key W_K (eq. 15), both L2-normalised per token (Q̂, K̂);
    g = Q̂ l_g / sqrt(d) (eq. 16), then L2-normalised over the tokens (SwiftFormer's released code);
    q = sum_i g_i Q̂_i (eq. 17); x̂ = Q̂ + T(K̂ * q) (eq. 18); returns the linear projection P(x̂)
    (the T(x̂) that eq. 19 concatenates).
    """

    def __init__(self, c_query: int, c_key: int, dim: int) -> None:
        super().__init__()
        self.to_query = nn.Linear(c_query, dim)
        self.to_key = nn.Linear(c_key, dim)
        self.w_g = nn.Parameter(torch.randn(dim))
        self.transform = nn.Linear(dim, dim)
        self.proj = nn.Linear(dim, dim)
        self.scale = dim ** -0.5

    def forward(self, x_query: torch.Tensor, x_key: torch.Tensor) -> torch.Tensor:
        q = F.normalize(self.to_query(x_query), dim=-1)
        k = F.normalize(self.to_key(x_key), dim=-1)
        g = torch.matmul(q, self.w_g) * self.scale          # (B, n)
        g = F.normalize(g, dim=1)                           # over tokens
        q_global = torch.sum(g.unsqueeze(-1) * q, dim=1, keepdim=True)  # (B, 1, d)
        return self.proj(q + self.transform(k * q_global))
