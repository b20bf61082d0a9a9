import pytest
import torch

from spacepose.models.stereo_config import StereoConfig
from spacepose.models.stereo_update import MultiLevelUpdate


@pytest.mark.parametrize("n_levels", [1, 2, 3])
def test_update_shapes(n_levels):
    cfg = StereoConfig.cpu().replace(n_gru_layers=n_levels)
    upd = MultiLevelUpdate(cfg)
    hidden = [torch.randn(1, cfg.hidden_dims[i], 16 // 2**i, 16 // 2**i) for i in range(n_levels)]
    biases = [tuple(torch.randn_like(h) for _ in range(3)) for h in hidden]
    lookup = torch.randn(1, cfg.lookup_channels, 16, 16)
    new_hidden, delta = upd(hidden, biases, lookup, torch.rand(1, 1, 16, 16))
    assert [h.shape for h in new_hidden] == [h.shape for h in hidden]
    assert delta.shape == (1, 1, 16, 16)
    assert upd.upsample_mask(new_hidden[0]).shape == (1, 9 * 16, 16, 16)
