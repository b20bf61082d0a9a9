"""Exact rewrite of 3-D convolutions as 2-D ones, for the exported stereo graph.

onnxruntime's CPU provider runs 2-D convolutions through its blocked (NCHWc) direct kernels, but
3-D ones through im2col + GEMM, one group at a time. For the depthwise 3x3x3 / 5x5x5 convolutions of
the TSCA-Stereo regulariser (SECA query / key, the depthwise-separable encoder convs) that is 4-9x
slower than torch eager, and its dense 3x3x3 convolutions run at about half torch's speed.
:class:`Conv3dAs2d` computes the *same* function as a ``Conv3d``: the sum over its ``k_d`` depth taps
of a ``Conv2d`` applied to every (shifted, strided) depth slice, the slices folded into the batch axis.

Measured on this machine, one thread, onnxruntime 1.32, with a training job on the other core
(``python -m spacepose.tools.bench_conv3d --json reports/bench_conv3d.json``): depthwise 32-channel
5x5x5 at 12x32x32 runs 20.1 -> 3.6 ms (torch eager 4.3), the dense 16-channel 3x3x3 at 24x64x64
26.4 -> 22.1 ms (torch 11.3). 1x1x1 layers already run as one GEMM and stay, as do layers with fewer
than :data:`MIN_OUT_CHANNELS` outputs.

Only the export uses this: training and the torch-eager baseline run the original layers, and the
export's parity check (torch original vs onnxruntime rewritten) guards the equivalence.
"""

from __future__ import annotations

import copy

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["Conv3dAs2d", "rewrite_conv3d", "wants_rewrite", "MIN_OUT_CHANNELS"]

#: narrower layers (the 1-channel disparity classifier) stay 3-D: onnxruntime's blocked 2-D kernels
#: need 8 or 16 output channels, and the plain path is slower than its Conv3d
MIN_OUT_CHANNELS = 8


class Conv3dAs2d(nn.Module):
    """The map of ``conv`` (an ``nn.Conv3d`` with zero padding given as numbers and no dilation):
    (B, C, D, H, W) -> (B, C_out, D', H', W'), computed with ``k_d`` grouped ``Conv2d`` calls."""

    def __init__(self, conv: nn.Conv3d) -> None:
        super().__init__()
        if conv.dilation != (1, 1, 1) or conv.padding_mode != "zeros" or isinstance(conv.padding, str):
            raise ValueError("Conv3dAs2d needs zero padding given as numbers and no dilation")
        weight = conv.weight.detach()                                  # (C_out, C_in / g, kd, kh, kw)
        self.kd = int(weight.shape[2])
        self.stride = tuple(int(s) for s in conv.stride)
        self.padding = tuple(int(p) for p in conv.padding)
        self.groups = int(conv.groups)
        self.out_channels = int(weight.shape[0])
        # kept in the Conv3d layout, so the state dict is the original's; tap j is weight[:, :, j]
        self.weight = nn.Parameter(weight.clone(), requires_grad=False)
        self.bias = None if conv.bias is None else nn.Parameter(conv.bias.detach().clone(), requires_grad=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, c, d, h, w = x.shape
        pd, ph, pw = self.padding
        sd, sh, sw = self.stride
        xt = x.transpose(1, 2)                                         # (B, D, C, H, W)
        if pd:
            xt = F.pad(xt, (0, 0, 0, 0, 0, 0, pd, pd))
        d_out = (d + 2 * pd - self.kd) // sd + 1
        out = None
        for j in range(self.kd):
            taps = xt[:, j: j + sd * (d_out - 1) + 1: sd].reshape(b * d_out, c, h, w)
            y = F.conv2d(taps, self.weight[:, :, j], self.bias if j == 0 else None, (sh, sw), (ph, pw), 1, self.groups)
            out = y if out is None else out + y
        return out.reshape((b, d_out, self.out_channels) + tuple(out.shape[-2:])).transpose(1, 2)


def wants_rewrite(module: nn.Module) -> bool:
    """True for the Conv3d layers :func:`rewrite_conv3d` replaces: a kernel wider than 1x1x1 (or a depth
    stride), at least :data:`MIN_OUT_CHANNELS` outputs, zero padding given as numbers, no dilation."""
    return (isinstance(module, nn.Conv3d) and not isinstance(module.padding, str)
            and module.padding_mode == "zeros" and module.dilation == (1, 1, 1)
            and module.out_channels >= MIN_OUT_CHANNELS
            and (module.kernel_size != (1, 1, 1) or module.stride[0] > 1))


def _fold_batchnorm(conv: nn.Conv3d, bn: nn.BatchNorm3d) -> nn.Conv3d:
    """A copy of ``conv`` computing ``bn(conv(x))`` in eval mode (what the ONNX exporter does when the
    BatchNorm directly follows a Conv, which it no longer does once the Conv is rewritten)."""
    scale = bn.weight.detach() / torch.sqrt(bn.running_var + bn.eps) if bn.affine else 1.0 / torch.sqrt(bn.running_var + bn.eps)
    shift = bn.bias.detach() if bn.affine else torch.zeros_like(bn.running_mean)
    folded = copy.deepcopy(conv)
    bias = conv.bias.detach() if conv.bias is not None else torch.zeros_like(bn.running_mean)
    folded.weight = nn.Parameter(conv.weight.detach() * scale.reshape(-1, 1, 1, 1, 1), requires_grad=False)
    folded.bias = nn.Parameter((bias - bn.running_mean) * scale + shift, requires_grad=False)
    return folded


def rewrite_conv3d(module: nn.Module) -> nn.Module:
    """A deep copy of ``module`` in eval mode with every layer :func:`wants_rewrite` accepts replaced by
    :class:`Conv3dAs2d` (``module`` itself is left untouched). A ``BatchNorm3d`` (with running
    statistics) that directly follows such a layer in an ``nn.Sequential`` is folded into it and
    becomes ``nn.Identity``."""
    out = copy.deepcopy(module).eval()
    if wants_rewrite(out):
        return Conv3dAs2d(out)
    for parent in list(out.modules()):
        children = list(parent.named_children())
        for i, (name, child) in enumerate(children):
            if not wants_rewrite(child):
                continue
            after = children[i + 1] if isinstance(parent, nn.Sequential) and i + 1 < len(children) else None
            if after is not None and isinstance(after[1], nn.BatchNorm3d) and after[1].track_running_stats:
                child = _fold_batchnorm(child, after[1])
                setattr(parent, after[0], nn.Identity())
            setattr(parent, name, Conv3dAs2d(child))
    return out
