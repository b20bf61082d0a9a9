"""Triplet Attention (paper §3.2.1, eqs. 1-2): cross-dimension attention without channel reduction.

Three branches see the feature map (B, C, H, W) through rotations so that a Z-pool (max and mean
over one axis) followed by a 7x7 conv and a sigmoid yields a gate over the two remaining axes:

- branch 1: pools over H -> gate over (C, W)
- branch 2: pools over W -> gate over (H, C)
- branch 3: pools over C -> gate over (H, W)

Output ``T = (y1 + y2 + y3) / 3`` (same shape as the input).
"""

from __future__ import annotations

import torch
from torch import nn

__all__ = ["z_pool", "AttentionGate", "TripletAttention"]


def z_pool(x: torch.Tensor) -> torch.Tensor:
    """(B, C, H, W) -> (B, 2, H, W): max and mean over dim 1, stacked."""
    return torch.cat([x.amax(dim=1, keepdim=True), x.mean(dim=1, keepdim=True)], dim=1)


class AttentionGate(nn.Module):
    """x (B, C, H, W) -> x * sigmoid(conv7x7(z_pool(x))); the gate is (B, 1, H, W)."""

    def __init__(self, kernel_size: int = 7) -> None:
        super().__init__()
        self.conv = nn.Conv2d(2, 1, kernel_size, padding=kernel_size // 2)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x * torch.sigmoid(self.conv(z_pool(x)))


class TripletAttention(nn.Module):
    """(B, C, H, W) -> (B, C, H, W), mean of the three rotated attention branches."""

    def __init__(self, kernel_size: int = 7) -> None:
        super().__init__()
        self.gate_cw = AttentionGate(kernel_size)
        self.gate_hc = AttentionGate(kernel_size)
        self.gate_hw = AttentionGate(kernel_size)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        # rotate H into the channel slot: (B, H, C, W); pooling over H leaves a (C, W) gate
        y1 = self.gate_cw(x.permute(0, 2, 1, 3)).permute(0, 2, 1, 3)
        # rotate W into the channel slot: (B, W, H, C); pooling over W leaves an (H, C) gate
        y2 = self.gate_hc(x.permute(0, 3, 2, 1)).permute(0, 3, 2, 1)
        y3 = self.gate_hw(x)
        return (y1 + y2 + y3) / 3.0
