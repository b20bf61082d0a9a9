"""Small ResNet-style RGB encoder-decoder; PoseNet drives it stage by stage to fuse between stages."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["ConvBNAct", "ResBlock", "RGBDecoderLayer", "RGBNormalise", "RGBBranch"]

_MEAN = (0.485 * 255, 0.456 * 255, 0.406 * 255)
_STD = (0.229 * 255, 0.224 * 255, 0.225 * 255)


class RGBNormalise(nn.Module):
    """(B, 3, H, W) RGB in [0, 255] -> ImageNet-normalised (constants, not parameters)."""

    def __init__(self) -> None:
        super().__init__()
        self.register_buffer("mean", torch.tensor(_MEAN).reshape(1, 3, 1, 1), persistent=False)
        self.register_buffer("inv_std", 1.0 / torch.tensor(_STD).reshape(1, 3, 1, 1), persistent=False)

    def forward(self, rgb: torch.Tensor) -> torch.Tensor:
        return (rgb - self.mean) * self.inv_std


class ConvBNAct(nn.Sequential):
    def __init__(self, c_in: int, c_out: int, stride: int = 1, kernel: int = 3) -> None:
        super().__init__(nn.Conv2d(c_in, c_out, kernel, stride, kernel // 2, bias=False),
                         nn.BatchNorm2d(c_out), nn.ReLU(inplace=True))


class ResBlock(nn.Module):
    """Basic residual block (two 3x3 convs); ``stride`` 2 halves the resolution."""

    def __init__(self, c_in: int, c_out: int, stride: int = 1) -> None:
        super().__init__()
        self.conv1 = ConvBNAct(c_in, c_out, stride)
        self.conv2 = nn.Sequential(nn.Conv2d(c_out, c_out, 3, 1, 1, bias=False), nn.BatchNorm2d(c_out))
        self.shortcut = (nn.Identity() if stride == 1 and c_in == c_out else
                         nn.Sequential(nn.Conv2d(c_in, c_out, 1, stride, bias=False), nn.BatchNorm2d(c_out)))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.relu(self.conv2(self.conv1(x)) + self.shortcut(x))


class RGBDecoderLayer(nn.Module):
    """Nearest x2 upsampling of the coarse map, concat with the skip, 3x3 conv."""

    def __init__(self, c_skip: int, c_coarse: int, c_out: int) -> None:
        super().__init__()
        self.conv = ConvBNAct(c_skip + c_coarse, c_out)

    def forward(self, skip: torch.Tensor, coarse: torch.Tensor) -> torch.Tensor:
        return self.conv(torch.cat([skip, F.interpolate(coarse, scale_factor=2.0, mode="nearest")], dim=1))


class RGBBranch(nn.Module):
    """Encoder stages at strides 4, 8, ... (one per point level), a bottleneck one stride lower,
    decoder layers back to stride 4 and an output layer at stride 2. PoseNet calls the parts."""

    def __init__(self, stem: int, widths: tuple[int, ...], bottleneck: int, out: int) -> None:
        super().__init__()
        self.normalise = RGBNormalise()
        self.stem = ConvBNAct(3, stem, stride=2)
        chans = (stem,) + tuple(widths)
        self.encoder = nn.ModuleList(ResBlock(chans[i], chans[i + 1], stride=2) for i in range(len(widths)))
        self.bottleneck = ResBlock(widths[-1], bottleneck, stride=2)
        coarse = (tuple(widths[1:]) + (bottleneck,))
        self.decoder = nn.ModuleList(RGBDecoderLayer(widths[i], coarse[i], widths[i]) for i in range(len(widths)))
        self.out = RGBDecoderLayer(stem, widths[0], out)
