"""Tests of spacepose.models.flip_net."""

import pytest

torch = pytest.importorskip("torch")

from spacepose.models.flip_net import FlipNet, FlipNetConfig  # noqa: E402


def _views(n=3, size=32, seed=0):
    g = torch.Generator().manual_seed(seed)
    v = torch.rand(n, 3, size, size, generator=g)
    v[:, 1:] = (v[:, 1:] > 0.5).float()
    return v


def test_swapping_the_poses_negates_the_logit_exactly():
    net = FlipNet(FlipNetConfig(size=32, widths=(8, 8, 16), hidden=8)).eval()
    v = _views()
    swapped = v[:, [0, 2, 1]]
    with torch.no_grad():
        a, b = net(v), net(swapped)
    assert a.shape == (3,)
    torch.testing.assert_close(a, -b, rtol=0, atol=1e-6)
    same = v.clone()
    same[:, 2] = same[:, 1]
    with torch.no_grad():
        assert torch.allclose(net(same), torch.zeros(3), atol=1e-6)   # two equal outlines: no preference


def test_shapes_are_checked():
    net = FlipNet(FlipNetConfig(size=32, widths=(8, 8, 16), hidden=8))
    with pytest.raises(ValueError, match="expected"):
        net(torch.zeros(2, 3, 16, 16))
    with pytest.raises(ValueError, match="expected"):
        net(torch.zeros(2, 4, 32, 32))


@pytest.mark.parametrize("kwargs", [dict(size=8), dict(size=36), dict(widths=()), dict(hidden=0)])
def test_bad_configs_are_refused(kwargs):
    with pytest.raises(ValueError):
        FlipNetConfig(**kwargs)


def test_it_learns_which_outline_the_image_fills():
    """The loss falls on a toy task: the grey plane is outline A or outline B, the label says which."""
    torch.manual_seed(0)
    net = FlipNet(FlipNetConfig(size=32, widths=(8, 8, 16), hidden=8))
    v = _views(16, seed=1)
    labels = (torch.rand(16, generator=torch.Generator().manual_seed(2)) > 0.5).float()
    v[:, 0] = torch.where(labels[:, None, None] > 0.5, v[:, 1], v[:, 2]) * 0.8
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)
    losses = []
    for _ in range(60):
        loss = torch.nn.functional.binary_cross_entropy_with_logits(net(v), labels)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(float(loss.detach()))
    assert losses[-1] < 0.5 * losses[0]
