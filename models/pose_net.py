"""Multimodal pose network: RGB CNN + RandLA-style point net fused by ECFT blocks, FFB6D heads.

``PoseNet(cfg)(rgb, points, choose, nbr_0..nbr_{L-1}, sub_0.., up_0.., pix2pt_0..)`` with the inputs
described in :mod:`spacepose.pose_inputs` (``pose_input_names`` gives the positional order)
returns ``(seg_logits (B, N, n_classes), kp_offsets (B, M, N, 3), ctr_offsets (B, N, 3))``.

OFFSET CONVENTION: offsets are in metres and point FROM the point TO the keypoint,
``offset = keypoint - point``, so a point's vote is ``xyz_cam + offset`` (:func:`keypoint_votes`).

Export: the graph only gathers (Gather), multiplies (MatMul/Conv) and does elementwise maths; no
scatter, no kNN, no data-dependent control flow. Fusion happens at every encoder level and (with
``cfg.fuse_decoder``) every decoder level; level ``l`` pairs N_l points with the stride-4·2^l map.
"""

from __future__ import annotations

from typing import Mapping

import torch
from torch import nn

from spacepose.pose_inputs import pose_input_names

from .ecft import ECFT
from .point_branch import PointBranch, gather_index, gather_rows, neighbour_max_pool
from .pose_config import PoseNetConfig
from .rgb_branch import RGBBranch

__all__ = ["PoseNet", "keypoint_votes", "count_parameters"]


def keypoint_votes(xyz_cam: torch.Tensor, offsets: torch.Tensor) -> torch.Tensor:
    """Votes ``xyz_cam + offset``: xyz (B, N, 3), offsets (B, [M,] N, 3) -> same shape as offsets."""
    return (xyz_cam.unsqueeze(1) if offsets.dim() == 4 else xyz_cam) + offsets


def count_parameters(module: nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())


def _head(c_in: int, width: int, c_out: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(c_in, width), nn.ReLU(inplace=True), nn.Linear(width, width),
                         nn.ReLU(inplace=True), nn.Linear(width, c_out))


