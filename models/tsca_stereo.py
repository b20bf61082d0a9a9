"""TSCA-Stereo (paper §3.2): IGEV-Stereo with Triplet Attention in the context net and SECA +
depthwise-separable 3D convs in the regulariser; ``StereoConfig.variant`` picks the Table-4 variant.

``model(left, right, iters=None, test_mode=False)``:
left, right float32 (B, 3, H, W) RGB in [0, 255], H and W multiples of 32.
- train mode: ``(init_disp, preds)``; init_disp (B, 1, H, W), preds a list of ``iters`` tensors
  (B, 1, H, W); all in full-resolution input pixels (x_right = x_left - disparity).
- test_mode: only the final disparity (B, 1, H, W).
``iters=None`` means ``cfg.iters`` in test mode and ``cfg.train_iters`` otherwise.
The forward has no data-dependent control flow (exportable with a fixed iteration count).
"""

from __future__ import annotations

import torch
from torch import nn

from spacepose.errors import ShapeError
from spacepose.models.cost_volume import all_pairs_correlation, groupwise_correlation
from spacepose.models.regularizer import Regularizer
from spacepose.models.stereo_config import StereoConfig
from spacepose.models.stereo_context import ContextNetwork
from spacepose.models.stereo_features import FeatureNetwork
from spacepose.models.stereo_lookup import GeometryLookup
from spacepose.models.stereo_update import MultiLevelUpdate
from spacepose.models.upsample import UpsampleMaskHead, convex_upsample

__all__ = ["TSCAStereo"]

FACTOR = 4  # working resolution of volumes and the finest GRU is 1/4


def _check_pair(left: torch.Tensor, right: torch.Tensor) -> None:
    if left.dim() != 4 or left.shape[1] != 3 or left.shape != right.shape:
        raise ShapeError(f"left/right must both be (B, 3, H, W); got {tuple(left.shape)} and {tuple(right.shape)}")
    if left.shape[2] % 32 or left.shape[3] % 32:
        raise ShapeError(f"H and W must be multiples of 32; got {tuple(left.shape[2:])}")


class TSCAStereo(nn.Module):
    def __init__(self, cfg: StereoConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.features = FeatureNetwork(cfg.feature_widths, cfg.match_dim)
        self.context = ContextNetwork(cfg)
        self.regularizer = Regularizer(
            cfg.groups, cfg.reg_widths, cfg.feature_widths[1:], cfg.use_dwsep, cfg.use_seca,
            cfg.seca_depthwise_qk, cfg.seca_quarter_res,
        )
        self.init_mask = UpsampleMaskHead(cfg.feature_widths[1], FACTOR)
        self.update = MultiLevelUpdate(cfg, FACTOR)
        self.register_buffer(
            "disparities", torch.arange(cfg.num_disp, dtype=torch.float32).view(1, -1, 1, 1), persistent=False
        )

    @staticmethod
    def normalise(image: torch.Tensor) -> torch.Tensor:
        """[0, 255] -> [-1, 1]."""
        return image * (2.0 / 255.0) - 1.0

    def initial_disparity(self, gev: torch.Tensor) -> torch.Tensor:
        """Soft-argmin over the classifier's disparity softmax: GEV -> (B, 1, H/4, W/4) (1/4 px)."""
        prob = torch.softmax(self.regularizer.classify(gev), dim=1)
        return (prob * self.disparities).sum(dim=1, keepdim=True)

    def forward(
        self, left: torch.Tensor, right: torch.Tensor, iters: int | None = None, test_mode: bool = False
    ) -> torch.Tensor | tuple[torch.Tensor, list[torch.Tensor]]:
        _check_pair(left, right)
        n_iters = (self.cfg.iters if test_mode else self.cfg.train_iters) if iters is None else int(iters)
        if n_iters < 0 or (n_iters == 0 and not test_mode):
            raise ValueError(f"iters must be >= 1 in training (>= 0 in test mode); got {n_iters}")
        left_n, right_n = self.normalise(left), self.normalise(right)
        b = left.shape[0]

        feats = self.features(torch.cat([left_n, right_n], dim=0))
        match_left, match_right = feats.matching[:b], feats.matching[b:]
        guide = [f[:b] for f in feats.pyramid]

        volume = groupwise_correlation(match_left, match_right, self.cfg.groups, self.cfg.num_disp)
        gev = self.regularizer(volume, guide)
        disp = self.initial_disparity(gev)
        init_up = convex_upsample(disp, self.init_mask(guide[0]), FACTOR)

        context = self.context(left_n)
        hidden = context.hidden
        lookup = GeometryLookup(
            gev, all_pairs_correlation(match_left, match_right), self.cfg.corr_levels, self.cfg.corr_radius
        )
        preds: list[torch.Tensor] = []
        for k in range(n_iters):
            disp = disp.detach()
            hidden, delta = self.update(hidden, context.biases, lookup(disp), disp)
            disp = disp + delta
            if test_mode and k < n_iters - 1:
                continue  # only the last iteration is upsampled at inference
            preds.append(convex_upsample(disp, self.update.upsample_mask(hidden[0]), FACTOR))
        if test_mode:
            return preds[-1] if preds else init_up
        return init_up, preds
