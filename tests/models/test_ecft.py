"""ECFT block (paper eqs. 14-22): the fusion flags decide which branch is updated."""

from __future__ import annotations

import pytest
import torch

from spacepose.models.ecft import ECFT, AugmentedShortcut

B, C_R, C_P, H, W, N, K = 1, 16, 24, 4, 4, 10, 3


def _inputs(seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    f_rgb = torch.randn(B, C_R, H, W, generator=g)
    f_point = torch.randn(B, N, C_P, generator=g)
    pix2pt = torch.randint(0, N, (B, H * W), generator=g)
    pt_pix = torch.randint(0, H * W, (B, N, K), generator=g)
    return f_rgb, f_point, pix2pt, pt_pix


@pytest.mark.parametrize("attention", ["ecaa", "vanilla"])
@pytest.mark.parametrize("fusion, rgb_updated, point_updated",
                         [("both", True, True), ("pt2rgb", True, False), ("rgb2pt", False, True), ("none", False, False)])
def test_direction_flags(attention, fusion, rgb_updated, point_updated):
    torch.manual_seed(0)
    block = ECFT(C_R, C_P, 16, fusion=fusion, attention=attention).eval()
    f_rgb, f_point, pix2pt, pt_pix = _inputs()
    out_rgb, out_point = block(f_rgb, f_point, pix2pt, pt_pix)
    assert out_rgb.shape == f_rgb.shape and out_point.shape == f_point.shape
    assert (not torch.equal(out_rgb, f_rgb)) == rgb_updated
    assert (not torch.equal(out_point, f_point)) == point_updated
    # information flow: the RGB output depends on the point input only for point -> RGB fusion
    other_rgb, other_point = _inputs(seed=1)[:2]
    rgb_from_other_points, _ = block(f_rgb, other_point, pix2pt, pt_pix)
    _, point_from_other_rgb = block(other_rgb, f_point, pix2pt, pt_pix)
    assert (not torch.allclose(rgb_from_other_points, out_rgb)) == (fusion in ("both", "pt2rgb"))
    assert (not torch.allclose(point_from_other_rgb, out_point)) == (fusion in ("both", "rgb2pt"))


def test_residual_structure():
    """With the attention/FFN path zeroed, fused = AugSC(F) + F (eqs. 21-22)."""
    torch.manual_seed(0)
    block = ECFT(C_R, C_P, 16, fusion="rgb2pt").eval()
    with torch.no_grad():
        block.rgb2pt.ffn.gate.weight.zero_()
    f_rgb, f_point, pix2pt, pt_pix = _inputs()
    _, out_point = block(f_rgb, f_point, pix2pt, pt_pix)
    torch.testing.assert_close(out_point, block.rgb2pt.shortcut(f_point) + f_point)
    assert isinstance(block.rgb2pt.shortcut, AugmentedShortcut)


def test_bad_flags():
    with pytest.raises(ValueError, match="fusion"):
        ECFT(C_R, C_P, 16, fusion="sideways")
    with pytest.raises(ValueError, match="attention"):
        ECFT(C_R, C_P, 16, attention="linear")
