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
import math
import os
import random
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import torch
import torch.distributed as dist
from torch.utils.data import DataLoader, Sampler

from spacepose.errors import DatasetError, SpaceposeError
from spacepose.models.stereo_config import StereoConfig
from spacepose.tools.stereo_data import StereoCropConfig, StereoCropDataset

log = logging.getLogger(__name__)

__all__ = ["TrainConfig", "train_stereo", "load_checkpoint", "build_model", "git_commit", "EpochSampler"]

CHECKPOINT_NAME = "last.pt"


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
    stereo: dict[str, Any] = field(default_factory=dict)  # StereoConfig overrides

    def stereo_config(self) -> StereoConfig:
        base = StereoConfig.paper(self.variant) if self.preset == "paper" else StereoConfig.cpu(self.variant)
        return base.replace(train_iters=self.iters, **self.stereo)

    def crop_config(self, augment: bool = True) -> StereoCropConfig:
        crop = tuple(self.train_crop) if (augment and self.train_crop) else None
        return StereoCropConfig(size=tuple(self.size), roi_prob=self.roi_prob,
                                max_disp=float(self.stereo_config().max_disp), augment=augment, train_crop=crop)


def git_commit(cwd: str | Path | None = None) -> str | None:
    """``git rev-parse HEAD`` of the source tree, or None."""
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=cwd or Path(__file__).resolve().parent,
                             capture_output=True, text=True, timeout=10, check=True)
        return out.stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        return None


def build_model(config: StereoConfig) -> torch.nn.Module:
    from spacepose.models.tsca_stereo import TSCAStereo

    return TSCAStereo(config)


class EpochSampler(Sampler[int]):
    """Per-epoch permutation of ``range(n)`` from (seed, epoch), sharded over ranks, resumable.

    ``skip`` drops the first ``skip`` indices of this rank's share (used to resume mid-epoch).
    """

    def __init__(self, n: int, seed: int = 0, rank: int = 0, world: int = 1) -> None:
        self.n, self.seed, self.rank, self.world = int(n), int(seed), int(rank), int(world)
        self.epoch, self.skip = 0, 0

    def set_epoch(self, epoch: int, skip: int = 0) -> None:
        self.epoch, self.skip = int(epoch), int(skip)

    def per_rank(self) -> int:
        return math.ceil(self.n / self.world)

    def __iter__(self) -> Iterator[int]:
        g = torch.Generator()
        g.manual_seed(self.seed * 1_000_003 + self.epoch)
        perm = torch.randperm(self.n, generator=g).tolist()
        total = self.per_rank() * self.world
        perm = (perm * (total // max(len(perm), 1) + 1))[:total]  # pad by repetition
        share = perm[self.rank::self.world]
        return iter(share[self.skip:])

    def __len__(self) -> int:
        return max(self.per_rank() - self.skip, 0)


def _rng_state() -> dict[str, Any]:
    state = {"torch": torch.get_rng_state(), "numpy": np.random.get_state(), "python": random.getstate()}
    if torch.cuda.is_available():
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def _set_rng_state(state: dict[str, Any]) -> None:
    torch.set_rng_state(state["torch"])
    np.random.set_state(state["numpy"])
    random.setstate(state["python"])
    if "cuda" in state and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])


def _atomic_save(obj: Any, path: Path) -> None:
    tmp = path.with_name(path.name + ".tmp")
    torch.save(obj, tmp)
    os.replace(tmp, path)


def load_checkpoint(path: str | Path, map_location: str = "cpu") -> dict[str, Any]:
    """A training checkpoint (dict with model, optimizer, scheduler, step, configs)."""
    p = Path(path)
    if not p.is_file():
        raise SpaceposeError(f"checkpoint not found: {p}")
    try:
        return torch.load(p, map_location=map_location, weights_only=False)
    except Exception as err:  # torch raises pickle/zip errors of many types
        raise SpaceposeError(f"cannot read checkpoint {p}: {err}") from err


def model_from_checkpoint(ckpt: dict[str, Any]) -> tuple[torch.nn.Module, StereoConfig]:
    config = StereoConfig.from_dict(ckpt["stereo_config"])
    model = build_model(config)
    model.load_state_dict(ckpt["model"])
    model.eval()
    return model, config


def _sequence_loss(init_disp, preds, gt, valid, max_disp):
    from spacepose.models.stereo_loss import sequence_loss

    return sequence_loss(init_disp, preds, gt, valid, max_disp=max_disp)


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


def _dist_setup() -> tuple[int, int, int]:
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world > 1 and not dist.is_initialized():
        backend = "nccl" if torch.cuda.is_available() else "gloo"
        dist.init_process_group(backend=backend)
    rank = dist.get_rank() if dist.is_initialized() else 0
    local = int(os.environ.get("LOCAL_RANK", "0"))
    return rank, world if dist.is_initialized() else 1, local


