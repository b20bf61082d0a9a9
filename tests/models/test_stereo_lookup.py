import torch
import torch.nn.functional as F

from spacepose.models.stereo_lookup import GeometryLookup, linear_lookup_1d


def _grid_sample_1d(volume, positions):
    """Reference: grid_sample on a (N, C, 1, L) image, zeros padding, align_corners=True."""
    length = volume.shape[-1]
    gx = 2.0 * positions / (length - 1) - 1.0
    grid = torch.stack([gx, torch.zeros_like(gx)], dim=-1).unsqueeze(1)  # (N, 1, K, 2)
    return F.grid_sample(volume.unsqueeze(2), grid, align_corners=True, padding_mode="zeros").squeeze(2)


def test_gather_lookup_matches_grid_sample():
    torch.manual_seed(0)
    volume = torch.randn(50, 3, 12)
    positions = torch.rand(50, 9) * 20.0 - 4.0  # includes out-of-range both sides
    positions[0, :3] = torch.tensor([0.0, 11.0, -1.0])  # exact ends
    torch.testing.assert_close(linear_lookup_1d(volume, positions), _grid_sample_1d(volume, positions), atol=1e-4, rtol=0)


def test_geometry_lookup_shape_and_centre_value():
    b, c0, d, h, w = 1, 2, 8, 3, 6
    gev = torch.randn(b, c0, d, h, w)
    corr = torch.randn(b, h, w, w)
    look = GeometryLookup(gev, corr, levels=2, radius=1)
    disp = torch.full((b, 1, h, w), 2.0)
    out = look(disp)
    assert out.shape == (b, 2 * 3 * (c0 + 1), h, w)
    # level 0, centre tap (k = 0) of channel 0 reads gev at disparity 2
    torch.testing.assert_close(out[0, 1, 1, 4], gev[0, 0, 2, 1, 4])
    # level 0 all-pairs centre tap reads corr at x - d
    torch.testing.assert_close(out[0, c0 * 3 + 1, 1, 4], corr[0, 1, 4, 2])
