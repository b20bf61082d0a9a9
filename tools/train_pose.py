"""Train the multimodal pose network (RGB CNN + point net + ECFT + FFB6D heads), paper §5.3.

* samples: :class:`spacepose.tools.pose_data.PoseDataset` (stereo-predicted or noisy GT depth
  through the flight preprocessing, per-point labels, photometric augmentation);
* loss: :func:`spacepose.models.pose_loss.pose_loss`, eq. 26 with K1 = K2 = K3 = 1 (focal γ = 2 +
  L1 offsets in units of ``xyz_scale``);
* Adam with the paper's cyclic learning rate: linear 1e-5 -> 1e-3 -> 1e-5, three cycles over the
  run (``torch.optim.lr_scheduler.CyclicLR``, triangular, step size ``steps / (2 * cycles)``);
* ``OUT/last.pt`` every ``ckpt_every`` steps and at exit (atomic replace), resumable (model,
  optimiser, scheduler, step, sampler position, RNG states); ``OUT/log.jsonl``; ``OUT/config.json``;
* validation on a few deterministic test frames: loss parts, segmentation accuracy, and the pose
  from the runtime voting stage (:func:`spacepose.pose_stage.solve_pose`) -> e_t, e_R;
* CUDA when available, else CPU; ``torchrun`` (``WORLD_SIZE`` set) -> DDP.
"""

from __future__ import annotations

import dataclasses
import json
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from spacepose.errors import DatasetError, SpaceposeError
from spacepose.flip import flip_matrix
from spacepose.models.pose_config import PoseNetConfig
from spacepose.models.pose_loss import PoseLossConfig, flipped_keypoint_targets, pose_loss
from spacepose.tools import training_common as tc
from spacepose.tools.pose_data import PoseDataConfig, PoseDataset
from spacepose.tools.training_common import CHECKPOINT_NAME, EpochSampler, git_commit

log = logging.getLogger(__name__)

__all__ = ["TrainPoseConfig", "train_pose", "build_model", "load_checkpoint", "model_from_checkpoint",
           "cyclic_scheduler", "validate_pose"]


@dataclass(frozen=True)
class TrainPoseConfig:
    """Everything that defines a pose training run (saved as OUT/config.json and in checkpoints)."""

    dataset: str
    out: str
    steps: int = 1000
    batch: int = 8
    depth_source: str = "gt_noisy"
    fusion: str = "both"
    attention: str = "ecaa"
    preset: str = "cpu"                    # PoseNetConfig.cpu() or .paper()
    net: dict[str, Any] = field(default_factory=dict)   # PoseNetConfig overrides
    lr_min: float = 1e-5
    lr_max: float = 1e-3
    cycles: int = 3
    clip: float = 10.0
    augment: bool = True
    ckpt_every: int = 200
    log_every: int = 10
    val_every: int = 200
    val_samples: int = 8
    workers: int = 1
    threads: int = 0                       # torch.set_num_threads (0 = torch's default)
    seed: int = 0
    limit: int | None = None               # use only the first N training frames
    radius_m: float | None = None          # target radius for the depth window (default: mesh)
    #: warm start: model weights from this checkpoint, fresh optimiser and schedule (fine-tuning)
    init: str | None = None
    #: stop after this many seconds of training in one call (None: run all ``steps``)
    time_limit_s: float | None = None
    #: keep the schedule on pace with ``time_limit_s`` (:class:`~spacepose.tools.training_common.SchedulePacer`)
    pace_lr: bool = False
    #: score keypoints against the nearer of the true pose and the pose flipped 180° about this body
    #: axis ("x", "y", "z"; None: the paper's loss). For a near-symmetric target, whose plain L1
    #: optimum without the flip cue is the flat midpoint (``python -m spacepose.tools.keypoint_floor``).
    symmetric_flip: str | None = None

    def net_config(self) -> PoseNetConfig:
        overrides = {k: tuple(v) if isinstance(v, list) else v for k, v in self.net.items()}
        overrides.update(fusion=self.fusion, attention=self.attention)
        return PoseNetConfig.paper(**overrides) if self.preset == "paper" else PoseNetConfig.cpu(**overrides)

    def data_config(self, augment: bool = True) -> PoseDataConfig:
        return PoseDataConfig(depth_source=self.depth_source, augment=augment and self.augment)


