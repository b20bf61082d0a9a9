import math

import pytest
import torch

from spacepose.errors import ShapeError
from spacepose.models.stereo_loss import sequence_loss, sequence_weights


def test_weights_guarded_for_one_iteration():
    assert sequence_weights(1) == [1.0]
    w = sequence_weights(16)
    assert w[-1] == 1.0 and math.isclose(w[0], 0.9**15)


def test_loss_value_and_mask():
    gt = torch.tensor([[[[1.0, 2.0, 50.0, 5.0]]]])
    valid = torch.tensor([[[[True, True, True, False]]]])
    init = gt + torch.tensor([[[[0.5, 0.5, 0.0, 9.0]]]])  # smooth-L1 of 0.5 = 0.125
    pred = gt + torch.tensor([[[[2.0, 4.0, 99.0, 9.0]]]])
    loss, m = sequence_loss(init, [pred], gt, valid, max_disp=10.0)  # pixel 2: gt >= max_disp
    assert math.isclose(loss.item(), 0.125 + 3.0, rel_tol=1e-6)
    assert math.isclose(m["epe"], 3.0, rel_tol=1e-6)
    assert m["bad1"] == 100.0 and m["bad3"] == 50.0


def test_two_iterations_weighted():
    gt = torch.zeros(1, 1, 2, 2)
    valid = torch.ones(1, 1, 2, 2, dtype=torch.bool)
    loss, _ = sequence_loss(gt, [gt + 1.0, gt + 2.0], gt, valid, max_disp=10.0)
    assert math.isclose(loss.item(), 0.9**15 * 1.0 + 2.0, rel_tol=1e-6)


def test_empty_mask_and_nan_gt_do_not_give_nan():
    gt = torch.full((1, 1, 2, 2), float("nan"))
    loss, m = sequence_loss(torch.zeros_like(gt), [torch.zeros_like(gt)], gt, torch.ones_like(gt, dtype=torch.bool), 10.0)
    assert loss.item() == 0.0 and m["epe"] == 0.0


def test_shape_mismatch_raises():
    gt = torch.zeros(1, 1, 2, 2)
    with pytest.raises(ShapeError):
        sequence_loss(gt, [torch.zeros(1, 1, 2, 3)], gt, gt.bool(), 10.0)
