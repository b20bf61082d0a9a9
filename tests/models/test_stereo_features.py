import torch

from spacepose.models.stereo_features import FeatureNetwork, ResidualBlock


def test_feature_pyramid_shapes():
    net = FeatureNetwork((8, 12, 16, 20, 24), match_dim=32)
    out = net(torch.randn(2, 3, 64, 96))
    assert [tuple(f.shape) for f in out.pyramid] == [(2, 12, 16, 24), (2, 16, 8, 12), (2, 20, 4, 6), (2, 24, 2, 3)]
    assert out.matching.shape == (2, 32, 16, 24)


def test_residual_block_stride():
    assert ResidualBlock(4, 8, 2)(torch.randn(1, 4, 8, 8)).shape == (1, 8, 4, 4)
    assert isinstance(ResidualBlock(4, 4).skip, torch.nn.Identity)
