import torch

from spacepose.models.cost_volume import all_pairs_correlation, groupwise_correlation


def test_groupwise_matches_naive_loop():
    torch.manual_seed(0)
    b, c, h, w, g, d_max = 2, 8, 3, 7, 4, 5
    left, right = torch.randn(b, c, h, w), torch.randn(b, c, h, w)
    vol = groupwise_correlation(left, right, g, d_max)
    assert vol.shape == (b, g, d_max, h, w)
    ref = torch.zeros_like(vol)
    per = c // g
    for gi in range(g):
        for d in range(d_max):
            for x in range(d, w):
                ref[:, gi, d, :, x] = (left[:, gi * per : (gi + 1) * per, :, x] * right[:, gi * per : (gi + 1) * per, :, x - d]).mean(1)
    torch.testing.assert_close(vol, ref)


def test_all_pairs_matches_einsum():
    left, right = torch.randn(2, 6, 3, 5), torch.randn(2, 6, 3, 5)
    ref = torch.einsum("bchx,bchy->bhxy", left, right) / 6
    torch.testing.assert_close(all_pairs_correlation(left, right), ref)
