"""Helpers shared by the export tests (not a test module)."""

import torch

from spacepose.models.pose_config import PoseNetConfig

#: a pose net small enough to export and recover in a second or two
TINY_POSE_NET = PoseNetConfig(crop_size=(64, 64), n_points=128, k=8, n_levels=2, ratio=4, rgb_stem=8,
                              rgb_widths=(16, 16), rgb_bottleneck=16, rgb_out=8, point_stem=8, point_widths=(16, 16),
                              point_bottleneck=16, head_width=16)


def randomise_batchnorm(model, seed):
    """Non-trivial BatchNorm statistics, as after training (folding then changes the conv weights); eval mode."""
    gen = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for m in model.modules():
            if isinstance(m, (torch.nn.BatchNorm1d, torch.nn.BatchNorm2d, torch.nn.BatchNorm3d)):
                m.weight.copy_(0.5 + torch.rand(m.weight.shape, generator=gen))
                m.bias.copy_(0.2 * torch.randn(m.bias.shape, generator=gen))
                m.running_mean.copy_(0.3 * torch.randn(m.running_mean.shape, generator=gen))
                m.running_var.copy_(0.5 + torch.rand(m.running_var.shape, generator=gen))
    return model.eval()