def train_stereo(cfg: TrainConfig, *, resume: bool = False) -> dict[str, Any]:
    """Run (or resume) training; returns a summary dict (final step, last losses, checkpoint path)."""
    rank, world, local_rank = _dist_setup()
    if cfg.threads > 0:
        torch.set_num_threads(cfg.threads)
    device = torch.device(f"cuda:{local_rank}" if torch.cuda.is_available() else "cpu")
    if device.type == "cuda":
        torch.cuda.set_device(device)
    out = Path(cfg.out)
    ckpt_path = out / CHECKPOINT_NAME
    if ckpt_path.exists() and not resume:
        raise SpaceposeError(f"{ckpt_path} exists: pass --resume to continue it, or choose another --out")
    if resume and not ckpt_path.exists():
        raise SpaceposeError(f"--resume given but {ckpt_path} does not exist")
    if rank == 0:
        out.mkdir(parents=True, exist_ok=True)

    stereo_cfg = cfg.stereo_config()
    torch.manual_seed(cfg.seed)
    np.random.seed(cfg.seed)
    random.seed(cfg.seed)
    model = build_model(stereo_cfg).to(device)
    model.train()
    optimizer = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay, eps=1e-8)
    scheduler = torch.optim.lr_scheduler.OneCycleLR(optimizer, cfg.lr, total_steps=cfg.steps + 100, pct_start=0.01,
                                                    cycle_momentum=False, anneal_strategy="linear")
    step = 0
    if resume:
        ckpt = load_checkpoint(ckpt_path, map_location=str(device))
        saved = ckpt.get("train_config", {})
        for key in ("variant", "preset", "size", "batch", "stereo"):
            if key in saved and json.loads(json.dumps(saved[key])) != json.loads(json.dumps(getattr(cfg, key))):
                raise SpaceposeError(f"cannot resume: {key} differs from the checkpoint ({saved[key]!r} vs {getattr(cfg, key)!r})")
        model.load_state_dict(ckpt["model"])
        optimizer.load_state_dict(ckpt["optimizer"])
        scheduler.load_state_dict(ckpt["scheduler"])
        step = int(ckpt["step"])
        _set_rng_state(ckpt["rng"])
        log.info("resumed %s at step %d", ckpt_path, step)

    net = model
    if world > 1:
        net = torch.nn.parallel.DistributedDataParallel(model, device_ids=[local_rank] if device.type == "cuda" else None)

    train_set = StereoCropDataset(cfg.dataset, "train", cfg.crop_config(True), seed=cfg.seed, limit=cfg.limit)
    try:
        val_set = StereoCropDataset(cfg.dataset, "test", cfg.crop_config(False), seed=cfg.seed,
                                    limit=cfg.val_samples, deterministic=True)
    except DatasetError:
        val_set = None
        log.warning("no test split: validation disabled")
    sampler = EpochSampler(len(train_set), cfg.seed, rank, world)
    batches_per_epoch = max(sampler.per_rank() // cfg.batch, 1)
    if rank == 0:
        config_doc = {"train": dataclasses.asdict(cfg), "stereo": stereo_cfg.to_dict(), "world_size": world,
                      "device": str(device), "commit": git_commit(), "train_frames": len(train_set)}
        (out / "config.json").write_text(json.dumps(config_doc, indent=2, default=list))
    log_fh = open(out / "log.jsonl", "a", encoding="utf-8") if rank == 0 else None

    def save() -> None:
        if rank != 0:
            return
        _atomic_save({"model": model.state_dict(), "optimizer": optimizer.state_dict(),
                      "scheduler": scheduler.state_dict(), "step": step, "rng": _rng_state(),
                      "train_config": json.loads(json.dumps(dataclasses.asdict(cfg), default=list)),
                      "stereo_config": stereo_cfg.to_dict(), "commit": git_commit(),
                      "dataset": {"path": str(cfg.dataset), "train_frames": len(train_set)}}, ckpt_path)

    def write_log(entry: dict[str, Any]) -> None:
        if log_fh is not None:
            log_fh.write(json.dumps(entry) + "\n")
            log_fh.flush()

    last: dict[str, float] = {}
    t_last = time.perf_counter()
    try:
        while step < cfg.steps:
            epoch, pos = divmod(step, batches_per_epoch)
            sampler.set_epoch(epoch, skip=pos * cfg.batch)
            train_set.set_epoch(epoch)
            loader = DataLoader(train_set, batch_size=cfg.batch, sampler=sampler, num_workers=cfg.workers,
                                drop_last=True, persistent_workers=False)
            for batch in loader:
                left, right = batch["left"].to(device), batch["right"].to(device)
                gt, valid = batch["disparity"].to(device), batch["valid"].to(device)
                init_disp, preds = net(left, right, iters=cfg.iters)
                loss, metrics = _sequence_loss(init_disp, preds, gt, valid, stereo_cfg.max_disp)
                optimizer.zero_grad(set_to_none=True)
                loss.backward()
                grad_norm = torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.clip)
                optimizer.step()
                scheduler.step()
                step += 1
                last = {"loss": float(loss.detach()), **_to_float(metrics)}
                if step % cfg.log_every == 0 or step == cfg.steps:
                    now = time.perf_counter()
                    write_log({"step": step, **last, "grad_norm": float(grad_norm), "lr": scheduler.get_last_lr()[0],
                               "s_per_step": (now - t_last) / cfg.log_every, "epoch": epoch})
                    t_last = now
                    log.info("step %d loss %.4f", step, last["loss"])
                if val_set is not None and rank == 0 and (step % cfg.val_every == 0 or step == cfg.steps):
                    v = validate(model, val_set, device, stereo_cfg.iters or cfg.iters)
                    write_log({"step": step, **v})
                    last.update(v)
                if step % cfg.ckpt_every == 0:
                    save()
                if step >= cfg.steps:
                    break
    finally:
        save()
        if log_fh is not None:
            log_fh.close()
        if world > 1 and dist.is_initialized():
            dist.destroy_process_group()
    return {"step": step, "checkpoint": str(ckpt_path), **last}
