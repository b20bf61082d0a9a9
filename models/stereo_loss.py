"""IGEV-Stereo training loss and metrics.

loss = smooth_L1(init_disp, gt) + sum_i gamma_N^(N-1-i) * L1(preds[i], gt),
gamma_N = gamma^(15 / (N - 1)) (N = 1: the single prediction has weight 1), means over the valid
pixels: ``valid & finite(gt) & gt < max_disp``. An empty mask gives loss 0 (no NaN). An optional
per-pixel ``weight`` turns the means into weighted means (training weighs target pixels above the
background so the loss follows the metric, which is taken on target pixels); metrics stay unweighted.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from spacepose.errors import ShapeError

__all__ = ["sequence_weights", "sequence_loss", "silhouette_band", "pixel_weights"]


def sequence_weights(n: int, gamma: float = 0.9) -> list[float]:
    """Weights of the N iteration losses, last = 1."""
    if n < 1:
        raise ValueError("need at least one prediction")
    adjusted = gamma ** (15.0 / (n - 1)) if n > 1 else gamma
    return [adjusted ** (n - 1 - i) for i in range(n)]


def silhouette_band(target: torch.Tensor, radius: int) -> torch.Tensor:
    """(B, 1, H, W) bool: target pixels within ``radius`` px (Chebyshev) of a non-target pixel.

    ``target`` (B, 1, H, W) bool or 0/1 float. The image border is not an edge (pooling pads with
    -inf), so a crop that cuts the target does not make its cut a silhouette.
    """
    if target.dim() != 4 or target.shape[1] != 1:
        raise ShapeError(f"target must be (B, 1, H, W), got {tuple(target.shape)}")
    if radius < 1:
        raise ValueError(f"radius must be >= 1, got {radius}")
    fg = target.bool()
    background = (~fg).to(torch.float32)
    near_bg = F.max_pool2d(background, 2 * radius + 1, stride=1, padding=radius) > 0
    return fg & near_bg


def pixel_weights(target: torch.Tensor, target_weight: float = 1.0, edge_weight: float = 1.0,
                  edge_radius: int = 3) -> torch.Tensor | None:
    """Per-pixel loss weights (B, 1, H, W) float, or None when both factors are 1 (plain mean).

    Background pixels weigh 1, target pixels ``target_weight``, and target pixels in the silhouette
    band (:func:`silhouette_band`) ``target_weight * edge_weight``: a network that works at 1/4
    resolution blurs the target's outline into the background, and on this thin target about half
    the target pixels lie within 3 px of it.
    """
    if target_weight == 1.0 and edge_weight == 1.0:
        return None
    fg = target.bool()
    weight = torch.where(fg, torch.full_like(target, float(target_weight), dtype=torch.float32),
                         torch.ones_like(target, dtype=torch.float32))
    if edge_weight != 1.0:
        weight = torch.where(silhouette_band(fg, edge_radius), weight * float(edge_weight), weight)
    return weight


def _masked_mean(values: torch.Tensor, mask: torch.Tensor, count: torch.Tensor,
                 weight: torch.Tensor | None = None) -> torch.Tensor:
    if weight is not None:
        values = values * weight
    return torch.where(mask, values, torch.zeros_like(values)).sum() / count


def sequence_loss(
    init_disp: torch.Tensor,
    preds: list[torch.Tensor],
    gt: torch.Tensor,
    valid: torch.Tensor,
    max_disp: float,
    gamma: float = 0.9,
    weight: torch.Tensor | None = None,
) -> tuple[torch.Tensor, dict[str, float]]:
    """init_disp, preds[i], gt (B, 1, H, W) float; valid (B, 1, H, W) bool; weight None or
    (B, 1, H, W) float >= 0 (per-pixel loss weight).

    Returns (scalar loss, {"epe", "bad1", "bad3"} of the last prediction; bad in % of valid px).
    """
    if init_disp.shape != gt.shape or valid.shape != gt.shape or any(p.shape != gt.shape for p in preds):
        raise ShapeError("init_disp, preds, gt and valid must all be (B, 1, H, W) of one shape")
    gt_safe = torch.nan_to_num(gt, nan=0.0, posinf=0.0, neginf=0.0)
    mask = valid.bool() & torch.isfinite(gt) & (gt < max_disp)
    count = mask.sum().clamp(min=1).to(gt.dtype)
    if weight is not None:
        if weight.shape != gt.shape:
            raise ShapeError("weight must have the shape of gt")
        weight = weight.to(gt.dtype)
        loss_count = torch.where(mask, weight, torch.zeros_like(weight)).sum().clamp(min=1e-6)
    else:
        loss_count = count

    loss = _masked_mean(F.smooth_l1_loss(init_disp, gt_safe, reduction="none"), mask, loss_count, weight)
    for seq_weight, pred in zip(sequence_weights(len(preds), gamma), preds):
        loss = loss + seq_weight * _masked_mean((pred - gt_safe).abs(), mask, loss_count, weight)

    with torch.no_grad():
        err = (preds[-1] - gt_safe).abs()
        metrics = {
            "epe": float(_masked_mean(err, mask, count)),
            "bad1": float(_masked_mean((err > 1.0).to(err.dtype), mask, count)) * 100.0,
            "bad3": float(_masked_mean((err > 3.0).to(err.dtype), mask, count)) * 100.0,
        }
    return loss, metrics
