"""RandLA-Net-style point branch that only gathers with indices computed outside the graph.

Points are channels-last (B, N, C). Neighbour (``nbr``), subsampling (``sub``) and upsampling
(``up``) indices come from :mod:`spacepose.pose_inputs`; everything here is Gather / MatMul /
elementwise, so it exports to ONNX.
"""

from __future__ import annotations

import torch
from torch import nn

__all__ = ["gather_rows", "gather_index", "LocalAggregation", "neighbour_max_pool", "PointDecoderLayer", "mlp"]


def gather_rows(feats: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
    """``feats`` (B, N, C), ``idx`` (B, *S) int64 in [0, N) -> (B, *S, C) (one Gather op)."""
    b, n, c = feats.shape
    offsets = (torch.arange(b, device=idx.device, dtype=idx.dtype) * n).reshape([b] + [1] * (idx.dim() - 1))
    flat = (idx + offsets).reshape(-1)
    return feats.reshape(b * n, c).index_select(0, flat).reshape(list(idx.shape) + [c])


def gather_index(values: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
    """``values`` (B, N) int64, ``idx`` (B, *S) -> (B, *S): values[b, idx[b, ...]]."""
    return gather_rows(values.unsqueeze(-1), idx).squeeze(-1)


def mlp(c_in: int, c_out: int) -> nn.Sequential:
    """Shared per-point layer: Linear + LayerNorm + LeakyReLU."""
    return nn.Sequential(nn.Linear(c_in, c_out), nn.LayerNorm(c_out), nn.LeakyReLU(0.2))


def neighbour_max_pool(feats: torch.Tensor, nbr: torch.Tensor, sub: torch.Tensor) -> torch.Tensor:
    """Subsample (B, N_l, C) to (B, N_{l+1}, C): max over the K level-l neighbours of each kept point."""
    return torch.amax(gather_rows(feats, gather_index_rows(nbr, sub)), dim=2)


def gather_index_rows(nbr: torch.Tensor, sub: torch.Tensor) -> torch.Tensor:
    """Rows of an index table: ``nbr`` (B, N, K), ``sub`` (B, M) -> (B, M, K)."""
    return gather_rows(nbr, sub)


class LocalAggregation(nn.Module):
    """Local spatial encoding + attentive pooling over K gathered neighbours, with a residual.

    ``forward(feats (B, N, c_in), xyz (B, N, 3), nbr (B, N, K)) -> (B, N, c_out)``.
    """

    def __init__(self, c_in: int, c_out: int) -> None:
        super().__init__()
        half = c_out // 2
        self.pre = mlp(c_in, half)
        self.pos = mlp(10, c_out - half)
        self.score = nn.Linear(c_out, c_out, bias=False)
        self.post = nn.Sequential(nn.Linear(c_out, c_out), nn.LayerNorm(c_out))
        self.shortcut = nn.Sequential(nn.Linear(c_in, c_out), nn.LayerNorm(c_out))
        self.act = nn.LeakyReLU(0.2)

    def forward(self, feats: torch.Tensor, xyz: torch.Tensor, nbr: torch.Tensor) -> torch.Tensor:
        nxyz = gather_rows(xyz, nbr)                                   # (B, N, K, 3)
        centre = xyz.unsqueeze(2).expand_as(nxyz)
        rel = centre - nxyz
        dist = torch.sqrt(torch.sum(rel * rel, dim=-1, keepdim=True) + 1e-12)
        pos = self.pos(torch.cat([centre, nxyz, rel, dist], dim=-1))
        h = torch.cat([gather_rows(self.pre(feats), nbr), pos], dim=-1)  # (B, N, K, c_out)
        weights = torch.softmax(self.score(h), dim=2)
        agg = torch.sum(weights * h, dim=2)
        return self.act(self.post(agg) + self.shortcut(feats))


class PointDecoderLayer(nn.Module):
    """Nearest-point upsampling + skip concat: (skip (B, N_l, c_skip), coarse (B, N_{l+1}, c_coarse), up (B, N_l))."""

    def __init__(self, c_skip: int, c_coarse: int, c_out: int) -> None:
        super().__init__()
        self.fuse = mlp(c_skip + c_coarse, c_out)

    def forward(self, skip: torch.Tensor, coarse: torch.Tensor, up: torch.Tensor) -> torch.Tensor:
        return self.fuse(torch.cat([skip, gather_rows(coarse, up)], dim=-1))


class PointBranch(nn.Module):
    """Input layer, one LocalAggregation per level, a bottleneck at N_L and decoder layers back to N_0."""

    def __init__(self, c_in: int, stem: int, widths: tuple[int, ...], bottleneck: int) -> None:
        super().__init__()
        self.stem = mlp(c_in, stem)
        chans = (stem,) + tuple(widths)
        self.encoder = nn.ModuleList(LocalAggregation(chans[i], chans[i + 1]) for i in range(len(widths)))
        self.bottleneck = mlp(widths[-1], bottleneck)
        coarse = tuple(widths[1:]) + (bottleneck,)
        self.decoder = nn.ModuleList(PointDecoderLayer(widths[i], coarse[i], widths[i]) for i in range(len(widths)))
