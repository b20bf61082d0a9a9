"""Train TSCA-Stereo on a rendered dataset with IGEV's loss and schedule.

* loss: ``spacepose.models.stereo_loss.sequence_loss`` (smooth-L1 on the initial disparity +
  gamma-weighted L1 over the iterations, GT >= max_disp masked);
* AdamW (weight decay 1e-5), OneCycle (IGEV: linear anneal, 1 % warm-up, no momentum cycling,
  ``total_steps = steps + 100``), gradient clipping at 1.0;
* samples from :class:`spacepose.tools.stereo_data.StereoCropDataset` (ROI windows + letterboxed
  frames, photometric augmentation);
* checkpoints ``OUT/last.pt`` every ``ckpt_every`` steps and at exit (atomic replace), resumable
  (model, optimiser, scheduler, step, sampler position and RNG states); ``OUT/log.jsonl`` (one JSON
  object per logged step / validation); ``OUT/config.json``;
* CUDA when available, else CPU; multi-GPU with ``torchrun`` (``WORLD_SIZE`` set -> DDP, each rank
  its own shard of every epoch's permutation).
"""

from __future__ import annotations

import dataclasses
import json
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from spacepose.errors import DatasetError, SpaceposeError
from spacepose.models.stereo_config import StereoConfig
from spacepose.models.stereo_loss import pixel_weights
from spacepose.tools import training_common as tc
from spacepose.tools.pose_data import dataset_info
from spacepose.tools.stereo_data import StereoCropConfig, StereoCropDataset
from spacepose.tools.training_common import CHECKPOINT_NAME, EpochSampler, git_commit


log = logging.getLogger(__name__)

__all__ = ["TrainConfig", "train_stereo", "load_checkpoint", "build_model", "git_commit", "EpochSampler",
           "CHECKPOINT_NAME"]


@dataclass(frozen=True)
class TrainConfig:
    """Everything that defines a stereo training run (saved as OUT/config.json)."""

    dataset: str
    out: str
    steps: int = 1000
    batch: int = 4
    variant: str = "full"
    preset: str = "cpu"  # StereoConfig.cpu() or .paper()
    iters: int = 4  # training iterations of the update block
    lr: float = 4e-4
    weight_decay: float = 1e-5
    clip: float = 1.0
    size: tuple[int, int] = (256, 256)
    train_crop: tuple[int, int] | None = None  # random sub-crop of each sample (see StereoCropConfig)
    roi_prob: float = 0.75
    ckpt_every: int = 200
    log_every: int = 10
    val_every: int = 200
    val_samples: int = 8
    workers: int = 0
    threads: int = 0  # torch.set_num_threads (0 = leave torch's default)
    seed: int = 0
    limit: int | None = None  # use only the first N training frames
    #: repeat every training frame of a regime this many times per epoch (e.g. {"mixed": 3})
    oversample: dict[str, int] = field(default_factory=dict)
    #: warm start: model weights from this checkpoint, fresh optimiser and schedule (fine-tuning)
    init: str | None = None
    #: stop after this many seconds of training in one call (None: run all ``steps``)
    time_limit_s: float | None = None
    #: keep the schedule on pace with ``time_limit_s`` (:class:`~spacepose.tools.training_common.SchedulePacer`)
    pace_lr: bool = False
    #: loss weight of target pixels relative to background pixels (1: plain mean over valid pixels)
    target_weight: float = 1.0
    #: extra factor for target pixels within ``edge_radius`` px of the silhouette (1: none)
    edge_weight: float = 1.0
    edge_radius: int = 3
    #: photometric augmentation, :attr:`StereoCropConfig.photometric` ("mild" up to session 35, or "wide")
    photometric: str = "mild"
    stereo: dict[str, Any] = field(default_factory=dict)  # StereoConfig overrides

    def stereo_config(self) -> StereoConfig:
        base = StereoConfig.paper(self.variant) if self.preset == "paper" else StereoConfig.cpu(self.variant)
        return base.replace(train_iters=self.iters, **self.stereo)

    def crop_config(self, augment: bool = True) -> StereoCropConfig:
        crop = tuple(self.train_crop) if (augment and self.train_crop) else None
        return StereoCropConfig(size=tuple(self.size), roi_prob=self.roi_prob,
                                max_disp=float(self.stereo_config().max_disp), augment=augment, train_crop=crop,
                                photometric=self.photometric)


