"""3D regularisation network (paper §3.2.3, eqs. 11-13): group-wise correlation -> geometry
encoding volume (GEV).

A 3-level 3D U-Net at 1/4 .. 1/32 (disparity halves with the image):

- stem at 1/4: G -> c0 channels, then feature-guided excitation;
- encoder j = 1..3: ``E_j = SECA(DWConv(E_{j-1}))`` (stride 2) — plain Conv3d / no SECA in the
  baseline (``use_dwsep`` / ``use_seca`` switch them);
- decoder j = 1..3: ``D_j = SECA(Concat(UPConv(D_{j-1}), E_{3-j}))`` with D_0 = E_3 and E_0 the
  stem volume; the baseline aggregates the concat with a 1x1x1 + 3x3x3 conv instead of SECA.

Every stage is followed by an excitation ``vol * sigmoid(conv1x1(image feature))`` broadcast over
disparity (IGEV). Input (B, G, D, H/4, W/4) with D divisible by 8, image features [f4 .. f32].
Output GEV (B, c0, D, H/4, W/4) and ``classify(gev)`` -> logits (B, D, H/4, W/4).
"""

from __future__ import annotations

import torch
from torch import nn

from spacepose.models.seca import SECA

__all__ = ["conv3d_block", "FeatureExcitation", "Regularizer"]


def conv3d_block(in_ch: int, out_ch: int, kernel: int = 3, stride: int = 1, dwsep: bool = False) -> nn.Sequential:
    """Conv3d (or depthwise kxkxk + pointwise 1x1x1) -> BN -> LeakyReLU."""
    pad = kernel // 2
    if dwsep:
        convs: list[nn.Module] = [
            nn.Conv3d(in_ch, in_ch, kernel, stride, pad, groups=in_ch, bias=False),
            nn.Conv3d(in_ch, out_ch, 1, bias=False),
        ]
    else:
        convs = [nn.Conv3d(in_ch, out_ch, kernel, stride, pad, bias=False)]
    return nn.Sequential(*convs, nn.BatchNorm3d(out_ch), nn.LeakyReLU(0.2, inplace=True))


class FeatureExcitation(nn.Module):
    """vol (B, C, D, h, w) * sigmoid(conv1x1(feature (B, F, h, w)))[:, :, None]."""

    def __init__(self, feature_ch: int, volume_ch: int) -> None:
        super().__init__()
        self.conv = nn.Conv2d(feature_ch, volume_ch, 1)

    def forward(self, volume: torch.Tensor, feature: torch.Tensor) -> torch.Tensor:
        return volume * torch.sigmoid(self.conv(feature)).unsqueeze(2)


class EncoderBlock(nn.Module):
    """(B, in_ch, D, h, w) -> (B, out_ch, D/2, h/2, w/2)."""

    def __init__(self, in_ch: int, out_ch: int, use_dwsep: bool, use_seca: bool, depthwise_qk: bool) -> None:
        super().__init__()
        self.conv = nn.Sequential(
            conv3d_block(in_ch, out_ch, 3, 2, use_dwsep), conv3d_block(out_ch, out_ch, 3, 1, use_dwsep)
        )
        self.seca: nn.Module = SECA(out_ch, out_ch, depthwise_qk) if use_seca else nn.Identity()

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.seca(self.conv(x))


class DecoderBlock(nn.Module):
    """(B, in_ch, D, h, w), skip (B, out_ch, 2D, 2h, 2w) -> (B, out_ch, 2D, 2h, 2w)."""

    def __init__(self, in_ch: int, out_ch: int, use_seca: bool, depthwise_qk: bool) -> None:
        super().__init__()
        self.up = nn.Sequential(
            nn.ConvTranspose3d(in_ch, out_ch, 4, 2, 1, bias=False),
            nn.BatchNorm3d(out_ch),
            nn.LeakyReLU(0.2, inplace=True),
        )
        if use_seca:
            self.aggregate: nn.Module = SECA(2 * out_ch, out_ch, depthwise_qk)
        else:
            self.aggregate = nn.Sequential(conv3d_block(2 * out_ch, out_ch, 1), conv3d_block(out_ch, out_ch, 3))

    def forward(self, x: torch.Tensor, skip: torch.Tensor) -> torch.Tensor:
        return self.aggregate(torch.cat([self.up(x), skip], dim=1))


class Regularizer(nn.Module):
    def __init__(
        self,
        groups: int,
        widths: tuple[int, ...],
        feature_widths: tuple[int, ...],
        use_dwsep: bool,
        use_seca: bool,
        depthwise_qk: bool = False,
        seca_quarter_res: bool = True,
    ) -> None:
        """widths: (c0, c1, c2, c3) at 1/4 .. 1/32; feature_widths: image features at 1/4 .. 1/32.

        seca_quarter_res=False keeps the baseline aggregation in the 1/4 decoder block (CPU cost)."""
        super().__init__()
        c = widths
        self.stem = nn.Sequential(conv3d_block(groups, c[0]), conv3d_block(c[0], c[0]))
        self.encoders = nn.ModuleList(
            [EncoderBlock(c[j - 1], c[j], use_dwsep, use_seca, depthwise_qk) for j in (1, 2, 3)]
        )
        self.decoders = nn.ModuleList(
            [DecoderBlock(c[j + 1], c[j], use_seca and (j > 0 or seca_quarter_res), depthwise_qk) for j in (2, 1, 0)]
        )
        self.enc_excite = nn.ModuleList([FeatureExcitation(feature_widths[j], c[j]) for j in range(4)])
        self.dec_excite = nn.ModuleList([FeatureExcitation(feature_widths[j], c[j]) for j in (2, 1, 0)])
        self.classifier = nn.Conv3d(c[0], 1, 3, padding=1)

    def forward(self, volume: torch.Tensor, features: list[torch.Tensor]) -> torch.Tensor:
        """volume (B, G, D, H/4, W/4), features [f4, f8, f16, f32] -> GEV (B, c0, D, H/4, W/4)."""
        encoded = [self.enc_excite[0](self.stem(volume), features[0])]
        for j, block in enumerate(self.encoders, start=1):
            encoded.append(self.enc_excite[j](block(encoded[-1]), features[j]))
        y = encoded[3]
        for block, excite, j in zip(self.decoders, self.dec_excite, (2, 1, 0)):
            y = excite(block(y, encoded[j]), features[j])
        return y

    def classify(self, gev: torch.Tensor) -> torch.Tensor:
        """GEV (B, c0, D, h, w) -> disparity logits (B, D, h, w)."""
        return self.classifier(gev).squeeze(1)
