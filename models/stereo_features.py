"""Shared feature network of TSCA-Stereo (run once on left and right stacked along the batch).

A residual encoder 1/2 -> 1/32 with a U-Net decoder back to 1/4 (IGEV's layout, trained from
scratch instead of a MobileNetV2 backbone). Input: normalised images (B, 3, H, W), H and W
multiples of 32. Output ``StereoFeatures``:

- pyramid: [f4, f8, f16, f32], decoded features at 1/4 .. 1/32 with
  ``feature_widths[1:]`` channels (guide the 3D regulariser),
- matching: (B, match_dim, H/4, W/4) features for the correlation volumes.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["ResidualBlock", "conv_bn_relu", "StereoFeatures", "FeatureNetwork"]


def conv_bn_relu(in_ch: int, out_ch: int, kernel: int = 3, stride: int = 1) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(in_ch, out_ch, kernel, stride, kernel // 2, bias=False),
        nn.BatchNorm2d(out_ch),
        nn.ReLU(inplace=True),
    )


class ResidualBlock(nn.Module):
    """(B, in_ch, H, W) -> (B, out_ch, H/stride, W/stride): two 3x3 conv-BN, identity/1x1 skip."""

    def __init__(self, in_ch: int, out_ch: int, stride: int = 1) -> None:
        super().__init__()
        self.conv1 = conv_bn_relu(in_ch, out_ch, 3, stride)
        self.conv2 = nn.Sequential(nn.Conv2d(out_ch, out_ch, 3, 1, 1, bias=False), nn.BatchNorm2d(out_ch))
        self.skip: nn.Module = nn.Identity()
        if stride != 1 or in_ch != out_ch:
            self.skip = nn.Sequential(nn.Conv2d(in_ch, out_ch, 1, stride, bias=False), nn.BatchNorm2d(out_ch))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.relu(self.conv2(self.conv1(x)) + self.skip(x))


class StereoFeatures(NamedTuple):
    pyramid: list[torch.Tensor]  # [f4, f8, f16, f32]
    matching: torch.Tensor  # (B, match_dim, H/4, W/4)


class FeatureNetwork(nn.Module):
    """widths: channels at 1/2, 1/4, 1/8, 1/16, 1/32."""

    def __init__(self, widths: tuple[int, ...], match_dim: int) -> None:
        super().__init__()
        w = widths
        self.stem = nn.Sequential(conv_bn_relu(3, w[0], 3, 2), conv_bn_relu(w[0], w[0]))
        self.down = nn.ModuleList([ResidualBlock(w[i], w[i + 1], 2) for i in range(4)])
        # decoder: 1/32 -> 1/16 -> 1/8 -> 1/4, concat skip then 3x3 conv
        self.up = nn.ModuleList([conv_bn_relu(w[i + 1] + w[i], w[i]) for i in range(3, 0, -1)])
        self.match = nn.Sequential(conv_bn_relu(w[1], w[1]), nn.Conv2d(w[1], match_dim, 1))

    def forward(self, x: torch.Tensor) -> StereoFeatures:
        encoded = []
        y = self.stem(x)
        for block in self.down:
            y = block(y)
            encoded.append(y)  # 1/4, 1/8, 1/16, 1/32
        decoded = [encoded[3]]
        for i, conv in zip((2, 1, 0), self.up):
            up = F.interpolate(decoded[0], scale_factor=2.0, mode="bilinear", align_corners=False)
            decoded.insert(0, conv(torch.cat([up, encoded[i]], dim=1)))
        return StereoFeatures(pyramid=decoded, matching=self.match(decoded[0]))