def build_model(config: StereoConfig) -> torch.nn.Module:
    from spacepose.models.tsca_stereo import TSCAStereo

    return TSCAStereo(config)


def load_checkpoint(path: str | Path, map_location: str = "cpu") -> dict[str, Any]:
    """A training checkpoint (dict with model, optimizer, scheduler, step, configs)."""
    return tc.load_checkpoint(path, map_location)


def model_from_checkpoint(ckpt: dict[str, Any]) -> tuple[torch.nn.Module, StereoConfig]:
    config = StereoConfig.from_dict(ckpt["stereo_config"])
    model = build_model(config)
    model.load_state_dict(ckpt["model"])
    model.eval()
    return model, config


def init_from(model: torch.nn.Module, path: str | Path, config: StereoConfig, device: torch.device) -> list[str]:
    """Load the weights of checkpoint ``path`` into ``model``; its architecture must equal ``config``'s
    (iteration counts aside, which are not weights). Returns the checkpoint's folded BatchNorms (a
    checkpoint rebuilt from a graph by ``spacepose recover-checkpoint``), which must train frozen."""
    ckpt = load_checkpoint(path, map_location=str(device))
    saved = StereoConfig.from_dict(ckpt["stereo_config"])
    ignore = {"train_iters": 1, "iters": 0}
    fields = {f.name for f in dataclasses.fields(StereoConfig)}
    strip = {k: v for k, v in ignore.items() if k in fields}
    if saved.replace(**strip) != config.replace(**strip):
        raise SpaceposeError(f"--init {path}: its model config differs from this run's")
    model.load_state_dict(ckpt["model"])
    log.info("initialised weights from %s (trained %s steps)", path, ckpt.get("step"))
    return list(ckpt.get("folded_bn") or [])


def _sequence_loss(init_disp, preds, gt, valid, max_disp, weight=None):
    from spacepose.models.stereo_loss import sequence_loss

    return sequence_loss(init_disp, preds, gt, valid, max_disp=max_disp, weight=weight)


def _to_float(metrics: dict[str, Any]) -> dict[str, float]:
    out = {}
    for k, v in metrics.items():
        if isinstance(v, torch.Tensor):
            v = v.detach().float().mean().item()
        if isinstance(v, (int, float)):
            out[k] = float(v)
    return out


@torch.no_grad()
def validate(model: torch.nn.Module, dataset: StereoCropDataset, device: torch.device, iters: int) -> dict[str, float]:
    """EPE / bad-3 over target pixels of deterministic ROI views of a few test frames."""
    model.eval()
    err_sum, bad3, n = 0.0, 0.0, 0
    for i in range(len(dataset)):
        s = dataset[i]
        left, right = s["left"][None].to(device), s["right"][None].to(device)
        pred = model(left, right, iters=iters, test_mode=True)
        gt = s["disparity"][None].to(device)
        valid = (s["valid"][None].to(device) > 0.5) & (s["target"][None].to(device) > 0.5)
        e = (pred - gt).abs()[valid]
        err_sum += float(e.sum())
        bad3 += float((e > 3).sum())
        n += int(valid.sum())
    model.train()
    return {"val_epe": err_sum / max(n, 1), "val_bad3": 100.0 * bad3 / max(n, 1), "val_pixels": float(n)}


def dataset_record(cfg: TrainConfig, train_set: StereoCropDataset) -> dict[str, Any]:
    """What the checkpoint (and the exported graph) records of the training data: the rendered set's own seed
    and frame count (``dataset.json``; not the training seed), the distinct train frames and, with
    ``--oversample``, the samples per epoch and the factors."""
    info = dataset_info(cfg.dataset)
    frames = len({rec.frame for rec in train_set.records})
    doc: dict[str, Any] = {"path": str(cfg.dataset), "seed": info.get("seed"), "size": info.get("count"),
                           "image_size": info.get("size"), "train_frames": frames}
    if cfg.oversample:
        doc.update(train_samples=len(train_set), oversample=dict(cfg.oversample))
    return doc


