"""Losses of the pose heads (paper eqs. 23-26) and the offset targets they compare against.

OFFSET CONVENTION (shared with :mod:`spacepose.models.pose_net`): ``offset = keypoint - point``
(metres, camera frame); the vote of a point is ``point + offset``.

Normalisation note: eqs. 23 and 25 divide by N, the number of all points; we divide by the number
of target points (as FFB6D's code does), so the offset losses do not shrink when the target
covers few points. Offsets are divided by ``offset_scale`` (metres) before the L1, so a config
can put them in the units the network sees (use ``PoseNetConfig.xyz_scale``).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F

from spacepose.flip import flip_matrix as _flip_matrix_np

__all__ = ["PoseLossConfig", "focal_loss", "offset_l1", "offset_l1_min", "flip_matrix", "flipped_keypoint_targets",
           "keypoint_offset_targets", "centre_offset_targets", "pose_loss"]


@dataclass(frozen=True)
class PoseLossConfig:
    """Weights of eq. 26 (K1 keypoints, K2 semantic, K3 centre; paper: all 1) and the focal parameters."""

    k_keypoints: float = 1.0
    k_semantic: float = 1.0
    k_center: float = 1.0
    gamma: float = 2.0
    alpha: float = 1.0
    offset_scale: float = 1.0

    def __post_init__(self) -> None:
        if self.gamma < 0 or self.alpha <= 0 or self.offset_scale <= 0:
            raise ValueError("gamma must be >= 0, alpha and offset_scale > 0")


def focal_loss(logits: torch.Tensor, labels: torch.Tensor, gamma: float = 2.0, alpha: float = 1.0) -> torch.Tensor:
    """Eq. 24 averaged over points: ``-alpha (1 - c)^gamma log(c)``, c = softmax prob of the true class.

    ``logits`` (B, N, C), ``labels`` (B, N) int64 in [0, C).
    """
    log_p = F.log_softmax(logits, dim=-1).gather(-1, labels.unsqueeze(-1)).squeeze(-1)
    return torch.mean(-alpha * (1.0 - log_p.exp()) ** gamma * log_p)


def offset_l1(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Eqs. 23/25: sum over keypoints and xyz of |pred - target|, averaged over the masked points.

    ``pred``/``target`` (B, M, N, 3) or (B, N, 3); ``mask`` (B, N) bool/float (1 = target point).
    """
    if pred.dim() == 3:
        pred, target = pred.unsqueeze(1), target.unsqueeze(1)
    w = mask.to(pred.dtype)
    per_point = torch.abs(pred - target).sum(dim=-1).sum(dim=1)   # (B, N)
    return torch.sum(per_point * w) / torch.clamp(torch.sum(w), min=1.0)


def offset_l1_min(pred: torch.Tensor, targets: list[torch.Tensor], mask: torch.Tensor) -> torch.Tensor:
    """:func:`offset_l1` against the best of several target sets, chosen per sample.

    ``pred`` and each of ``targets`` (B, M, N, 3); ``mask`` (B, N). For every sample the target set
    with the smallest summed L1 is kept; the result is normalised like :func:`offset_l1` (by all masked
    points of the batch), so a single target set gives exactly :func:`offset_l1`.
    """
    w = mask.to(pred.dtype)
    per_sample = torch.stack([(torch.abs(pred - t).sum(dim=-1).sum(dim=1) * w).sum(dim=1) for t in targets])
    return per_sample.min(dim=0).values.sum() / torch.clamp(torch.sum(w), min=1.0)


def flip_matrix(axis: str) -> torch.Tensor:
    """(3, 3) float32 rotation by 180 degrees about body axis ``"x"``, ``"y"`` or ``"z"``
    (:func:`spacepose.flip.flip_matrix`, the runtime's, as a tensor)."""
    return torch.from_numpy(_flip_matrix_np(axis)).to(torch.float32)


def flipped_keypoint_targets(kp_targets: torch.Tensor, R: torch.Tensor, keypoints: torch.Tensor,
                             centre: torch.Tensor, axis: str) -> torch.Tensor:
    """Keypoint offset targets of the pose turned 180° about body ``axis`` through the centre.

    ``kp_targets`` (B, M, N, 3) of the true pose, ``R`` (B, 3, 3), ``keypoints`` (M, 3) and ``centre``
    (3,) in the object frame. The flipped pose maps keypoint k to ``R (c + S (k - c)) + t``, so the
    targets move by ``R (S - I)(k - c)``, the same for every point.
    """
    S = flip_matrix(axis).to(kp_targets.dtype)
    rel = (keypoints - centre).to(kp_targets.dtype)                       # (M, 3)
    moved = torch.einsum("bij,mj->bmi", R.to(kp_targets.dtype), rel @ S.T - rel)
    return kp_targets + moved.unsqueeze(2)


def keypoint_offset_targets(points: torch.Tensor, keypoints: torch.Tensor) -> torch.Tensor:
    """``keypoint - point``: points (B, N, 3), keypoints (B, M, 3) camera frame -> (B, M, N, 3)."""
    return keypoints.unsqueeze(2) - points.unsqueeze(1)


def centre_offset_targets(points: torch.Tensor, centre: torch.Tensor) -> torch.Tensor:
    """``centre - point``: points (B, N, 3), centre (B, 3) -> (B, N, 3)."""
    return centre.unsqueeze(1) - points


def pose_loss(seg_logits: torch.Tensor, kp_offsets: torch.Tensor, ctr_offsets: torch.Tensor,
              labels: torch.Tensor, kp_targets: torch.Tensor, ctr_targets: torch.Tensor,
              cfg: PoseLossConfig | None = None,
              kp_targets_alt: torch.Tensor | None = None) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Eq. 26: ``K1 L_keypoints + K2 L_semantic + K3 L_center``; returns (total, parts).

    ``labels`` (B, N) int64 with 0 = background; offsets are supervised where ``labels > 0``.
    ``kp_targets_alt`` (B, M, N, 3): the keypoint targets of an equally plausible pose (a symmetry of
    the target, :func:`flipped_keypoint_targets`); each sample is then scored against the nearer of
    the two sets (:func:`offset_l1_min`). Not the paper's loss: a training option for near-symmetric targets.
    """
    cfg = cfg or PoseLossConfig()
    mask = labels > 0
    s = cfg.offset_scale
    kp_term = (offset_l1(kp_offsets / s, kp_targets / s, mask) if kp_targets_alt is None else
               offset_l1_min(kp_offsets / s, [kp_targets / s, kp_targets_alt / s], mask))
    parts = {
        "keypoints": kp_term,
        "semantic": focal_loss(seg_logits, labels, cfg.gamma, cfg.alpha),
        "center": offset_l1(ctr_offsets / s, ctr_targets / s, mask),
    }
    total = cfg.k_keypoints * parts["keypoints"] + cfg.k_semantic * parts["semantic"] + cfg.k_center * parts["center"]
    return total, parts
