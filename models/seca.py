"""SECA: Spatial and Efficient Channel Attention for 3D cost volumes (paper §3.2.2, eqs. 3-10).

Input X (B, C, D, H, W). Two parallel branches:

- ECA (eq. 3): global average over D, H, W -> 1-D conv across channels (adaptive odd kernel)
  -> sigmoid -> channel-reweighted X.
- multi-scale spatial attention (eqs. 4-9): Xq = ReLU(3x3x3 conv), Xk = ReLU(5x5x5 conv),
  Xv = ReLU(1x1x1 conv), all C channels; U = Xq * Xk; per channel a softmax over the L = D*H*W
  positions gives W, scaled by L so that the mean weight is 1 (instance norm's eps then stays
  negligible); X_attn = W * Xv.

Fusion (eq. 10): concat [X_attn, X_ECA] (2C) -> InstanceNorm3d -> 1x1x1 conv -> ReLU -> out_ch.
"""

from __future__ import annotations

import math

import torch
from torch import nn

__all__ = ["EfficientChannelAttention3d", "SECA"]


def eca_kernel_size(channels: int, gamma: int = 2, b: int = 1) -> int:
    """ECA-Net's adaptive kernel: nearest odd number to (log2(C) + b) / gamma, at least 1."""
    k = int(abs((math.log2(channels) + b) / gamma))
    return k if k % 2 else k + 1


class EfficientChannelAttention3d(nn.Module):
    """(B, C, D, H, W) -> same shape, scaled per channel by sigmoid(conv1d(mean over D,H,W))."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        k = eca_kernel_size(channels)
        self.conv = nn.Conv1d(1, 1, k, padding=k // 2, bias=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = x.mean(dim=(2, 3, 4)).unsqueeze(1)  # (B, 1, C)
        w = torch.sigmoid(self.conv(y)).squeeze(1)  # (B, C)
        return x * w[:, :, None, None, None]


class SECA(nn.Module):
    """(B, in_ch, D, H, W) -> (B, out_ch, D, H, W).

    depthwise_qk: the 3x3x3 / 5x5x5 query and key convs are depthwise (groups = in_ch) — a cost
    knob for the CPU model; the paper model uses full convs.
    """

    def __init__(self, in_ch: int, out_ch: int | None = None, depthwise_qk: bool = False) -> None:
        super().__init__()
        out_ch = in_ch if out_ch is None else out_ch
        groups = in_ch if depthwise_qk else 1
        self.eca = EfficientChannelAttention3d(in_ch)
        self.query = nn.Sequential(nn.Conv3d(in_ch, in_ch, 3, padding=1, groups=groups), nn.ReLU())
        self.key = nn.Sequential(nn.Conv3d(in_ch, in_ch, 5, padding=2, groups=groups), nn.ReLU())
        self.value = nn.Sequential(nn.Conv3d(in_ch, in_ch, 1), nn.ReLU())
        self.norm = nn.InstanceNorm3d(2 * in_ch, affine=True)
        self.fuse = nn.Sequential(nn.Conv3d(2 * in_ch, out_ch, 1), nn.ReLU())

    def spatial_weights(self, x: torch.Tensor) -> torch.Tensor:
        """Eqs. 4-8: (B, C, D, H, W) -> softmax(Xq * Xk over D*H*W) * L, same shape."""
        u = self.query(x) * self.key(x)
        flat = u.flatten(2)  # (B, C, L)
        weights = torch.softmax(flat, dim=-1) * flat.shape[-1]
        return weights.reshape(u.shape)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x_attn = self.spatial_weights(x) * self.value(x)
        x_eca = self.eca(x)
        return self.fuse(self.norm(torch.cat([x_attn, x_eca], dim=1)))
