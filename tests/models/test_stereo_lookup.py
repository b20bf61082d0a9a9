import torch
import torch.nn.functional as F

from spacepose.models.stereo_lookup import GeometryLookup, linear_lookup_1d, window_lookup_1d


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


def test_window_lookup_matches_grid_sample():
    torch.manual_seed(1)
    c, length, n, r = 3, 12, 40, 4
    volume = torch.randn(c, length, n)
    centre = torch.rand(n) * 24.0 - 6.0                   # windows leave the volume on both sides
    centre[:3] = torch.tensor([0.0, 11.0, 5.0])           # integer centres (fraction 0)
    positions = centre[:, None] + torch.arange(-r, r + 1, dtype=torch.float32)[None]  # (N, 2r+1)
    want = _grid_sample_1d(volume.permute(2, 0, 1), positions).permute(1, 2, 0)     # (C, 2r+1, N)
    torch.testing.assert_close(window_lookup_1d(volume, centre, r), want, atol=1e-5, rtol=0)


def test_geometry_lookup_matches_per_pixel_linear_lookup():
    """The channel order of the batched lookup: per level c0 * (2r+1) GEV taps then 2r+1 all-pairs taps,
    against linear_lookup_1d pixel by pixel (batch 2, 3 levels)."""
    torch.manual_seed(2)
    b, c0, d, h, w, r = 2, 3, 16, 2, 5, 2
    gev, corr = torch.randn(b, c0, d, h, w), torch.randn(b, h, w, w)
    disp = torch.rand(b, 1, h, w) * 12.0 - 1.0
    out = GeometryLookup(gev, corr, levels=3, radius=r)(disp)
    offsets = torch.arange(-r, r + 1, dtype=torch.float32)
    for bi in range(b):
        for y in range(h):
            for x in range(w):
                dv = float(disp[bi, 0, y, x])
                g, cr, want = gev[bi, :, :, y, x][None], corr[bi, y, x][None, None], []
                for level in range(3):
                    s = 1.0 / 2**level
                    want.append(linear_lookup_1d(g, (dv * s + offsets)[None]).flatten())
                    want.append(linear_lookup_1d(cr, ((x - dv) * s + offsets)[None]).flatten())
                    if level < 2:
                        g, cr = F.avg_pool1d(g, 2, 2), F.avg_pool1d(cr, 2, 2)
                torch.testing.assert_close(out[bi, :, y, x], torch.cat(want), atol=1e-5, rtol=0)