def build_model(config: PoseNetConfig) -> torch.nn.Module:
    from spacepose.models.pose_net import PoseNet

    return PoseNet(config)


def cyclic_scheduler(optimizer: torch.optim.Optimizer, steps: int, lr_min: float = 1e-5, lr_max: float = 1e-3,
                     cycles: int = 3) -> torch.optim.lr_scheduler.CyclicLR:
    """Paper §5.3: linear ``lr_min -> lr_max -> lr_min``, ``cycles`` times over ``steps`` steps."""
    up = max(1, int(round(steps / (2.0 * max(cycles, 1)))))
    return torch.optim.lr_scheduler.CyclicLR(optimizer, base_lr=lr_min, max_lr=lr_max, step_size_up=up,
                                             step_size_down=up, mode="triangular", cycle_momentum=False)


def load_checkpoint(path: str | Path, map_location: str = "cpu") -> dict[str, Any]:
    """A pose training checkpoint (dict with model, optimizer, scheduler, step, configs, keypoints)."""
    return tc.load_checkpoint(path, map_location, kind="pose")


def model_from_checkpoint(ckpt: dict[str, Any]) -> tuple[torch.nn.Module, PoseNetConfig]:
    config = PoseNetConfig.from_dict(ckpt["net_config"])
    model = build_model(config)
    model.load_state_dict(ckpt["model"])
    model.eval()
    return model, config


def init_from(model: torch.nn.Module, path: str | Path, config: PoseNetConfig) -> list[str]:
    """Load the weights of pose checkpoint ``path`` (a training run's, or one that ``spacepose
    recover-checkpoint`` rebuilt from a graph) into ``model``, whose config must equal the checkpoint's.
    Returns the checkpoint's folded BatchNorms, which must train frozen."""
    ckpt = load_checkpoint(path)
    if PoseNetConfig.from_dict(ckpt["net_config"]) != config:
        raise SpaceposeError(f"--init {path}: its network config differs from this run's")
    model.load_state_dict(ckpt["model"])
    log.info("initialised weights from %s (trained %s steps)", path, ckpt.get("step"))
    return list(ckpt.get("folded_bn") or [])


def _forward(net: torch.nn.Module, names: list[str], batch: dict[str, Any], device: torch.device):
    return net(*[batch[n].to(device) for n in names])


