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
26.4 -> 22.1 ms (torch 11.3). 1x1x1 layers already run as one GEMM and stay. Layers with fewer than
:data:`MIN_OUT_CHANNELS` outputs (the disparity classifier) become :class:`NarrowConv3dAs2d`: one 2-D
convolution with the depth taps stacked as its outputs. In separate processes on 2 threads (session
13 scratch timing) the dense 16-channel layer took 7.4-8.0 ms in this form against torch eager's
9.2-12.4 ms.

:class:`ConvTranspose3dAs2d` does the same for a ``ConvTranspose3d`` (the regulariser's decoder
upsamplers, 4x4x4 with stride 2): one ``ConvTranspose2d`` per depth tap over all input slices, the
taps summed into the output slices they reach (each output slice gets the taps of its phase, shifted
by whole slices). onnxruntime runs a 3-D ``ConvTranspose`` through col2im one group at a time; with its
memory arena the decoder's took 17.5 of the stereo graph's ~130 ms kernel time, the 2-D form 8.0 ms
(``python -m spacepose.tools.profile_graph_ops``, 2 threads; session 13).

The dense 3x3x3 convolutions with depth stride 1 (the regulariser's stem and its 1/4-resolution
decoder) can instead become :class:`WinogradConv3dAs2d`: Winograd's minimal filtering F(4, 3) along
depth only. Each tile of 4 output slices needs 6 tap-combined 2-D convolutions instead of 12 (run as
one grouped convolution), the depth transforms are two constant ``MatMul`` calls, and the result is
the same function up to float rounding (1e-5 relative). The dense 16-channel layer at 24x64x64 took
4.7-5.2 ms in this form (six convolutions; grouped, 1.2x less again) against 7.2-7.3 ms per tap and
torch eager's 4.3-5.1 ms (2 threads, session 14 scratch timing).

