"""OutlineRefinerNet: the stereo outline sharpened against the left image (a small U-Net; session 41).

Input: :func:`spacepose.outline_refiner.refiner_planes`, (B, 3, H, W) with H and W multiples of 4: the left image
relative to its brightness inside the stereo outline, the stereo outline (0 / 1) and the disparity over the
outline's threshold. Output: (B, 1, H, W), per pixel the logit that the target covers it. The output is the
network's plus ``prior`` times (outline - 1/2), so an untrained network returns the stereo outline itself.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn
from torch.nn import functional as F

__all__ = ["OutlineRefinerConfig", "OutlineRefinerNet"]


@dataclass(frozen=True)
class OutlineRefinerConfig:
    """width: channels at full resolution (twice and four times that at 1/2 and 1/4). prior: weight of the stereo
    outline added to the logit."""

    width: int = 16
    prior: float = 4.0

    def __post_init__(self) -> None:
        if self.width < 1 or not self.prior >= 0.0:
            raise ValueError(f"OutlineRefinerConfig: bad width {self.width} or prior {self.prior}")


def _block(cin: int, cout: int, dilation: int = 1) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(cin, cout, 3, padding=dilation, dilation=dilation, bias=False),
                         nn.BatchNorm2d(cout), nn.ReLU(inplace=True))


class OutlineRefinerNet(nn.Module):
    """(B, 3, H, W) planes -> (B, 1, H, W) logits; H and W multiples of 4."""

    def __init__(self, config: OutlineRefinerConfig = OutlineRefinerConfig()) -> None:
        super().__init__()
        self.config = config
        w = config.width
        self.e1 = nn.Sequential(_block(3, w), _block(w, w))
        self.e2 = nn.Sequential(nn.MaxPool2d(2), _block(w, 2 * w), _block(2 * w, 2 * w))
        self.e3 = nn.Sequential(nn.MaxPool2d(2), _block(2 * w, 4 * w), _block(4 * w, 4 * w, 2), _block(4 * w, 4 * w, 4))
        self.d2 = nn.Sequential(_block(6 * w, 2 * w), _block(2 * w, 2 * w))
        self.d1 = nn.Sequential(_block(3 * w, w), _block(w, w))
        self.head = nn.Conv2d(w, 1, 1)

    def forward(self, planes: torch.Tensor) -> torch.Tensor:
        a = self.e1(planes)
        b = self.e2(a)
        c = self.e3(b)
        u = self.d2(torch.cat([F.interpolate(c, scale_factor=2.0, mode="nearest"), b], 1))
        u = self.d1(torch.cat([F.interpolate(u, scale_factor=2.0, mode="nearest"), a], 1))
        return self.head(u) + self.config.prior * (planes[:, 1:2] - 0.5)
