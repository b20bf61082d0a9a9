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

__all__ = ["linear_lookup_1d", "window_lookup_1d", "GeometryLookup"]


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


def window_lookup_1d(volume: torch.Tensor, centre: torch.Tensor, radius: int) -> torch.Tensor:
    """volume (C, L, N) (N columns, e.g. pixels), centre (N,) float -> (C, 2r+1, N): linear samples at
    ``centre + k`` for k = -r .. r along L, zeros outside — :func:`linear_lookup_1d` at positions
    ``centre[n] + k``, computed from ONE gather of the 2r+2 rows around each centre (the taps share
    their fractional part), with the columns last so that the result needs no transpose."""
    c, length, n = volume.shape
    taps = 2 * radius + 1
    padded = F.pad(volume, (0, 0, 1, 1))                             # (C, L + 2, N); row j of volume is j + 1
    base = torch.floor(centre)
    frac = (centre - base).reshape(1, 1, n)
    rows = base.long().reshape(1, n) + torch.arange(1 - radius, radius + 3, device=volume.device).reshape(-1, 1)
    rows = torch.clamp(rows, 0, length + 1)                          # (2r+2, N); rows 0 and L + 1 are zeros
    window = torch.gather(padded, 1, rows.unsqueeze(0).expand(c, taps + 1, n))
    low = window[:, :taps]
    return low + (window[:, 1:] - low) * frac


def _halve(volume: torch.Tensor) -> torch.Tensor:
    """(C, L, N) -> (C, L // 2, N): mean of row pairs (avg_pool1d(2, 2) along L)."""
    m = volume.shape[1] // 2
    return 0.5 * (volume[:, 0:2 * m:2] + volume[:, 1:2 * m:2])


class GeometryLookup:
    """Built once per forward; ``lookup(disp)`` is called once per GRU iteration.

    gev (B, c0, D, h, w), corr (B, h, w, W2) -> lookup(disp (B, 1, h, w)) ->
    (B, levels * (2r+1) * (c0 + 1), h, w); per level the c0 * (2r+1) GEV taps (channel-major), then
    the 2r+1 all-pairs taps. The pyramids are kept as (channels, length, B*h*w).
    """

    def __init__(self, gev: torch.Tensor, corr: torch.Tensor, levels: int, radius: int) -> None:
        b, c0, d, h, w = gev.shape
        n = b * h * w
        self.shape = (b, h, w)
        self.radius = radius
        self.gev_pyramid = [gev.permute(1, 2, 0, 3, 4).reshape(c0, d, n)]
        self.corr_pyramid = [corr.permute(3, 0, 1, 2).reshape(1, corr.shape[-1], n)]
        for _ in range(levels - 1):
            self.gev_pyramid.append(_halve(self.gev_pyramid[-1]))
            self.corr_pyramid.append(_halve(self.corr_pyramid[-1]))
        self.x = torch.arange(w, dtype=gev.dtype, device=gev.device).view(1, 1, 1, w)

    def __call__(self, disp: torch.Tensor) -> torch.Tensor:
        b, h, w = self.shape
        n = b * h * w
        d_flat = disp.permute(1, 0, 2, 3).reshape(n)
        x_right = (self.x - disp).permute(1, 0, 2, 3).reshape(n)
        out = []
        for i, (gev_i, corr_i) in enumerate(zip(self.gev_pyramid, self.corr_pyramid)):
            scale = 1.0 / 2**i
            out.append(window_lookup_1d(gev_i, d_flat * scale, self.radius).reshape(-1, n))
            out.append(window_lookup_1d(corr_i, x_right * scale, self.radius).reshape(-1, n))
        features = torch.cat(out, dim=0)                             # (channels, B*h*w)
        return features.reshape(-1, b, h, w).permute(1, 0, 2, 3)
