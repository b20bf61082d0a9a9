"""How much of the keypoint loss a pose network has learned: its loss next to two reference predictors.

    python -m spacepose.tools.keypoint_floor data/tdrs640 --checkpoint runs/recovered/pose.pt --frames 64

On frames of a split, with the training's own samples (:class:`~spacepose.tools.pose_data.PoseDataset`,
no augmentation), it prints the keypoint term of the loss (eq. 23, in the units training logs:
L1 summed over keypoints and xyz, offsets over ``xyz_scale``, averaged over target points) of:

* ``centre_only`` — every keypoint offset predicted as the true centre offset: a network that knows
  where the target is but nothing of how it is turned;
* ``flip_<axis>`` — the midpoint of the true keypoints and those of the pose flipped 180° about the
  target's body axis: what an L1 regressor that cannot tell that flip converges to;
* ``network`` — the checkpoint's own prediction (with ``--checkpoint``).

A network at ``centre_only`` has learned nothing about the orientation. Numbers only, no assertion.
"""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path
from typing import Sequence

import numpy as np

from spacepose.flip import FLIP_AXES, flip_matrix

__all__ = ["keypoint_floor", "main"]

log = logging.getLogger(__name__)



def _kp_l1(pred: np.ndarray, target: np.ndarray, mask: np.ndarray, scale: float) -> float:
    """Eq. 23 term: pred/target (M, N, 3) metres, mask (N,) bool -> mean over target points."""
    per_point = np.abs(pred - target).sum(axis=-1).sum(axis=0) / scale
    return float(per_point[mask].mean()) if mask.any() else float("nan")


def keypoint_floor(dataset: str | Path, *, checkpoint: str | Path | None = None, frames: int = 64,
                   split: str = "train") -> dict[str, float]:
    """Mean keypoint loss of the reference predictors (and the network) over ``frames`` frames."""
    import torch

    from spacepose.models.pose_config import PoseNetConfig
    from spacepose.tools.pose_data import PoseDataConfig, PoseDataset
    from spacepose.tools.train_pose import load_checkpoint, model_from_checkpoint

    model = None
    if checkpoint is not None:
        model, net_cfg = model_from_checkpoint(load_checkpoint(checkpoint))
    else:
        net_cfg = PoseNetConfig.cpu()
    spec = net_cfg.input_spec()
    ds = PoseDataset(dataset, split, spec, PoseDataConfig(depth_source="gt_noisy", augment=False), limit=frames,
                     deterministic=True)
    scale = net_cfg.xyz_scale
    rows: dict[str, list[float]] = {"centre_only": [], **{f"flip_{a}": [] for a in FLIP_AXES}, "network": []}
    kp_obj = ds.keypoints - ds.centre
    for i in range(len(ds)):
        s = ds.sample(i)
        if s is None:
            continue
        mask = s["labels"] > 0
        target = s["kp_targets"].astype(np.float64)
        ctr = s["ctr_targets"].astype(np.float64)
        rows["centre_only"].append(_kp_l1(np.broadcast_to(ctr, target.shape), target, mask, scale))
        R = np.asarray(s["R"], dtype=np.float64)
        for axis in FLIP_AXES:
            moved = (kp_obj @ flip_matrix(axis).T - kp_obj) @ R.T        # flipped minus true keypoints, camera frame
            rows[f"flip_{axis}"].append(_kp_l1(target + 0.5 * moved[:, None, :], target, mask, scale))
        if model is not None:
            feeds = [torch.from_numpy(np.ascontiguousarray(s[n]))[None] for n in model.input_names]
            with torch.no_grad():
                kp = model(*feeds)[1][0].numpy().astype(np.float64)
            rows["network"].append(_kp_l1(kp, target, mask, scale))
    out = {k: float(np.nanmean(v)) for k, v in rows.items() if v}
    out["frames"] = float(len(rows["centre_only"]))
    return out


def main(argv: Sequence[str] | None = None) -> int:
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    p = argparse.ArgumentParser(prog="python -m spacepose.tools.keypoint_floor", description=__doc__.split("\n")[0])
    p.add_argument("dataset", type=Path)
    p.add_argument("--checkpoint", type=Path, default=None, help="pose checkpoint (spacepose recover-checkpoint makes one)")
    p.add_argument("--frames", type=int, default=64)
    p.add_argument("--split", default="train")
    p.add_argument("--out", type=Path, default=None, help="also write the numbers as JSON")
    args = p.parse_args(argv)
    result = keypoint_floor(args.dataset, checkpoint=args.checkpoint, frames=args.frames, split=args.split)
    print("| predictor | keypoint loss (eq. 23, training units) |\n|---|---|")
    for key, value in result.items():
        if key != "frames":
            print(f"| {key} | {value:.3f} |")
    print(f"over {int(result['frames'])} {args.split} frames")
    if args.out:
        args.out.write_text(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":  # pragma: no cover
    import sys

    sys.exit(main())