:class:`PolyphaseConvTranspose3dAs2d` replaces :class:`ConvTranspose3dAs2d` for the ungrouped transposed
convolutions whose kernel is a multiple of their stride (the decoder's 4x4x4, stride 2): every output
phase of a strided transposed convolution is a plain correlation, so one 2-D convolution over windows of
adjacent depth slices (stacked as channels) gives all phases at once, and a grouped 0/1 ``ConvTranspose2d``
interleaves the spatial ones. No col2im runs over the data: the decoder's 1/4-resolution upsampler took
2.6 ms instead of 7.6 ms (torch eager 2.3-2.4 ms).

Only the export uses this: training and the torch-eager baseline run the original layers, and the
export's parity check (torch original vs onnxruntime rewritten) guards the equivalence.
"""

from __future__ import annotations

import copy
import functools

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["Conv3dAs2d", "ConvTranspose3dAs2d", "NarrowConv3dAs2d", "WinogradConv3dAs2d",
           "PolyphaseConvTranspose3dAs2d", "rewrite_conv3d", "wants_rewrite", "wants_transposed_rewrite",
           "wants_narrow_rewrite", "wants_winograd_rewrite", "wants_polyphase_rewrite", "polyphase_kernel_index",
           "winograd_depth_transforms", "WINOGRAD_BT", "WINOGRAD_G", "WINOGRAD_AT", "MIN_OUT_CHANNELS"]

#: narrower layers (the 1-channel disparity classifier) are not split into per-tap 2-D convolutions:
#: onnxruntime's blocked 2-D kernels need 8 or 16 output channels, and the plain path is slower than
#: its Conv3d. :class:`NarrowConv3dAs2d` stacks their depth taps as output channels instead
MIN_OUT_CHANNELS = 8


def _expressible(module: nn.Module) -> bool:
    """Zero padding given as numbers and no dilation: what the 2-D forms below can express."""
    return (not isinstance(module.padding, str) and module.padding_mode == "zeros"
            and tuple(module.dilation) == (1, 1, 1))


class _DepthTaps(nn.Module):
    """What the 2-D forms share: a 3-D (transposed) convolution's depth kernel size, stride, padding,
    groups and out channels, and its weight and bias, kept in the original layout (the state dict is
    the original's; tap j is ``weight[:, :, j]``)."""

    def __init__(self, conv: nn.Conv3d | nn.ConvTranspose3d) -> None:
        super().__init__()
        if not _expressible(conv):
            raise ValueError(f"{type(self).__name__} needs zero padding given as numbers and no dilation")
        weight = conv.weight.detach()
        self.kd = int(weight.shape[2])
        self.stride = tuple(int(s) for s in conv.stride)
        self.padding = tuple(int(p) for p in conv.padding)
        self.groups = int(conv.groups)
        self.out_channels = int(conv.out_channels)
        self.weight = nn.Parameter(weight.clone(), requires_grad=False)
        self.bias = None if conv.bias is None else nn.Parameter(conv.bias.detach().clone(), requires_grad=False)

    def _depth_first(self, x: torch.Tensor) -> torch.Tensor:
        """(B, C, D, H, W) -> (B, D + 2 p_d, C, H, W), zero-padded in depth."""
        pd = self.padding[0]
        xt = x.transpose(1, 2)
        return F.pad(xt, (0, 0, 0, 0, 0, 0, pd, pd)) if pd else xt


class Conv3dAs2d(_DepthTaps):
    """The map of ``conv`` (an ``nn.Conv3d`` with zero padding given as numbers and no dilation):
    (B, C, D, H, W) -> (B, C_out, D', H', W'), computed with ``k_d`` grouped ``Conv2d`` calls."""

    def __init__(self, conv: nn.Conv3d) -> None:
        super().__init__(conv)                                          # weight (C_out, C_in / g, kd, kh, kw)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, c, d, h, w = x.shape
        pd, ph, pw = self.padding
        sd, sh, sw = self.stride
        xt = self._depth_first(x)                                      # (B, D + 2 pd, C, H, W)
        d_out = (d + 2 * pd - self.kd) // sd + 1
        out = None
        for j in range(self.kd):
            taps = xt[:, j: j + sd * (d_out - 1) + 1: sd].reshape(b * d_out, c, h, w)
            y = F.conv2d(taps, self.weight[:, :, j], self.bias if j == 0 else None, (sh, sw), (ph, pw), 1, self.groups)
            out = y if out is None else out + y
        return out.reshape((b, d_out, self.out_channels) + tuple(out.shape[-2:])).transpose(1, 2)


class ConvTranspose3dAs2d(_DepthTaps):
    """The map of ``conv`` (an ``nn.ConvTranspose3d`` with zero padding and no dilation):
    (B, C, D, H, W) -> (B, C_out, D', H', W') with D' = (D - 1) s_d - 2 p_d + k_d + op_d, computed with
    ``k_d`` grouped ``ConvTranspose2d`` calls.

    Depth tap j of input slice m lands on output slice ``m s_d - p_d + j``. Output slice
    ``o = i s_d + k`` (phase k of block i) thus sums the taps ``j = r + q s_d`` (``r = (k + p_d) mod s_d``)
    of input slices ``i + (k + p_d) div s_d - q``: whole-slice shifts of each tap's 2-D result.
    """

    def __init__(self, conv: nn.ConvTranspose3d) -> None:
        super().__init__(conv)                                          # weight (C_in, C_out / g, kd, kh, kw)
        self.output_padding = tuple(int(p) for p in conv.output_padding)

    @staticmethod
    def _shifted(y: torch.Tensor, shift: int, length: int) -> torch.Tensor | None:
        """z (B, length, ...) with z[:, i] = y[:, i + shift] where that slice exists, else zeros; None
        when no slice of y lands in range."""
        lo, hi = max(0, -shift), min(length, y.shape[1] - shift)        # i range reading y
        if hi <= lo:
            return None
        z = y[:, lo + shift: hi + shift]
        parts = []
        if lo:
            parts.append(torch.zeros_like(y[:, :1]).expand(-1, lo, -1, -1, -1))
        parts.append(z)
        if length - hi:
            parts.append(torch.zeros_like(y[:, :1]).expand(-1, length - hi, -1, -1, -1))
        return parts[0] if len(parts) == 1 else torch.cat(parts, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, c, d, h, w = x.shape
        sd, sh, sw = self.stride
        pd, ph, pw = self.padding
        opd, oph, opw = self.output_padding
        xs = x.transpose(1, 2).reshape(b * d, c, h, w)
        taps = []
        for j in range(self.kd):
            y = F.conv_transpose2d(xs, self.weight[:, :, j], None, (sh, sw), (ph, pw), (oph, opw), self.groups)
            taps.append(y.reshape((b, d) + tuple(y.shape[1:])))
        d_out = (d - 1) * sd - 2 * pd + self.kd + opd
        blocks = -(-d_out // sd)
        phases = []
        for k in range(sd):
            r, base = (k + pd) % sd, (k + pd) // sd
            acc = None
            for j in range(r, self.kd, sd):
                part = self._shifted(taps[j], base - (j - r) // sd, blocks)
                if part is not None:
                    acc = part if acc is None else acc + part
            phases.append(torch.zeros_like(taps[0][:, :1]).expand(-1, blocks, -1, -1, -1) if acc is None else acc)
        out = phases[0] if sd == 1 else torch.stack(phases, 2).reshape((b, blocks * sd) + tuple(phases[0].shape[2:]))
        if blocks * sd != d_out:
            out = out[:, :d_out]
        out = out.transpose(1, 2)
        return out if self.bias is None else out + self.bias.reshape(1, -1, 1, 1, 1)


class NarrowConv3dAs2d(_DepthTaps):
    """The map of ``conv`` (an ungrouped ``nn.Conv3d`` with few outputs, zero padding, no dilation):
    (B, C, D, H, W) -> (B, C_out, D', H', W'), computed with one ``Conv2d`` whose ``k_d * C_out``
    outputs are the depth taps, over every (padded) input slice; output slice o sums tap j of input
    slice ``o s_d + j``. For the classifier (16 -> 1, 3x3x3, at 24x64x64) onnxruntime takes 3.0-3.2 ms
    instead of 5.3 ms (2 threads, session 13 scratch timing)."""

    def __init__(self, conv: nn.Conv3d) -> None:
        if conv.groups != 1:
            raise ValueError("NarrowConv3dAs2d needs an ungrouped convolution")
        super().__init__(conv)                                          # weight (C_out, C_in, kd, kh, kw)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, c, d, h, w = x.shape
        pd, ph, pw = self.padding
        sd, sh, sw = self.stride
        xt = self._depth_first(x)                                      # (B, D + 2 pd, C, H, W)
        dp = d + 2 * pd
        d_out = (dp - self.kd) // sd + 1
        c_in, kh, kw = self.weight.shape[1], self.weight.shape[3], self.weight.shape[4]
        stacked = self.weight.permute(2, 0, 1, 3, 4).reshape(self.kd * self.out_channels, c_in, kh, kw)
        y = F.conv2d(xt.reshape(b * dp, c, h, w), stacked, None, (sh, sw), (ph, pw))
        y = y.reshape((b, dp, self.kd, self.out_channels) + tuple(y.shape[-2:]))
        out = None
        for j in range(self.kd):
            tap = y[:, j: j + sd * (d_out - 1) + 1: sd, j]
            out = tap if out is None else out + tap
        out = out.transpose(1, 2)
        return out if self.bias is None else out + self.bias.reshape(1, -1, 1, 1, 1)


#: Winograd F(4, 3) (Lavin & Gray 2016, points 0, +-1, +-2, infinity): for a 3-tap filter g and 6 inputs d,
#: the 4 outputs ``y_i = sum_k g_k d_{i+k}`` are ``WINOGRAD_AT @ ((WINOGRAD_G @ g) * (WINOGRAD_BT @ d))``
WINOGRAD_BT = np.array([[4, 0, -5, 0, 1, 0], [0, -4, -4, 1, 1, 0], [0, 4, -4, -1, 1, 0],
                        [0, -2, -1, 2, 1, 0], [0, 2, -1, -2, 1, 0], [0, 4, 0, -5, 0, 1]], dtype=np.float64)
WINOGRAD_G = np.array([[1 / 4, 0, 0], [-1 / 6, -1 / 6, -1 / 6], [-1 / 6, 1 / 6, -1 / 6],
                       [1 / 24, 1 / 12, 1 / 6], [1 / 24, -1 / 12, 1 / 6], [0, 0, 1]], dtype=np.float64)
WINOGRAD_AT = np.array([[1, 1, 1, 1, 1, 0], [0, 1, -1, 2, -2, 0], [0, 1, 1, 4, 4, 0], [0, 1, -1, 8, -8, 1]],
                       dtype=np.float64)
_TILE, _POINTS = WINOGRAD_AT.shape


@functools.lru_cache(maxsize=None)
def winograd_depth_transforms(depth: int, pad: int) -> tuple[np.ndarray, np.ndarray]:
    """The depth transforms of :class:`WinogradConv3dAs2d` for ``depth`` input slices zero-padded by
    ``pad`` on each side: ``T_in`` (6 n, depth) and ``T_out`` (depth + 2 pad - 2, 6 n), float32, with
    n = ceil(outputs / 4) tiles. Row ``6 t + k`` of ``T_in @ x`` is point k of tile t; the padding is
    the columns left out, and the last tile's outputs beyond the end are rows left out."""
    d_out = depth + 2 * pad - 2
    if depth < 1 or pad < 0 or d_out < 1:
        raise ValueError(f"no 3-tap output for depth {depth} with padding {pad}")
    n = -(-d_out // _TILE)
    t_in = np.zeros((_POINTS * n, depth))
    t_out = np.zeros((d_out, _POINTS * n))
    for t in range(n):
        for k in range(_POINTS):
            for j in range(_POINTS):
                if 0 <= t * _TILE + j - pad < depth:
                    t_in[_POINTS * t + k, t * _TILE + j - pad] = WINOGRAD_BT[k, j]
            for i in range(min(_TILE, d_out - t * _TILE)):
                t_out[t * _TILE + i, _POINTS * t + k] = WINOGRAD_AT[i, k]
    t_in, t_out = t_in.astype(np.float32), t_out.astype(np.float32)
    t_in.setflags(write=False)
    t_out.setflags(write=False)
    return t_in, t_out


class WinogradConv3dAs2d(_DepthTaps):
    """The map of ``conv`` (an ``nn.Conv3d`` with 3 depth taps, depth stride 1, zero padding given as
    numbers, no dilation): (B, C, D, H, W) -> (B, C_out, D', H', W'), computed with Winograd F(4, 3)
    along depth (module docstring): the depth transform ``T_in`` (one ``MatMul``), whose 6 points per
    tile become channel groups of ONE grouped ``Conv2d`` over all tiles (group k holds the transformed
    kernel ``WINOGRAD_G[k] @ taps``), and ``T_out`` (one ``MatMul``). One convolution instead of six
    spares onnxruntime a slice and a layout reorder per point (1.2x on the regulariser's stem layer).
    Equal to ``conv`` up to float rounding. The state dict is the original's."""

    def __init__(self, conv: nn.Conv3d) -> None:
        super().__init__(conv)                                          # weight (C_out, C_in / g, 3, kh, kw)
        if self.kd != 3 or self.stride[0] != 1:
            raise ValueError("WinogradConv3dAs2d needs 3 depth taps and depth stride 1")

    def _kernels(self) -> torch.Tensor:
        """The transformed kernels stacked, (6 C_out, C_in / g, kh, kw): rows ``k C_out ..`` hold
        ``sum_j WINOGRAD_G[k, j] weight[:, :, j]``. Computed from the weight, so that the export folds
        them into one initializer."""
        return torch.cat([functools.reduce(torch.add, [float(c) * self.weight[:, :, j]
                                                       for j, c in enumerate(row) if c != 0.0])
                          for row in WINOGRAD_G])

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, c, d, h, w = x.shape
        pd, ph, pw = self.padding
        _, sh, sw = self.stride
        t_in, t_out = (torch.from_numpy(m.copy()).to(x.dtype) for m in winograd_depth_transforms(d, pd))
        n = t_in.shape[0] // _POINTS
        u = torch.matmul(t_in, x.transpose(1, 2).reshape(b, d, c * h * w))              # (B, 6 n, C H W)
        m = F.conv2d(u.reshape(b * n, _POINTS * c, h, w), self._kernels(), None, (sh, sw), (ph, pw), 1,
                     _POINTS * self.groups)                                             # (B n, 6 C_out, H', W')
        co, ho, wo = m.shape[1] // _POINTS, m.shape[2], m.shape[3]
        y = torch.matmul(t_out, m.reshape(b, n * _POINTS, co * ho * wo))
        y = y.reshape(b, t_out.shape[0], co, ho, wo).transpose(1, 2)
        return y if self.bias is None else y + self.bias.reshape(1, -1, 1, 1, 1)


def _window_plan(n_in: int, n_out: int, k: int, s: int, p: int) -> tuple[int, int, int, int, int]:
    """How :class:`PolyphaseConvTranspose3dAs2d` covers one axis of a transposed convolution (kernel
    ``k`` = q s, stride ``s``, padding ``p``; ``n_in`` inputs, ``n_out`` outputs): ``(left, right, start,
    windows, phase_pad)``. Window g (of ``windows``) reads inputs ``g + p // s - q + 1 + t`` (t < q), i.e.
    the axis zero-padded by ``left`` and ``right`` from index ``start + g`` on; its ``s`` results, slot
    sigma, are output ``s g + sigma - phase_pad`` (phase_pad = p mod s), so slots ``phase_pad ..
    phase_pad + n_out - 1`` of the windows in order are the outputs in order."""
    q, phase_pad = k // s, p % s
    first = p // s - q + 1                                              # input read by tap 0 of window 0
    left, start = max(0, -first), max(0, first)
    windows = -(-(n_out + 2 * phase_pad) // s)                          # the shuffle crops phase_pad each side
    right = max(0, start + windows + q - 1 - (n_in + left))
    return left, right, start, windows, phase_pad


def polyphase_kernel_index(shape: tuple[int, ...], stride: tuple[int, int, int]) -> np.ndarray:
    """Where :class:`PolyphaseConvTranspose3dAs2d` takes each value of its 2-D kernel from: an int64
    array of the kernel's shape (s_d C_out s_h s_w, q_d C_in, q_h, q_w) holding flat indices into a
    ``ConvTranspose3d`` weight of ``shape`` (C_in, C_out, k_d, k_h, k_w), k = q s in every axis. Entry
    (sigma_d, c, sigma_h, sigma_w, t_d, i, t_h, t_w) is weight[i, c, sigma_d + (q_d - 1 - t_d) s_d, ...]
    (slot sigma of window member t). Every weight value appears exactly once, which is how
    :mod:`spacepose.export.recover` reads the weight back."""
    c_in, c_out, *k = (int(v) for v in shape)
    s = [int(v) for v in stride]
    if any(kk % ss for kk, ss in zip(k, s)):
        raise ValueError(f"kernel {tuple(k)} is not a multiple of stride {tuple(s)}")
    q = [kk // ss for kk, ss in zip(k, s)]
    taps = [np.add.outer(np.arange(ss), (qq - 1 - np.arange(qq)) * ss) for ss, qq in zip(s, q)]  # (sigma, t) -> tap
    idx = np.arange(c_in * c_out * k[0] * k[1] * k[2]).reshape(c_in, c_out, *k)
    # idx[i, c, taps_d[sd, td], taps_h[sh, th], taps_w[sw, tw]] laid out (sd, c, sh, sw, td, i, th, tw)
    g = idx[:, :, taps[0]][:, :, :, :, taps[1]][:, :, :, :, :, :, taps[2]]  # (i, c, sd, td, sh, th, sw, tw)
    return np.ascontiguousarray(g.transpose(2, 1, 4, 6, 3, 0, 5, 7)).reshape(
        s[0] * c_out * s[1] * s[2], q[0] * c_in, q[1], q[2])


class PolyphaseConvTranspose3dAs2d(_DepthTaps):
    """The map of ``conv`` (an ungrouped ``nn.ConvTranspose3d`` whose kernel is a multiple of its stride
    in every axis, k = q s, with zero padding and no dilation): (B, C, D, H, W) -> (B, C_out, D', H', W'),
    computed as ONE ``Conv2d`` and one pixel shuffle, with no col2im over the data.

    Each output of a transposed convolution with stride s is one of s phases, and phase sigma is a
    plain q-tap correlation of the input (:func:`_window_plan`). So each window of q x q x q inputs gives
    all s_d s_h s_w phases of one output block at once: the q depth slices of a window are stacked as
    channels, a 2-D convolution with a q_h x q_w kernel (:func:`polyphase_kernel_index`, a permutation of
    the weight) gives (s_d, C_out, s_h, s_w) channels per window, the depth slots in order are the output
    slices, and a grouped ``ConvTranspose2d`` with a 0/1 selection kernel (s_h x s_w, stride s, one
    group per output channel; no overlapping taps) interleaves the spatial phases and adds the bias.
    Exact up to float rounding. The decoder's ``ConvTranspose3d(4, 2, 1)`` at 12x32x32 -> 24x64x64,
    16 channels, took 2.6 ms in this form against 7.6 ms for :class:`ConvTranspose3dAs2d` and 2.3-2.4 ms
    for torch eager (2 threads, session 15 scratch timing). The state dict is the original's."""

    def __init__(self, conv: nn.ConvTranspose3d) -> None:
        if conv.groups != 1:
            raise ValueError("PolyphaseConvTranspose3dAs2d needs an ungrouped transposed convolution")
        if any(k % s for k, s in zip(conv.kernel_size, conv.stride)):
            raise ValueError(f"PolyphaseConvTranspose3dAs2d needs a kernel that is a multiple of the stride, got "
                             f"{tuple(conv.kernel_size)} and {tuple(conv.stride)}")
        super().__init__(conv)                                          # weight (C_in, C_out, kd, kh, kw)
        self.output_padding = tuple(int(p) for p in conv.output_padding)
        self.kernel = tuple(int(k) for k in conv.kernel_size)
        sd, sh, sw = self.stride
        select = torch.zeros(self.out_channels * sh * sw, 1, sh, sw)
        for i in range(sh):
            for j in range(sw):
                select[i * sw + j:: sh * sw, 0, i, j] = 1.0
        self.register_buffer("select", select, persistent=False)

    def _kernel2d(self) -> torch.Tensor:
        """The 2-D kernel (s_d C_out s_h s_w, q_d C_in, q_h, q_w), ``weight.flat[polyphase_kernel_index(...)]``
        written as a reshape, a reversal of the tap axes by slices and a permutation of the weight (tap
        j = sigma + (q - 1 - t) s), which the export folds into one initializer."""
        c_in, c_out = self.weight.shape[:2]
        (qd, qh, qw), (sd, sh, sw) = (k // s for k, s in zip(self.kernel, self.stride)), self.stride
        w = self.weight.reshape(c_in, c_out, qd, sd, qh, sh, qw, sw)
        for axis, q in ((2, qd), (4, qh), (6, qw)):                    # reversed by slices (``flip`` does not fold)
            if q > 1:
                w = torch.cat([w.narrow(axis, q - 1 - t, 1) for t in range(q)], axis)
        return w.permute(3, 1, 5, 7, 2, 0, 4, 6).reshape(sd * c_out * sh * sw, qd * c_in, qh, qw)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, c, d, h, w = (int(v) for v in x.shape)                      # plain ints: the ONNX trace sees constants
        co, (sd, sh, sw), kernel = self.out_channels, self.stride, self.kernel
        size = [(n - 1) * s - 2 * p + k + op for n, s, p, k, op in
                zip((d, h, w), self.stride, self.padding, kernel, self.output_padding)]
        plan = [_window_plan(n, o, k, s, p) for n, o, k, s, p in
                zip((d, h, w), size, kernel, self.stride, self.padding)]
        qd = kernel[0] // sd
        (ld, rd, st_d, gd, pd), (lh, rh, st_h, gh, ph), (lw, rw, st_w, gw, pw) = plan
        xt = x.transpose(1, 2)
        if lw or rw or lh or rh or ld or rd:
            xt = F.pad(xt, (lw, rw, lh, rh, 0, 0, ld, rd))              # (B, D', C, H', W')
        ends = (st_h + gh + kernel[1] // sh - 1, st_w + gw + kernel[2] // sw - 1)
        if st_h or st_w or ends != tuple(xt.shape[-2:]):
            xt = xt[..., st_h: ends[0], st_w: ends[1]]
        stacked = torch.cat([xt[:, st_d + t: st_d + t + gd] for t in range(qd)], 2)
        z = F.conv2d(stacked.reshape(b * gd, qd * c, ends[0] - st_h, ends[1] - st_w), self._kernel2d())
        z = z.reshape(b, gd * sd, co * sh * sw, gh, gw)[:, pd: pd + size[0]]
        z = z.reshape(b * size[0], co * sh * sw, gh, gw)
        if sh * sw > 1:
            y = F.conv_transpose2d(z, self.select, self.bias, (sh, sw), (ph, pw), groups=co)
            if tuple(y.shape[-2:]) != tuple(size[1:]):
                y = y[:, :, :size[1], :size[2]]
        else:
            y = z if self.bias is None else z + self.bias.reshape(1, -1, 1, 1)
        return y.reshape(b, size[0], co, size[1], size[2]).transpose(1, 2)


def wants_narrow_rewrite(module: nn.Module) -> bool:
    """True for the Conv3d layers ``rewrite_conv3d(..., narrow=True)`` gives to :class:`NarrowConv3dAs2d`:
    ungrouped, fewer than :data:`MIN_OUT_CHANNELS` outputs, a kernel deeper than 1, zero padding given
    as numbers, no dilation."""
    return (isinstance(module, nn.Conv3d) and _expressible(module) and module.groups == 1
            and module.out_channels < MIN_OUT_CHANNELS and module.kernel_size[0] > 1)


def wants_transposed_rewrite(module: nn.Module) -> bool:
    """True for the ConvTranspose3d layers ``rewrite_conv3d(..., transposed=True)`` replaces: zero
    padding given as numbers, no dilation."""
    return isinstance(module, nn.ConvTranspose3d) and _expressible(module)


def wants_polyphase_rewrite(module: nn.Module) -> bool:
    """True for the ConvTranspose3d layers ``rewrite_conv3d(..., polyphase=True)`` gives to
    :class:`PolyphaseConvTranspose3dAs2d`: what :func:`wants_transposed_rewrite` accepts, ungrouped, with
    a kernel that is a multiple of the stride in every axis."""
    return (wants_transposed_rewrite(module) and module.groups == 1
            and all(k % s == 0 for k, s in zip(module.kernel_size, module.stride)))


def wants_winograd_rewrite(module: nn.Module) -> bool:
    """True for the Conv3d layers ``rewrite_conv3d(..., winograd=True)`` gives to :class:`WinogradConv3dAs2d`:
    what :func:`wants_rewrite` accepts, ungrouped (dense), with 3 depth taps and depth stride 1."""
    return (wants_rewrite(module) and module.groups == 1 and module.kernel_size[0] == 3
            and module.stride[0] == 1)


def wants_rewrite(module: nn.Module) -> bool:
    """True for the Conv3d layers :func:`rewrite_conv3d` replaces: a kernel wider than 1x1x1 (or a depth
    stride), at least :data:`MIN_OUT_CHANNELS` outputs, zero padding given as numbers, no dilation."""
    return (isinstance(module, nn.Conv3d) and _expressible(module)
            and module.out_channels >= MIN_OUT_CHANNELS
            and (module.kernel_size != (1, 1, 1) or module.stride[0] > 1))


def _fold_batchnorm(conv: nn.Conv3d | nn.ConvTranspose3d, bn: nn.BatchNorm3d) -> nn.Module:
    """A copy of ``conv`` computing ``bn(conv(x))`` in eval mode (what the ONNX exporter does when the
    BatchNorm directly follows a Conv, which it no longer does once the Conv is rewritten)."""
    scale = bn.weight.detach() / torch.sqrt(bn.running_var + bn.eps) if bn.affine else 1.0 / torch.sqrt(bn.running_var + bn.eps)
    shift = bn.bias.detach() if bn.affine else torch.zeros_like(bn.running_mean)
    folded = copy.deepcopy(conv)
    bias = conv.bias.detach() if conv.bias is not None else torch.zeros_like(bn.running_mean)
    if isinstance(conv, nn.ConvTranspose3d):                           # weight (C_in, C_out / g, ...)
        g, per = conv.groups, conv.out_channels // conv.groups
        w = conv.weight.detach().reshape((g, -1, per) + tuple(conv.weight.shape[2:]))
        w = w * scale.reshape(g, 1, per, 1, 1, 1)
        folded.weight = nn.Parameter(w.reshape(conv.weight.shape), requires_grad=False)
    else:
        folded.weight = nn.Parameter(conv.weight.detach() * scale.reshape(-1, 1, 1, 1, 1), requires_grad=False)
    folded.bias = nn.Parameter((bias - bn.running_mean) * scale + shift, requires_grad=False)
    return folded


def rewrite_conv3d(module: nn.Module, *, convs: bool = True, transposed: bool = False,
                   narrow: bool = False, winograd: bool = False, polyphase: bool = False) -> nn.Module:
    """A deep copy of ``module`` in eval mode in which, with ``winograd``, every layer
    :func:`wants_winograd_rewrite` accepts is replaced by :class:`WinogradConv3dAs2d`, with ``convs``
    every other one :func:`wants_rewrite` accepts by :class:`Conv3dAs2d`, with ``polyphase`` every one
    :func:`wants_polyphase_rewrite` accepts by :class:`PolyphaseConvTranspose3dAs2d`, with ``transposed``
    every other one :func:`wants_transposed_rewrite` accepts by :class:`ConvTranspose3dAs2d`, and with
    ``narrow`` every one :func:`wants_narrow_rewrite` accepts by :class:`NarrowConv3dAs2d` (``module``
    itself is left untouched). A ``BatchNorm3d`` (with running statistics) that directly follows such a
    layer in an ``nn.Sequential`` is folded into it and becomes ``nn.Identity``."""
    def replacement(layer: nn.Module) -> type[nn.Module] | None:
        if winograd and wants_winograd_rewrite(layer):
            return WinogradConv3dAs2d
        if convs and wants_rewrite(layer):
            return Conv3dAs2d
        if narrow and wants_narrow_rewrite(layer):
            return NarrowConv3dAs2d
        if polyphase and wants_polyphase_rewrite(layer):
            return PolyphaseConvTranspose3dAs2d
        return ConvTranspose3dAs2d if transposed and wants_transposed_rewrite(layer) else None

    out = copy.deepcopy(module).eval()
    if (kind := replacement(out)) is not None:
        return kind(out)
    for parent in list(out.modules()):
        children = list(parent.named_children())
        for i, (name, child) in enumerate(children):
            if (kind := replacement(child)) is None:
                continue
            after = children[i + 1] if isinstance(parent, nn.Sequential) and i + 1 < len(children) else None
            if after is not None and isinstance(after[1], nn.BatchNorm3d) and after[1].track_running_stats:
                child = _fold_batchnorm(child, after[1])
                setattr(parent, after[0], nn.Identity())
            setattr(parent, name, kind(child))
    return out
