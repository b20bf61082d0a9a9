import torch

from spacepose.models.upsample import UpsampleMaskHead, convex_upsample


def test_constant_disparity_is_scaled():
    disp = torch.full((2, 1, 4, 5), 3.0)
    up = convex_upsample(disp, torch.randn(2, 9 * 16, 4, 5), 4)
    assert up.shape == (2, 1, 16, 20)
    torch.testing.assert_close(up, torch.full_like(up, 12.0))


def test_peaked_mask_picks_centre_neighbour():
    disp = torch.randn(1, 1, 3, 3)
    mask = torch.full((1, 9, 4, 3, 3), -50.0)
    mask[:, 4] = 50.0  # neighbour 4 = centre
    up = convex_upsample(disp, mask.reshape(1, 36, 3, 3), 2)
    torch.testing.assert_close(up, 2 * disp.repeat_interleave(2, 2).repeat_interleave(2, 3), atol=1e-4, rtol=0)


def test_mask_head_shape():
    assert UpsampleMaskHead(8, 4)(torch.randn(1, 8, 5, 6)).shape == (1, 144, 5, 6)
