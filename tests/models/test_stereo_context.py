import pytest
import torch

from spacepose.models.stereo_config import StereoConfig
from spacepose.models.stereo_context import ContextNetwork
from spacepose.models.triplet_attention import TripletAttention


@pytest.mark.parametrize("n_levels", [1, 2, 3])
def test_context_shapes(n_levels):
    cfg = StereoConfig.cpu().replace(n_gru_layers=n_levels)
    out = ContextNetwork(cfg)(torch.randn(1, 3, 64, 64))
    assert len(out.hidden) == len(out.biases) == n_levels
    for i, (h, biases) in enumerate(zip(out.hidden, out.biases)):
        side = 64 // 2 ** (i + 2)
        assert h.shape == (1, cfg.hidden_dims[i], side, side)
        assert h.abs().max() <= 1.0  # tanh
        assert all(b.shape == h.shape for b in biases)


@pytest.mark.parametrize(("variant", "has_ta"), [("igev", False), ("ta", True), ("seca", False), ("full", True)])
def test_triplet_attention_only_in_ta_variants(variant, has_ta):
    net = ContextNetwork(StereoConfig.cpu(variant))
    n_ta = sum(isinstance(m, TripletAttention) for m in net.modules())
    assert n_ta == (net.levels.__len__() if has_ta else 0)