def _pixels_at_stride(choose: torch.Tensor, crop_width: int, stride: int) -> torch.Tensor:
    """Flat crop-pixel index -> flat index in the stride-``stride`` feature map (non-negative ints)."""
    row = torch.div(choose, crop_width, rounding_mode="floor")
    col = choose - row * crop_width
    return torch.div(row, stride, rounding_mode="floor") * (crop_width // stride) + torch.div(col, stride, rounding_mode="floor")


class PoseNet(nn.Module):
    """See the module docstring. ``cfg`` is kept as ``self.cfg`` (a frozen :class:`PoseNetConfig`)."""

    def __init__(self, cfg: PoseNetConfig | None = None) -> None:
        super().__init__()
        cfg = cfg or PoseNetConfig.cpu()
        self.cfg = cfg
        self.rgb = RGBBranch(cfg.rgb_stem, cfg.rgb_widths, cfg.rgb_bottleneck, cfg.rgb_out)
        self.point = PointBranch(cfg.point_channels, cfg.point_stem, cfg.point_widths, cfg.point_bottleneck)
        levels = range(cfg.n_levels)

        def blocks(enabled: bool) -> nn.ModuleList | None:
            if cfg.fusion == "none" or not enabled:
                return None
            return nn.ModuleList(ECFT(cfg.rgb_widths[i], cfg.point_widths[i], cfg.ecft_dim(i), cfg.fusion,
                                      cfg.attention, cfg.ffn_ratio, cfg.vanilla_heads) for i in levels)

        self.fuse_encoder = blocks(True)
        self.fuse_decoder = blocks(cfg.fuse_decoder)
        c_feat = cfg.point_widths[0] + cfg.rgb_out
        self.seg_head = _head(c_feat, cfg.head_width, cfg.n_classes)
        self.kp_head = _head(c_feat, cfg.head_width, 3 * cfg.n_keypoints)
        self.ctr_head = _head(c_feat, cfg.head_width, 3)

    @property
    def input_names(self) -> list[str]:
        return pose_input_names(self.cfg.n_levels)

    @property
    def used_input_names(self) -> list[str]:
        """Inputs this variant reads; ONNX export drops the others (``pix2pt_*`` when
        ``fusion="none"`` or ``attention="vanilla"``), so feed a session only its declared inputs."""
        reads_pix2pt = self.cfg.fusion in ("both", "pt2rgb") and self.cfg.attention == "ecaa"
        return [n for n in self.input_names if reads_pix2pt or not n.startswith("pix2pt_")]

    output_names = ("seg_logits", "kp_offsets", "ctr_offsets")

    def forward_dict(self, inputs: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """Run on a dict keyed by :attr:`input_names` (numpy arrays are converted)."""
        missing = [n for n in self.input_names if n not in inputs]
        if missing:
            raise KeyError(f"missing pose-net inputs: {missing}")
        args = [torch.as_tensor(inputs[n]) for n in self.input_names]
        return dict(zip(self.output_names, self(*args)))

    def forward(self, rgb: torch.Tensor, points: torch.Tensor, choose: torch.Tensor,
                *indices: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        cfg = self.cfg
        n_lv = cfg.n_levels
        if len(indices) != 4 * n_lv:
            raise ValueError(f"expected {4 * n_lv} index tensors (nbr, sub, up, pix2pt per level), got {len(indices)}")
        nbr, sub = indices[:n_lv], indices[n_lv:2 * n_lv]
        up, pix2pt = indices[2 * n_lv:3 * n_lv], indices[3 * n_lv:]
        crop_w = cfg.crop_size[0]

        xyz, chooses = [points[..., :3]], [choose]
        for lv in range(n_lv - 1):
            xyz.append(gather_rows(xyz[-1], sub[lv]))
            chooses.append(gather_index(chooses[-1], sub[lv]))
        # pixel (at the level's fusion stride) of each point's K neighbours, for pixel -> point
        pt_pix = [gather_index(_pixels_at_stride(chooses[lv], crop_w, 4 * 2**lv), nbr[lv]) for lv in range(n_lv)]

        r = self.rgb.stem(self.rgb.normalise(rgb))
        stem_map = r
        p = self.point.stem(points)
        skips_r, skips_p = [], []
        for lv in range(n_lv):
            r = self.rgb.encoder[lv](r)
            p = self.point.encoder[lv](p, xyz[lv], nbr[lv])
            if self.fuse_encoder is not None:
                r, p = self.fuse_encoder[lv](r, p, pix2pt[lv], pt_pix[lv])
            skips_r.append(r)
            skips_p.append(p)
            p = neighbour_max_pool(p, nbr[lv], sub[lv])
        r = self.rgb.bottleneck(r)
        p = self.point.bottleneck(p)
        for lv in reversed(range(n_lv)):
            r = self.rgb.decoder[lv](skips_r[lv], r)
            p = self.point.decoder[lv](skips_p[lv], p, up[lv])
            if self.fuse_decoder is not None:
                r, p = self.fuse_decoder[lv](r, p, pix2pt[lv], pt_pix[lv])
        r = self.rgb.out(stem_map, r)                                       # stride 2
        b, c = r.shape[:2]
        rgb_tokens = r.reshape(b, c, -1).transpose(1, 2)
        feat = torch.cat([p, gather_rows(rgb_tokens, _pixels_at_stride(choose, crop_w, 2))], dim=-1)

        seg_logits = self.seg_head(feat)
        n = feat.shape[1]
        kp = self.kp_head(feat).reshape(b, n, cfg.n_keypoints, 3).permute(0, 2, 1, 3) * cfg.xyz_scale
        ctr = self.ctr_head(feat) * cfg.xyz_scale
        return seg_logits, kp, ctr
