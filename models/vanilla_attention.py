"""Dot-product cross-attention, the quadratic baseline of paper Table 6."""

from __future__ import annotations

import torch
from torch import nn

__all__ = ["VanillaCrossAttention"]


class VanillaCrossAttention(nn.Module):
    """Multi-head ``softmax(Q K^T / sqrt(d_h)) V``: queries from one modality, keys/values from the other.

    ``forward(x_query (B, n_q, c_query), x_kv (B, n_kv, c_kv)) -> (B, n_q, dim)``; the token sets need
    not be aligned. Cost and memory grow with n_q * n_kv.
    """

    def __init__(self, c_query: int, c_kv: int, dim: int, heads: int = 4) -> None:
        super().__init__()
        if dim % heads:
            raise ValueError(f"dim={dim} not divisible by heads={heads}")
        self.heads = heads
        self.to_query = nn.Linear(c_query, dim)
        self.to_key = nn.Linear(c_kv, dim)
        self.to_value = nn.Linear(c_kv, dim)
        self.proj = nn.Linear(dim, dim)
        self.scale = (dim // heads) ** -0.5

    def _split(self, x: torch.Tensor) -> torch.Tensor:
        b, n, d = x.shape
        return x.reshape(b, n, self.heads, d // self.heads).transpose(1, 2)

    def forward(self, x_query: torch.Tensor, x_kv: torch.Tensor) -> torch.Tensor:
        q = self._split(self.to_query(x_query))
        k = self._split(self.to_key(x_kv))
        v = self._split(self.to_value(x_kv))
        attn = torch.softmax(torch.matmul(q, k.transpose(-1, -2)) * self.scale, dim=-1)
        out = torch.matmul(attn, v).transpose(1, 2)
        return self.proj(out.reshape(out.shape[0], out.shape[1], -1))
