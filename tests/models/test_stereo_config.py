import dataclasses
import json

import pytest

from spacepose.errors import SpaceposeError
from spacepose.models.stereo_config import VARIANTS, StereoConfig


@pytest.mark.parametrize(
    ("variant", "ta", "seca"), [("igev", False, False), ("ta", True, False), ("seca", False, True), ("full", True, True)]
)
def test_variant_switches(variant, ta, seca):
    cfg = StereoConfig.cpu(variant)
    assert (cfg.use_triplet_attention, cfg.use_seca, cfg.use_dwsep) == (ta, seca, seca)


def test_unknown_variant_raises():
    with pytest.raises(SpaceposeError, match="valid"):
        StereoConfig(variant="tsca")


def test_json_roundtrip():
    for cfg in (StereoConfig.cpu(), StereoConfig.paper("ta")):
        back = StereoConfig.from_dict(json.loads(json.dumps(dataclasses.asdict(cfg))))
        assert back == cfg


def test_paper_config_numbers():
    cfg = StereoConfig.paper()
    assert (cfg.max_disp, cfg.num_disp, cfg.n_gru_layers, cfg.iters, cfg.train_iters) == (192, 48, 3, 32, 22)
    assert cfg.lookup_channels == 162  # 2 levels * 9 * (8 + 1), as in IGEV


def test_invalid_values_raise():
    with pytest.raises(SpaceposeError):
        StereoConfig(max_disp=100)
    with pytest.raises(SpaceposeError):
        StereoConfig(match_dim=50, groups=16)
    with pytest.raises(SpaceposeError):
        StereoConfig.from_dict({"bogus": 1})
    assert set(VARIANTS) == {"igev", "ta", "seca", "full"}