@torch.no_grad()
def validate_pose(model: torch.nn.Module, dataset: PoseDataset, device: torch.device,
                  loss_cfg: PoseLossConfig, symmetric_flip: str | None = None) -> dict[str, float]:
    """Loss, segmentation accuracy and voted-pose errors (median e_t, e_R; valid share) on ``dataset``;
    with ``symmetric_flip`` also the median e_R to the nearer of the true and the flipped pose."""
    from spacepose.bundle import VotingConfig
    from spacepose.metrics import rotation_error_deg, translation_error
    from spacepose.pose_stage import solve_pose

    model.eval()
    names = model.input_names
    losses, accs, e_t, e_r, e_r_sym, n_valid = [], [], [], [], [], 0
    flip = None if symmetric_flip is None else flip_matrix(symmetric_flip)
    for i in range(len(dataset)):
        s = dataset[i]
        batch = {k: v[None] if isinstance(v, torch.Tensor) else v for k, v in s.items()}
        seg, kp, ctr = _forward(model, names, batch, device)
        loss, _ = pose_loss(seg, kp, ctr, batch["labels"].to(device), batch["kp_targets"].to(device),
                            batch["ctr_targets"].to(device), loss_cfg)
        losses.append(float(loss))
        accs.append(float((seg.argmax(-1).cpu() == batch["labels"]).float().mean()))
        stage = solve_pose(s["xyz"].double().numpy(), seg.cpu().numpy(), kp.cpu().numpy(), ctr.cpu().numpy(),
                           dataset.keypoints, dataset.centre, config=VotingConfig(), diameter_m=2.0 * dataset.radius_m,
                           distance_range_m=dataset.distance_range_m, focal_px=dataset.focal_px,
                           baseline_m=dataset.baseline_m)
        if stage.valid:
            n_valid += 1
            e_t.append(translation_error(s["t"].numpy(), stage.t))
            e_r.append(rotation_error_deg(s["R"].numpy(), stage.R))
            if flip is not None:
                e_r_sym.append(min(e_r[-1], rotation_error_deg(s["R"].numpy() @ flip, stage.R)))
    model.train()
    nan = float("nan")
    out = {"val_loss": float(np.mean(losses)), "val_seg_acc": float(np.mean(accs)),
           "val_valid": n_valid / max(len(dataset), 1),
           "val_e_t_median": float(np.median(e_t)) if e_t else nan,
           "val_e_R_median": float(np.median(e_r)) if e_r else nan}
    if flip is not None:
        out["val_e_R_flip_median"] = float(np.median(e_r_sym)) if e_r_sym else nan
    return out


