"""Gated feed-forward network with SwiGLU (paper eq. 19)."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["GatedFFN"]


class GatedFFN(nn.Module):
    """``LN(W (SiLU(x U) ⊙ x V))``: (B, n, c_in) -> (B, n, c_out); no biases, as in eq. 19."""

    def __init__(self, c_in: int, hidden: int, c_out: int) -> None:
        super().__init__()
        self.gate = nn.Linear(c_in, hidden, bias=False)   # U
        self.value = nn.Linear(c_in, hidden, bias=False)  # V
        self.out = nn.Linear(hidden, c_out, bias=False)   # W
        self.norm = nn.LayerNorm(c_out)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.norm(self.out(F.silu(self.gate(x)) * self.value(x)))
