"""Multi-level ConvGRU update operator (RAFT-Stereo / IGEV style).

Levels run at 1/4, 1/8, 1/16 (the first ``n_gru_layers``), coarsest updated first; each level's
input is the pooled finer hidden state and the upsampled coarser one; the 1/4 level also gets the
motion features (lookup + current disparity). Output per iteration: new hidden states, a
disparity increment (B, 1, H/4, W/4); the convex-upsampling mask (B, 9*16, H/4, W/4) is computed
only for the iterations whose output is upsampled.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from spacepose.models.stereo_config import StereoConfig

__all__ = ["ConvGRU", "MotionEncoder", "MultiLevelUpdate"]


class ConvGRU(nn.Module):
    """h (B, hidden, h, w), biases (cz, cr, cq) like h, inputs (B, *, h, w) -> new h."""

    def __init__(self, hidden: int, input_dim: int) -> None:
        super().__init__()
        self.hidden = hidden
        self.conv_zr = nn.Conv2d(hidden + input_dim, 2 * hidden, 3, padding=1)
        self.conv_q = nn.Conv2d(hidden + input_dim, hidden, 3, padding=1)

    def forward(self, h: torch.Tensor, biases: tuple[torch.Tensor, ...], *inputs: torch.Tensor) -> torch.Tensor:
        cz, cr, cq = biases
        x = torch.cat(inputs, dim=1)
        z, r = torch.split(self.conv_zr(torch.cat([h, x], dim=1)), [self.hidden, self.hidden], dim=1)
        z = torch.sigmoid(z + cz)
        r = torch.sigmoid(r + cr)
        q = torch.tanh(self.conv_q(torch.cat([r * h, x], dim=1)) + cq)
        return (1.0 - z) * h + z * q


class MotionEncoder(nn.Module):
    """lookup (B, corr_ch, h, w), disp (B, 1, h, w) -> (B, motion_dim, h, w) (last channel = disp)."""

    def __init__(self, corr_ch: int, motion_dim: int) -> None:
        super().__init__()
        mid = motion_dim
        self.corr = nn.Sequential(nn.Conv2d(corr_ch, mid, 1), nn.ReLU(inplace=True))
        self.disp = nn.Sequential(nn.Conv2d(1, mid // 4, 7, padding=3), nn.ReLU(inplace=True))
        self.fuse = nn.Sequential(nn.Conv2d(mid + mid // 4, motion_dim - 1, 3, padding=1), nn.ReLU(inplace=True))

    def forward(self, lookup: torch.Tensor, disp: torch.Tensor) -> torch.Tensor:
        y = self.fuse(torch.cat([self.corr(lookup), self.disp(disp)], dim=1))
        return torch.cat([y, disp], dim=1)


def pool2x(x: torch.Tensor) -> torch.Tensor:
    return F.avg_pool2d(x, 3, stride=2, padding=1)


def resize_to(x: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
    return F.interpolate(x, size=like.shape[-2:], mode="bilinear", align_corners=True)


class MultiLevelUpdate(nn.Module):
    def __init__(self, cfg: StereoConfig, factor: int = 4) -> None:
        super().__init__()
        n = cfg.n_gru_layers
        dims = cfg.hidden_dims[:n]
        self.n = n
        self.encoder = MotionEncoder(cfg.lookup_channels, cfg.motion_dim)
        in_dims = []
        for i in range(n):
            finer = cfg.motion_dim if i == 0 else dims[i - 1]
            coarser = dims[i + 1] if i + 1 < n else 0
            in_dims.append(finer + coarser)
        self.grus = nn.ModuleList([ConvGRU(dims[i], in_dims[i]) for i in range(n)])
        h0 = dims[0]
        self.disp_head = nn.Sequential(
            nn.Conv2d(h0, h0, 3, padding=1), nn.ReLU(inplace=True), nn.Conv2d(h0, 1, 3, padding=1)
        )
        self.mask_head = nn.Sequential(
            nn.Conv2d(h0, h0, 3, padding=1), nn.ReLU(inplace=True), nn.Conv2d(h0, 9 * factor * factor, 1)
        )

    def forward(
        self,
        hidden: list[torch.Tensor],
        biases: list[tuple[torch.Tensor, ...]],
        lookup: torch.Tensor,
        disp: torch.Tensor,
    ) -> tuple[list[torch.Tensor], torch.Tensor]:
        """-> (new hidden list, delta_disp (B, 1, h, w)); ``upsample_mask(hidden[0])`` on demand."""
        hidden = list(hidden)
        for i in range(self.n - 1, 0, -1):  # coarse to fine, 1/4 last
            inputs = [pool2x(hidden[i - 1])]
            if i + 1 < self.n:
                inputs.append(resize_to(hidden[i + 1], hidden[i]))
            hidden[i] = self.grus[i](hidden[i], biases[i], *inputs)
        inputs = [self.encoder(lookup, disp)]
        if self.n > 1:
            inputs.append(resize_to(hidden[1], hidden[0]))
        hidden[0] = self.grus[0](hidden[0], biases[0], *inputs)
        return hidden, self.disp_head(hidden[0])

    def upsample_mask(self, hidden0: torch.Tensor) -> torch.Tensor:
        """(B, hidden_dims[0], h, w) -> convex-upsampling logits (B, 9*f*f, h, w)."""
        return 0.25 * self.mask_head(hidden0)