def train_pose(cfg: TrainPoseConfig, *, resume: bool = False) -> dict[str, Any]:
    """Run (or resume) training; returns a summary (final step, last losses, checkpoint path)."""
    ctx = tc.start_run(cfg.out, resume=resume, threads=cfg.threads)
    rank, world, device, out, ckpt_path = ctx.rank, ctx.world, ctx.device, ctx.out, ctx.ckpt_path

    net_cfg = cfg.net_config()
    spec = net_cfg.input_spec(seed=cfg.seed)
    loss_cfg = PoseLossConfig(offset_scale=net_cfg.xyz_scale)
    train_set = PoseDataset(cfg.dataset, "train", spec, cfg.data_config(True), seed=cfg.seed, limit=cfg.limit,
                            radius_m=cfg.radius_m)
    if train_set.keypoints.shape[0] != net_cfg.n_keypoints:
        raise SpaceposeError(f"the target has {train_set.keypoints.shape[0]} keypoints, the net predicts {net_cfg.n_keypoints}")
    try:
        val_set = PoseDataset(cfg.dataset, "test", spec, cfg.data_config(False), seed=cfg.seed, limit=cfg.val_samples,
                              deterministic=True, keypoints=train_set.keypoints, centre=train_set.centre,
                              radius_m=train_set.radius_m)
    except DatasetError as err:
        val_set = None
        log.warning("validation disabled: %s", err)

    tc.seed_all(cfg.seed)
    model = build_model(net_cfg).to(device)
    model.train()
    optimizer = torch.optim.Adam(model.parameters(), lr=cfg.lr_min)
    scheduler = cyclic_scheduler(optimizer, cfg.steps, cfg.lr_min, cfg.lr_max, cfg.cycles)
    step = 0
    folded: list[str] = []
    if resume:
        ckpt = load_checkpoint(ckpt_path, map_location=str(device))
        folded = list(ckpt.get("folded_bn") or [])
        keys = ("preset", "net", "fusion", "attention", "batch", "depth_source", "symmetric_flip")
        step = tc.resume_training(ckpt, cfg, keys, model, optimizer, scheduler)
        log.info("resumed %s at step %d", ckpt_path, step)
    elif cfg.init:
        folded = init_from(model, cfg.init, net_cfg)
    tc.freeze_folded_batchnorm(model, folded)
    pacer = tc.SchedulePacer(cfg.steps, cfg.time_limit_s) if (cfg.pace_lr and cfg.time_limit_s) else None

    net = tc.wrap_ddp(model, ctx)
    names = model.input_names
    sampler = EpochSampler(len(train_set), cfg.seed, rank, world)
    if sampler.per_rank() < cfg.batch:
        raise SpaceposeError(f"batch {cfg.batch} exceeds the {sampler.per_rank()} training frames per rank")
    info = train_set.info
    dataset_doc = {"path": str(cfg.dataset), "seed": info.get("seed"), "size": info.get("count"),
                   "train_frames": len(train_set), "target": train_set.target, "depth_source": cfg.depth_source,
                   "distance_range_m": list(train_set.distance_range_m), "image_size": info.get("size")}
    if rank == 0:
        (out / "config.json").write_text(json.dumps(
            {"train": dataclasses.asdict(cfg), "net": dataclasses.asdict(net_cfg), "loss": dataclasses.asdict(loss_cfg),
             "data": dataclasses.asdict(cfg.data_config(True)), "world_size": world, "device": str(device),
             "commit": git_commit(), "dataset": dataset_doc}, indent=2, default=list))
    log_file = tc.JsonlLog(out / "log.jsonl", rank == 0)

    def save(step: int) -> None:
        if rank != 0:
            return
        tc.atomic_save({"kind": "pose", "model": model.state_dict(), "optimizer": optimizer.state_dict(),
                        "scheduler": scheduler.state_dict(), "step": step, "rng": tc.rng_state(),
                        "train_config": tc.to_json(dataclasses.asdict(cfg)),
                        "net_config": tc.to_json(dataclasses.asdict(net_cfg)),
                        "input_spec": tc.to_json(dataclasses.asdict(spec)), "keypoints": train_set.keypoints.tolist(),
                        "centre": train_set.centre.tolist(), "target": train_set.target, "radius_m": train_set.radius_m,
                        "rig": {"image_size": info.get("size"), "focal_px": train_set.focal_px,
                                "baseline_m": train_set.baseline_m},
                        "commit": git_commit(), "dataset": dataset_doc, "folded_bn": folded}, ckpt_path)

    kp_obj = torch.as_tensor(train_set.keypoints, dtype=torch.float32, device=device)
    centre_obj = torch.as_tensor(train_set.centre, dtype=torch.float32, device=device)

    def train_step(batch: dict[str, Any]) -> tuple[dict[str, float], float, float]:
        seg, kp, ctr = _forward(net, names, batch, device)
        kp_targets = batch["kp_targets"].to(device)
        alt = None if cfg.symmetric_flip is None else flipped_keypoint_targets(
            kp_targets, batch["R"].to(device), kp_obj, centre_obj, cfg.symmetric_flip)
        loss, parts = pose_loss(seg, kp, ctr, batch["labels"].to(device), kp_targets,
                                batch["ctr_targets"].to(device), loss_cfg, kp_targets_alt=alt)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        grad_norm = torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.clip)
        lr = scheduler.get_last_lr()[0]
        optimizer.step()
        scheduler.step() if pacer is None else pacer.step(scheduler)
        values = {"loss": float(loss.detach()), **{k: float(v.detach()) for k, v in parts.items()},
                  "target_share": float((batch["labels"] > 0).float().mean())}
        return values, float(grad_norm), lr

    validate_fn = None if val_set is None else (lambda: validate_pose(model, val_set, device, loss_cfg, cfg.symmetric_flip))
    step, last = tc.run_steps(step=step, steps=cfg.steps, batch=cfg.batch, workers=cfg.workers, train_set=train_set,
                              sampler=sampler, train_step=train_step, validate=validate_fn, save=save,
                              log_file=log_file, ctx=ctx, log_every=cfg.log_every, val_every=cfg.val_every,
                              ckpt_every=cfg.ckpt_every, time_limit_s=cfg.time_limit_s)
    return {"step": step, "checkpoint": str(ckpt_path), **last}
