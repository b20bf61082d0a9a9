"""FlipNet: which of two outlines the left image shows — a pose or its 180° flip (a small CNN).

Input: views of :func:`spacepose.flip_views.flip_views`, (B, 3, S, S): grey image relative to the
target's brightness, outline A, outline B. A branch ``f`` scores A against B from the planes
``[g, a, b, a - b, g * (a - b)]`` (the difference planes mark where the two poses disagree, which is
all that can tell them apart); the network returns ``f(g, a, b) - f(g, b, a)``, the logit of "A is the
right one". Swapping A and B negates it exactly, so the order of the poses never matters.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from .rgb_branch import ConvBNAct, ResBlock

__all__ = ["FlipNetConfig", "FlipNet"]


@dataclass(frozen=True)
class FlipNetConfig:
    """size: side S of a view (pixels). widths: channels of the stem (stride 2) and of each stride-2
    residual stage after it. hidden: width of the scoring MLP."""

    size: int = 128
    widths: tuple[int, ...] = (24, 32, 48, 64, 96)
    hidden: int = 64

    def __post_init__(self) -> None:
        if self.size < 16 or self.size % (2 ** len(self.widths)):
            raise ValueError(f"FlipNetConfig: size {self.size} must be >= 16 and divisible by 2**{len(self.widths)}")
        if not self.widths or min(self.widths) < 1 or self.hidden < 1:
            raise ValueError(f"FlipNetConfig: bad widths {self.widths} or hidden {self.hidden}")


class _Branch(nn.Module):
    """(B, 5, S, S) planes -> (B,) score."""

    def __init__(self, config: FlipNetConfig) -> None:
        super().__init__()
        w = config.widths
        layers: list[nn.Module] = [ConvBNAct(5, w[0], stride=2)]
        layers += [ResBlock(a, b, stride=2) for a, b in zip(w[:-1], w[1:])]
        self.features = nn.Sequential(*layers)
        self.head = nn.Sequential(nn.Linear(2 * w[-1], config.hidden), nn.ReLU(inplace=True), nn.Linear(config.hidden, 1))

    def forward(self, planes: torch.Tensor) -> torch.Tensor:
        x = self.features(planes)
        pooled = torch.cat([x.mean(dim=(2, 3)), x.amax(dim=(2, 3))], dim=1)
        return self.head(pooled)[:, 0]


class FlipNet(nn.Module):
    """(B, 3, S, S) views -> (B,) logit that outline A (plane 1) is the right pose (module docstring)."""

    def __init__(self, config: FlipNetConfig = FlipNetConfig()) -> None:
        super().__init__()
        self.config = config
        self.branch = _Branch(config)

    @staticmethod
    def _planes(g: torch.Tensor, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        d = a - b
        return torch.cat([g, a, b, d, g * d], dim=1)

    def forward(self, views: torch.Tensor) -> torch.Tensor:
        s = self.config.size
        if views.dim() != 4 or views.shape[1] != 3 or views.shape[2] != s or views.shape[3] != s:
            raise ValueError(f"FlipNet: expected (B, 3, {s}, {s}) views, got {tuple(views.shape)}")
        g, a, b = views[:, 0:1], views[:, 1:2], views[:, 2:3]
        both = self.branch(torch.cat([self._planes(g, a, b), self._planes(g, b, a)], dim=0)).reshape(2, -1)
        return both[0] - both[1]
