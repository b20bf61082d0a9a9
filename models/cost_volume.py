"""Cost volumes at 1/4 resolution, built by pad + stack (no in-place slice writes, so the ONNX
graph has no ScatterND).

Disparity convention: left pixel x matches right pixel x - d (d >= 0).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

__all__ = ["groupwise_correlation", "all_pairs_correlation"]


def groupwise_correlation(left: torch.Tensor, right: torch.Tensor, groups: int, num_disp: int) -> torch.Tensor:
    """(B, C, H, W) x2 -> (B, groups, num_disp, H, W).

    vol[b, g, d, y, x] = mean over the C/groups channels c of group g of
    left[b, c, y, x] * right[b, c, y, x - d], and 0 where x - d < 0.
    """
    b, c, h, w = left.shape
    per = c // groups
    right_pad = F.pad(right, (num_disp - 1, 0))  # zeros on the left border
    left_g = left.reshape(b, groups, per, h, w)
    slices = []
    for d in range(num_disp):
        start = num_disp - 1 - d
        shifted = right_pad[:, :, :, start : start + w].reshape(b, groups, per, h, w)
        slices.append((left_g * shifted).mean(dim=2))
    return torch.stack(slices, dim=2)


def all_pairs_correlation(left: torch.Tensor, right: torch.Tensor) -> torch.Tensor:
    """(B, C, H, W) x2 -> (B, H, W, W2): corr[b, y, x, x2] = mean_c left[b,c,y,x] * right[b,c,y,x2]."""
    c = left.shape[1]
    return torch.matmul(left.permute(0, 2, 3, 1), right.permute(0, 2, 1, 3)) / c
