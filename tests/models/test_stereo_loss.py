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


def test_weighted_loss_is_a_weighted_mean_and_metrics_stay_unweighted():
    torch.manual_seed(0)
    gt = torch.rand(2, 1, 8, 8) * 20
    preds = [gt + torch.randn_like(gt) for _ in range(3)]
    init = gt + 2 * torch.randn_like(gt)
    valid = torch.rand(2, 1, 8, 8) > 0.2
    plain, m_plain = sequence_loss(init, preds, gt, valid, max_disp=64)
    ones, m_ones = sequence_loss(init, preds, gt, valid, max_disp=64, weight=torch.ones_like(gt))
    assert torch.allclose(plain, ones) and m_plain == m_ones
    # all weight on a subset == the plain loss over that subset; metrics still over every valid pixel
    subset = torch.zeros_like(gt, dtype=torch.bool)
    subset[:, :, :4] = True
    only, m_only = sequence_loss(init, preds, gt, valid, max_disp=64, weight=subset.float())
    ref, _ = sequence_loss(init, preds, gt, valid & subset, max_disp=64)
    assert torch.allclose(only, ref) and m_only == m_plain
    heavier, _ = sequence_loss(init, preds, gt, valid, max_disp=64, weight=1.0 + 3.0 * subset.float())
    assert min(float(ref), float(plain)) - 1e-6 <= float(heavier) <= max(float(ref), float(plain)) + 1e-6
    with pytest.raises(ShapeError):
        sequence_loss(init, preds, gt, valid, max_disp=64, weight=torch.ones(2, 1, 4, 4))


def test_silhouette_band_and_pixel_weights():
    from spacepose.models.stereo_loss import pixel_weights, silhouette_band

    target = torch.zeros(1, 1, 12, 12, dtype=torch.bool)
    target[0, 0, 2:10, 2:10] = True                      # an 8x8 square
    target[0, 0, 0:4, 0] = True                          # touching the image border (left column)
    band = silhouette_band(target, 2)
    sq = band[0, 0, 2:10, 2:10]
    assert sq[:2].all() and sq[-2:].all() and sq[:, :2].all() and sq[:, -2:].all()
    assert not sq[2:6, 2:6].any()                        # interior: more than 2 px from the background
    assert not band[0, 0][~target[0, 0]].any()           # only target pixels are in the band
    # (0, 0) is target with background at (1, 1): in the band
    assert band[0, 0, 0, 0]
    lone = torch.zeros(1, 1, 5, 5, dtype=torch.bool)
    lone[0, 0, :, :] = True                              # all target: no background anywhere
    assert not silhouette_band(lone, 1).any()            # the border padding is not background

    assert pixel_weights(target.float()) is None
    w = pixel_weights(target.float(), target_weight=4.0, edge_weight=3.0, edge_radius=2)
    assert w.shape == target.shape and w.dtype == torch.float32
    assert w[0, 0, 0, 11] == 1.0                         # background
    assert w[0, 0, 5, 5] == 4.0                          # target interior
    assert w[0, 0, 2, 5] == 12.0                         # target in the band
    with pytest.raises(ValueError):
        silhouette_band(target, 0)
