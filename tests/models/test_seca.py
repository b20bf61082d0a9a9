import torch

from spacepose.models.seca import SECA, EfficientChannelAttention3d, eca_kernel_size


def test_shapes_in_out_channels():
    x = torch.randn(2, 8, 4, 6, 6)
    assert SECA(8)(x).shape == x.shape
    assert SECA(8, 4)(x).shape == (2, 4, 4, 6, 6)
    assert SECA(8, 4, depthwise_qk=True)(x).shape == (2, 4, 4, 6, 6)


def test_depthwise_switch_changes_structure():
    full, dw = SECA(8), SECA(8, depthwise_qk=True)
    assert full.key[0].groups == 1 and dw.key[0].groups == 8
    assert full.key[0].kernel_size == (5, 5, 5) and full.query[0].kernel_size == (3, 3, 3)


def test_spatial_weights_softmax_over_dhw():
    seca = SECA(4)
    x = torch.randn(1, 4, 3, 5, 6)
    w = seca.spatial_weights(x)
    # softmax over the L = D*H*W positions per channel, scaled by L: mean weight 1
    torch.testing.assert_close(w.mean(dim=(2, 3, 4)), torch.ones(1, 4))
    assert (w >= 0).all()


def test_eca_kernel_and_gate():
    assert eca_kernel_size(16) == 3 and eca_kernel_size(64) == 3 and eca_kernel_size(256) == 5
    eca = EfficientChannelAttention3d(8)
    x = torch.randn(2, 8, 2, 3, 3)
    y = eca(x)
    ratio = y / x  # per-channel gate in (0, 1), constant over D, H, W
    assert ((ratio > 0) & (ratio < 1)).all()
    torch.testing.assert_close(ratio, ratio[..., :1, :1, :1].expand_as(ratio))
