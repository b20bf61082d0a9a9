import pytest
import torch

from spacepose.models.regularizer import Regularizer
from spacepose.models.seca import SECA

FEATS = (12, 16, 20, 24)


def _features(b, h, w):
    return [torch.randn(b, c, h // 2**i, w // 2**i) for i, c in enumerate(FEATS)]


@pytest.mark.parametrize(("dwsep", "seca"), [(False, False), (True, True)])
def test_shapes(dwsep, seca):
    reg = Regularizer(4, (8, 8, 16, 16), FEATS, dwsep, seca, depthwise_qk=True)
    gev = reg(torch.randn(2, 4, 8, 16, 16), _features(2, 16, 16))
    assert gev.shape == (2, 8, 8, 16, 16)
    assert reg.classify(gev).shape == (2, 8, 16, 16)


def test_switches_change_structure():
    base = Regularizer(4, (8, 8, 16, 16), FEATS, False, False)
    full = Regularizer(4, (8, 8, 16, 16), FEATS, True, True, seca_quarter_res=True)
    light = Regularizer(4, (8, 8, 16, 16), FEATS, True, True, seca_quarter_res=False)
    count = lambda m: sum(isinstance(x, SECA) for x in m.modules())  # noqa: E731
    assert (count(base), count(full), count(light)) == (0, 6, 5)
    depthwise = lambda m: sum(  # noqa: E731
        isinstance(x, torch.nn.Conv3d) and x.groups > 1 and x.groups == x.in_channels for x in m.encoders.modules()
    )
    assert depthwise(base) == 0 and depthwise(full) == 6
