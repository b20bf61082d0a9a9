"""Pose losses (paper eqs. 23-26): focal loss by hand, masking, and overfitting one sample."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from spacepose.models.pose_config import PoseNetConfig
from spacepose.models.pose_loss import (PoseLossConfig, centre_offset_targets, focal_loss, keypoint_offset_targets,
                                        offset_l1, pose_loss)
from spacepose.models.pose_net import PoseNet
from spacepose.pose_inputs import build_pose_inputs


def test_focal_loss_hand_value():
    logits = torch.tensor([[[0.0, math.log(3.0)], [math.log(4.0), 0.0]]])  # p(true) = 3/4 and 4/5
    labels = torch.tensor([[1, 0]])
    expected = 0.5 * (-0.25 * (0.25 ** 2) * math.log(0.75) - 0.25 * (0.2 ** 2) * math.log(0.8))
    assert focal_loss(logits, labels, gamma=2.0, alpha=0.25).item() == pytest.approx(expected, rel=1e-6)


def test_focal_gamma_zero_is_cross_entropy():
    logits, labels = torch.randn(2, 7, 3), torch.randint(0, 3, (2, 7))
    torch.testing.assert_close(focal_loss(logits, labels, gamma=0.0), F.cross_entropy(logits.reshape(-1, 3), labels.reshape(-1)))


def test_offset_l1_only_on_target_points():
    pred, target = torch.zeros(1, 2, 3, 3), torch.zeros(1, 2, 3, 3)
    pred[0, :, 0] = torch.tensor([1.0, -2.0, 0.5])   # point 0 (target): |.|_1 = 3.5 per keypoint
    pred[0, :, 2] = 100.0                            # point 2 is background: ignored
    mask = torch.tensor([[True, True, False]])
    assert offset_l1(pred, target, mask).item() == pytest.approx(2 * 3.5 / 2)
    assert offset_l1(pred, target, torch.zeros(1, 3, dtype=torch.bool)).item() == 0.0


def test_joint_loss_weights_and_zero_at_targets():
    points = torch.randn(1, 5, 3)
    kps, centre = torch.randn(1, 2, 3), torch.randn(1, 3)
    labels = torch.tensor([[1, 1, 0, 1, 0]])
    kp_t, ctr_t = keypoint_offset_targets(points, kps), centre_offset_targets(points, centre)
    logits = torch.randn(1, 5, 2)
    total, parts = pose_loss(logits, kp_t, ctr_t, labels, kp_t, ctr_t)
    assert parts["keypoints"].item() == 0.0 and parts["center"].item() == 0.0
    torch.testing.assert_close(total, parts["semantic"])
    cfg = PoseLossConfig(k_keypoints=2.0, k_semantic=0.5, k_center=3.0)
    total, parts = pose_loss(logits, kp_t + 1.0, ctr_t - 1.0, labels, kp_t, ctr_t, cfg)
    assert parts["keypoints"].item() == pytest.approx(6.0) and parts["center"].item() == pytest.approx(3.0)
    assert total.item() == pytest.approx(2.0 * 6.0 + 0.5 * parts["semantic"].item() + 3.0 * 3.0, rel=1e-6)
    with pytest.raises(ValueError):
        PoseLossConfig(gamma=-1.0)


@pytest.fixture(autouse=True)
def one_thread():
    """Tiny graphs run faster on one thread, and the CI machine is shared."""
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(previous)


def test_loss_falls_when_overfitting_one_sample():
    cfg = PoseNetConfig(crop_size=(64, 64), n_points=256, k=8, n_levels=2, rgb_stem=8, rgb_widths=(16, 32),
                        rgb_bottleneck=32, rgb_out=16, point_stem=8, point_widths=(16, 32), point_bottleneck=32,
                        head_width=32, n_keypoints=4)
    rng = np.random.default_rng(0)
    xyz = rng.normal(scale=1.0, size=(256, 3)) + np.array([0.0, 0.0, 20.0])
    pixels = rng.integers(0, 64, (256, 2))
    rgb = rng.integers(0, 256, (64, 64, 3), dtype=np.uint8)
    inputs, _ = build_pose_inputs(rgb, xyz, pixels, cfg.input_spec())
    points = torch.as_tensor(xyz, dtype=torch.float32)[None]
    labels = torch.as_tensor(xyz[:, 0] > 0).long()[None]
    kp_t = keypoint_offset_targets(points, torch.tensor([[[1.0, 0, 20], [0, 1.0, 20], [0, 0, 21], [1, 1, 21]]]))
    ctr_t = centre_offset_targets(points, torch.tensor([[0.5, 0.0, 20.0]]))
    torch.manual_seed(0)
    net = PoseNet(cfg).train()
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)
    loss_cfg = PoseLossConfig(offset_scale=cfg.xyz_scale)
    losses = []
    for _ in range(30):
        out = net.forward_dict(inputs)
        total, _ = pose_loss(out["seg_logits"], out["kp_offsets"], out["ctr_offsets"], labels, kp_t, ctr_t, loss_cfg)
        opt.zero_grad()
        total.backward()
        opt.step()
        losses.append(total.item())
    assert np.isfinite(losses).all()
    assert losses[-1] < 0.5 * losses[0]


def _random_rotation(gen):
    q, _ = torch.linalg.qr(torch.randn(3, 3, generator=gen, dtype=torch.float64))
    return q * torch.sign(torch.det(q))


def test_flipped_targets_are_those_of_the_flipped_pose():
    from spacepose.models.pose_loss import flip_matrix, flipped_keypoint_targets, keypoint_offset_targets

    gen = torch.Generator().manual_seed(0)
    kp = torch.randn(8, 3, generator=gen, dtype=torch.float64)
    c = torch.randn(3, generator=gen, dtype=torch.float64)
    R = torch.stack([_random_rotation(gen) for _ in range(2)])
    t = torch.randn(2, 3, generator=gen, dtype=torch.float64) + torch.tensor([0.0, 0.0, 20.0], dtype=torch.float64)
    pts = torch.randn(2, 50, 3, generator=gen, dtype=torch.float64) + t[:, None]
    true = keypoint_offset_targets(pts, kp @ R.transpose(1, 2) + t[:, None])
    for axis in "xyz":
        S = flip_matrix(axis).double()
        assert torch.allclose(S @ S, torch.eye(3, dtype=torch.float64)) and torch.det(S) == 1.0
        R_f = R @ S                                   # the pose turned 180° about body `axis` through c
        t_f = t + torch.einsum("bij,j->bi", R, c - S @ c)
        want = keypoint_offset_targets(pts, kp @ R_f.transpose(1, 2) + t_f[:, None])
        got = flipped_keypoint_targets(true, R, kp, c, axis)
        assert torch.allclose(got, want, atol=1e-9)
    with pytest.raises(ValueError):
        flip_matrix("w")


def test_min_over_target_sets_is_chosen_per_sample():
    from spacepose.models.pose_loss import offset_l1, offset_l1_min

    gen = torch.Generator().manual_seed(1)
    a = torch.randn(2, 4, 30, 3, generator=gen)
    b = a + 5.0
    mask = torch.rand(2, 30, generator=gen) > 0.3
    assert torch.allclose(offset_l1_min(a + 0.1, [a], mask), offset_l1(a + 0.1, a, mask))
    pred = torch.stack([a[0], b[1]])                  # sample 0 matches set a, sample 1 set b
    assert float(offset_l1_min(pred, [a, b], mask)) == 0.0
    assert float(offset_l1(pred, a, mask)) > 0.0
    # pose_loss with the alternative set: the keypoint term is the per-sample min
    seg = torch.zeros(2, 30, 2)
    labels = mask.long()
    ctr = torch.zeros(2, 30, 3)
    _, parts = pose_loss(seg, pred, ctr, labels, a, ctr, kp_targets_alt=b)
    assert float(parts["keypoints"]) == 0.0