def train_stereo(cfg: TrainConfig, *, resume: bool = False) -> dict[str, Any]:
    """Run (or resume) training; returns a summary dict (final step, last losses, checkpoint path)."""
    ctx = tc.start_run(cfg.out, resume=resume, threads=cfg.threads)
    rank, world, device, out, ckpt_path = ctx.rank, ctx.world, ctx.device, ctx.out, ctx.ckpt_path

    stereo_cfg = cfg.stereo_config()
    tc.seed_all(cfg.seed)
    model = build_model(stereo_cfg).to(device)
    model.train()
    optimizer = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay, eps=1e-8)
    scheduler = torch.optim.lr_scheduler.OneCycleLR(optimizer, cfg.lr, total_steps=cfg.steps + 100, pct_start=0.01,
                                                    cycle_momentum=False, anneal_strategy="linear")
    step = 0
    folded: list[str] = []
    if resume:
        ckpt = load_checkpoint(ckpt_path, map_location=str(device))
        folded = list(ckpt.get("folded_bn") or [])
        step = tc.resume_training(ckpt, cfg, ("variant", "preset", "size", "batch", "stereo"), model, optimizer,
                                  scheduler)
        log.info("resumed %s at step %d", ckpt_path, step)
    elif cfg.init:
        folded = init_from(model, cfg.init, stereo_cfg, device)
    tc.freeze_folded_batchnorm(model, folded)
    pacer = tc.SchedulePacer(cfg.steps, cfg.time_limit_s) if (cfg.pace_lr and cfg.time_limit_s) else None

    net = tc.wrap_ddp(model, ctx)

    train_set = StereoCropDataset(cfg.dataset, "train", cfg.crop_config(True), seed=cfg.seed, limit=cfg.limit,
                                  oversample=cfg.oversample)
    try:
        val_set = StereoCropDataset(cfg.dataset, "test", cfg.crop_config(False), seed=cfg.seed,
                                    limit=cfg.val_samples, deterministic=True)
    except DatasetError:
        val_set = None
        log.warning("no test split: validation disabled")
    sampler = EpochSampler(len(train_set), cfg.seed, rank, world)
    dataset_doc = dataset_record(cfg, train_set)
    if rank == 0:
        config_doc = {"train": dataclasses.asdict(cfg), "stereo": stereo_cfg.to_dict(), "world_size": world,
                      "device": str(device), "commit": git_commit(), "train_frames": len(train_set),
                      "dataset": dataset_doc}
        (out / "config.json").write_text(json.dumps(config_doc, indent=2, default=list))
    log_file = tc.JsonlLog(out / "log.jsonl", rank == 0)

    def save(step: int) -> None:
        if rank != 0:
            return
        tc.atomic_save({"model": model.state_dict(), "optimizer": optimizer.state_dict(),
                        "scheduler": scheduler.state_dict(), "step": step, "rng": tc.rng_state(),
                        "train_config": tc.to_json(dataclasses.asdict(cfg)),
                        "stereo_config": stereo_cfg.to_dict(), "commit": git_commit(), "folded_bn": folded,
                        "dataset": dataset_doc}, ckpt_path)

    def train_step(batch: dict[str, Any]) -> tuple[dict[str, float], float, float]:
        left, right = batch["left"].to(device), batch["right"].to(device)
        gt, valid = batch["disparity"].to(device), batch["valid"].to(device)
        init_disp, preds = net(left, right, iters=cfg.iters)
        weight = pixel_weights(batch["target"].to(device), cfg.target_weight, cfg.edge_weight, cfg.edge_radius)
        loss, metrics = _sequence_loss(init_disp, preds, gt, valid, stereo_cfg.max_disp, weight)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        grad_norm = torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.clip)
        optimizer.step()
        scheduler.step() if pacer is None else pacer.step(scheduler)
        return {"loss": float(loss.detach()), **_to_float(metrics)}, float(grad_norm), scheduler.get_last_lr()[0]

    validate_fn = None if val_set is None else (lambda: validate(model, val_set, device, stereo_cfg.iters or cfg.iters))
    step, last = tc.run_steps(step=step, steps=cfg.steps, batch=cfg.batch, workers=cfg.workers, train_set=train_set,
                              sampler=sampler, train_step=train_step, validate=validate_fn, save=save,
                              log_file=log_file, ctx=ctx, log_every=cfg.log_every, val_every=cfg.val_every,
                              ckpt_every=cfg.ckpt_every, time_limit_s=cfg.time_limit_s)
    return {"step": step, "checkpoint": str(ckpt_path), **last}
