"""Geometry lookup: combined geometry encoding volume + all-pairs correlation pyramid, read by a
gather-based 1-D linear interpolation (no GridSample in the exported graph).

At disparity d (1/4-res pixels) and pyramid level i the lookup reads, for k = -r .. r,
- GEV level i at position d / 2^i + k (all c0 channels),
- all-pairs correlation level i at position (x - d) / 2^i + k,
with zeros outside the volume (grid_sample's zeros padding, align_corners=True).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

__all__ = ["linear_lookup_1d", "GeometryLookup"]


def linear_lookup_1d(volume: torch.Tensor, positions: torch.Tensor) -> torch.Tensor:
    """volume (N, C, L), positions (N, K) float -> (N, C, K), linear interpolation along L.

    Samples outside [0, L-1] blend with zeros, exactly like grid_sample(padding_mode="zeros",
    align_corners=True) on a 1-pixel-high image.
    """
    n, c, length = volume.shape
    padded = F.pad(volume, (1, 1))  # index j of volume is j + 1 here; 0 and L + 1 are zeros
    base = torch.floor(positions)
    frac = (positions - base).unsqueeze(1)  # (N, 1, K)
    i0 = torch.clamp(base.long() + 1, 0, length + 1)
    i1 = torch.clamp(base.long() + 2, 0, length + 1)
    k = positions.shape[1]
    v0 = torch.gather(padded, 2, i0.unsqueeze(1).expand(n, c, k))
    v1 = torch.gather(padded, 2, i1.unsqueeze(1).expand(n, c, k))
    return v0 * (1.0 - frac) + v1 * frac


class GeometryLookup:
    """Built once per forward; ``lookup(disp)`` is called once per GRU iteration.

    gev (B, c0, D, h, w), corr (B, h, w, W2) -> lookup(disp (B, 1, h, w)) ->
    (B, levels * (2r+1) * (c0 + 1), h, w).
    """

    def __init__(self, gev: torch.Tensor, corr: torch.Tensor, levels: int, radius: int) -> None:
        b, c0, d, h, w = gev.shape
        self.shape = (b, h, w)
        self.radius = radius
        gev_flat = gev.permute(0, 3, 4, 1, 2).reshape(b * h * w, c0, d)
        corr_flat = corr.reshape(b * h * w, 1, corr.shape[-1])
        self.gev_pyramid = [gev_flat]
        self.corr_pyramid = [corr_flat]
        for _ in range(levels - 1):
            self.gev_pyramid.append(F.avg_pool1d(self.gev_pyramid[-1], 2, 2))
            self.corr_pyramid.append(F.avg_pool1d(self.corr_pyramid[-1], 2, 2))
        self.offsets = torch.arange(-radius, radius + 1, dtype=gev.dtype, device=gev.device).view(1, -1)
        self.x = torch.arange(w, dtype=gev.dtype, device=gev.device).view(1, 1, 1, w)

    def __call__(self, disp: torch.Tensor) -> torch.Tensor:
        b, h, w = self.shape
        d_flat = disp.permute(0, 2, 3, 1).reshape(b * h * w, 1)
        x_right = (self.x - disp).permute(0, 2, 3, 1).reshape(b * h * w, 1)
        out = []
        for i, (gev_i, corr_i) in enumerate(zip(self.gev_pyramid, self.corr_pyramid)):
            scale = 1.0 / 2**i
            out.append(linear_lookup_1d(gev_i, d_flat * scale + self.offsets).flatten(1))
            out.append(linear_lookup_1d(corr_i, x_right * scale + self.offsets).flatten(1))
        features = torch.cat(out, dim=1)  # (B*h*w, channels)
        return features.reshape(b, h, w, -1).permute(0, 3, 1, 2)
