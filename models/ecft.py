"""Efficient Cross-modal Fusion Transformer (ECFT), paper eqs. 14-22.

One block fuses an RGB feature map and the point features of one level, in the directions
selected by ``fusion`` (paper Table 5):

* ``"pt2rgb"`` - point → RGB: the RGB tokens are updated, the point features pass through;
* ``"rgb2pt"`` - RGB → point: the point features are updated, the RGB map passes through;
* ``"both"``  - both, each from the *input* features of the other (eq. 14).

Each direction: x = attention(target, source) (ECAA eqs. 15-18 or dot-product, Table 6);
M = GFFN([x ‖ target]) (eq. 19); fused = AugSC(target) + target + M (eqs. 20-22).

Token alignment for ECAA (which needs one source token per target token), scatter-free:
point → pixel takes each pixel's nearest point (``pix2pt``, computed in numpy); pixel → point
takes the max over the pixels of the point's K nearest points (``pt_pix``), as in FFB6D.
The dot-product baseline attends to all tokens of the other modality instead.
"""

from __future__ import annotations

import torch
from torch import nn

from .ecaa import ECAA
from .gated_ffn import GatedFFN
from .point_branch import gather_rows
from .vanilla_attention import VanillaCrossAttention

__all__ = ["AugmentedShortcut", "CrossModalUpdate", "ECFT"]


class AugmentedShortcut(nn.Module):
    """``LN(F W + b)`` (eq. 20): a learnable token-wise remapping beside the identity shortcut."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.linear = nn.Linear(channels, channels)
        self.norm = nn.LayerNorm(channels)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.norm(self.linear(x))


class CrossModalUpdate(nn.Module):
    """One fusion direction on tokens: (target (B, n, c_t), source (B, m, c_s)) -> (B, n, c_t)."""

    def __init__(self, c_target: int, c_source: int, dim: int, attention: str = "ecaa",
                 ffn_ratio: float = 2.0, heads: int = 4) -> None:
        super().__init__()
        if attention == "ecaa":
            self.attention = ECAA(c_target, c_source, dim)
        elif attention == "vanilla":
            self.attention = VanillaCrossAttention(c_target, c_source, dim, heads)
        else:
            raise ValueError(f"attention must be 'ecaa' or 'vanilla', got {attention!r}")
        self.ffn = GatedFFN(dim + c_target, max(1, int(round(ffn_ratio * c_target))), c_target)
        self.shortcut = AugmentedShortcut(c_target)

    def forward(self, target: torch.Tensor, source: torch.Tensor) -> torch.Tensor:
        x = self.attention(target, source)
        m = self.ffn(torch.cat([x, target], dim=-1))
        return self.shortcut(target) + target + m


class ECFT(nn.Module):
    """Bidirectional RGB ↔ point fusion block.

    ``forward(f_rgb (B, C_r, H, W), f_point (B, N, C_p), pix2pt (B, H*W), pt_pix (B, N, K))``
    returns ``(f_rgb_fused, f_point_fused)`` of the same shapes. ``pix2pt`` indexes points,
    ``pt_pix`` holds flat pixel indices (at this map's resolution) of each point's neighbours.
    """

    def __init__(self, c_rgb: int, c_point: int, dim: int, fusion: str = "both", attention: str = "ecaa",
                 ffn_ratio: float = 2.0, heads: int = 4) -> None:
        super().__init__()
        if fusion not in ("both", "rgb2pt", "pt2rgb", "none"):
            raise ValueError(f"fusion must be one of both/rgb2pt/pt2rgb/none, got {fusion!r}")
        self.attention = attention
        self.pt2rgb = (CrossModalUpdate(c_rgb, c_point, dim, attention, ffn_ratio, heads)
                       if fusion in ("both", "pt2rgb") else None)
        self.rgb2pt = (CrossModalUpdate(c_point, c_rgb, dim, attention, ffn_ratio, heads)
                       if fusion in ("both", "rgb2pt") else None)

    def forward(self, f_rgb: torch.Tensor, f_point: torch.Tensor, pix2pt: torch.Tensor,
                pt_pix: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        b, c, h, w = f_rgb.shape
        rgb_tokens = f_rgb.reshape(b, c, h * w).transpose(1, 2)          # (B, HW, C_r)
        out_rgb, out_point = f_rgb, f_point
        if self.pt2rgb is not None:
            source = f_point if self.attention == "vanilla" else gather_rows(f_point, pix2pt)
            fused = self.pt2rgb(rgb_tokens, source)
            out_rgb = fused.transpose(1, 2).reshape(b, c, h, w)
        if self.rgb2pt is not None:
            source = rgb_tokens if self.attention == "vanilla" else torch.amax(gather_rows(rgb_tokens, pt_pix), dim=2)
            out_point = self.rgb2pt(f_point, source)
        return out_rgb, out_point
