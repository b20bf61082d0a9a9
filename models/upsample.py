"""Convex upsampling: each fine pixel is a softmax-weighted mix of the 3x3 coarse neighbourhood.

Built from pad + slicing + pixel_shuffle (exports to Pad/Slice/DepthToSpace; no unfold needed).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["convex_upsample", "UpsampleMaskHead"]


def convex_upsample(disp: torch.Tensor, mask: torch.Tensor, factor: int = 4) -> torch.Tensor:
    """disp (B, 1, h, w) in coarse pixels, mask (B, 9*f*f, h, w) logits -> (B, 1, f*h, f*w) in
    fine pixels (values multiplied by f). Channel k*f*f + s of the mask weighs neighbour k
    (row-major 3x3) for sub-pixel s (row-major f x f)."""
    b, _, h, w = disp.shape
    # softmax over the 9 neighbours written out: onnxruntime transposes for a Softmax on a non-last
    # axis (14 ms of the 256x256 graph); max / exp / sums over axis 1 are elementwise and reductions
    logits = mask.reshape(b, 9, factor * factor, h, w)
    expo = torch.exp(logits - torch.amax(logits, dim=1, keepdim=True))
    padded = F.pad(disp * factor, (1, 1, 1, 1), mode="replicate")
    neighbours = torch.stack(
        [padded[:, 0, dy : dy + h, dx : dx + w] for dy in range(3) for dx in range(3)], dim=1
    )  # (B, 9, h, w)
    fine = (expo * neighbours.unsqueeze(2)).sum(dim=1) / expo.sum(dim=1)  # (B, f*f, h, w)
    return F.pixel_shuffle(fine, factor)


class UpsampleMaskHead(nn.Module):
    """features (B, C, h, w) -> mask logits (B, 9*f*f, h, w) (used for the initial disparity)."""

    def __init__(self, in_ch: int, factor: int = 4, mid: int = 32) -> None:
        super().__init__()
        self.net = nn.Sequential(
            nn.Conv2d(in_ch, mid, 3, padding=1), nn.ReLU(inplace=True), nn.Conv2d(mid, 9 * factor * factor, 1)
        )

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        return 0.25 * self.net(features)
