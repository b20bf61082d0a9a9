"""Context network of TSCA-Stereo (paper §3.2.1, eq. 1-2 and Fig. 4).

Stem (stride-2 conv) to 1/2, then per GRU level i (1/4, 1/8, 1/16):
``F_i = ResBlock(Down(F_{i-1}))`` and, for the TA variants, ``T_i = TA(F_i)``. Each level's T_i
gives the initial hidden state ``tanh(conv)`` and the context ``relu(conv)``; the context is turned
into the three ConvGRU biases (cz, cr, cq) once, before the iterations.

Input: normalised left image (B, 3, H, W). Output ``ContextOutput``:
hidden[i] (B, hidden_dims[i], H/2^(i+2), W/2^(i+2)); biases[i] = (cz, cr, cq) of the same shape.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import nn

from spacepose.models.stereo_config import StereoConfig
from spacepose.models.stereo_features import ResidualBlock, conv_bn_relu
from spacepose.models.triplet_attention import TripletAttention

__all__ = ["ContextOutput", "ContextNetwork"]


class ContextOutput(NamedTuple):
    hidden: list[torch.Tensor]
    biases: list[tuple[torch.Tensor, torch.Tensor, torch.Tensor]]


class ContextLevel(nn.Module):
    """One scale: Down -> ResBlock -> (TA); (B, in_ch, h, w) -> (B, out_ch, h/2, w/2)."""

    def __init__(self, in_ch: int, out_ch: int, use_ta: bool) -> None:
        super().__init__()
        self.down = conv_bn_relu(in_ch, out_ch, 3, 2)
        self.res = ResidualBlock(out_ch, out_ch)
        self.attention: nn.Module = TripletAttention() if use_ta else nn.Identity()

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.attention(self.res(self.down(x)))


class ContextNetwork(nn.Module):
    def __init__(self, cfg: StereoConfig) -> None:
        super().__init__()
        n = cfg.n_gru_layers
        w = cfg.context_widths
        self.hidden_dims = cfg.hidden_dims[:n]
        self.stem = conv_bn_relu(3, w[0], 3, 2)
        self.levels = nn.ModuleList(
            [ContextLevel(w[i], w[i + 1], cfg.use_triplet_attention) for i in range(n)]
        )
        self.heads = nn.ModuleList([nn.Conv2d(w[i + 1], 2 * h, 3, padding=1) for i, h in enumerate(self.hidden_dims)])
        self.bias_convs = nn.ModuleList([nn.Conv2d(h, 3 * h, 3, padding=1) for h in self.hidden_dims])

    def forward(self, image: torch.Tensor) -> ContextOutput:
        hidden, biases = [], []
        y = self.stem(image)
        for level, head, bias_conv, h in zip(self.levels, self.heads, self.bias_convs, self.hidden_dims):
            y = level(y)
            net, ctx = torch.split(head(y), [h, h], dim=1)
            hidden.append(torch.tanh(net))
            cz, cr, cq = torch.split(bias_conv(torch.relu(ctx)), [h, h, h], dim=1)
            biases.append((cz, cr, cq))
        return ContextOutput(hidden=hidden, biases=biases)
