"""Plumbing shared by the stereo and pose training loops (:mod:`~spacepose.tools.train_stereo`,
:mod:`~spacepose.tools.train_pose`): run-folder checks, torch.distributed setup, seeding, RNG state
capture/restore, atomic checkpoints, resume, the per-epoch sampler and the JSONL log.
"""

from __future__ import annotations

import json
import logging
import math
import os
import random
import time
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Sequence

import numpy as np
import torch
import torch.distributed as dist
from torch.utils.data import DataLoader, Sampler

from spacepose.errors import SpaceposeError
from spacepose.export.metadata import git_commit

log = logging.getLogger(__name__)

__all__ = ["CHECKPOINT_NAME", "EpochSampler", "RunContext", "SchedulePacer", "git_commit", "to_json", "rng_state",
           "set_rng_state", "seed_all", "atomic_save", "load_checkpoint", "dist_setup", "start_run",
           "resume_training", "wrap_ddp", "JsonlLog", "finish_run", "run_steps"]

CHECKPOINT_NAME = "last.pt"


def to_json(obj: Any) -> Any:
    """``obj`` as it reads back from JSON (tuples -> lists; other sequences through ``list``)."""
    return json.loads(json.dumps(obj, default=list))


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


def rng_state() -> dict[str, Any]:
    """torch / numpy / python (and CUDA) global RNG states."""
    state = {"torch": torch.get_rng_state(), "numpy": np.random.get_state(), "python": random.getstate()}
    if torch.cuda.is_available():
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def set_rng_state(state: dict[str, Any]) -> None:
    """Restore what :func:`rng_state` captured."""
    torch.set_rng_state(state["torch"])
    np.random.set_state(state["numpy"])
    random.setstate(state["python"])
    if "cuda" in state and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])


def seed_all(seed: int) -> None:
    torch.manual_seed(seed)
    np.random.seed(seed)
    random.seed(seed)


def atomic_save(obj: Any, path: Path) -> None:
    """``torch.save`` to ``path.tmp``, then rename over ``path``."""
    tmp = path.with_name(path.name + ".tmp")
    torch.save(obj, tmp)
    os.replace(tmp, path)


def load_checkpoint(path: str | Path, map_location: str = "cpu", kind: str | None = None) -> dict[str, Any]:
    """A training checkpoint; with ``kind``, it must be a dict whose ``"kind"`` is ``kind``."""
    p = Path(path)
    if not p.is_file():
        raise SpaceposeError(f"checkpoint not found: {p}")
    try:
        ckpt = torch.load(p, map_location=map_location, weights_only=False)
    except Exception as err:  # torch raises pickle/zip errors of many types
        raise SpaceposeError(f"cannot read checkpoint {p}: {err}") from err
    if kind is not None and (not isinstance(ckpt, dict) or ckpt.get("kind") != kind):
        raise SpaceposeError(f"{p} is not a {kind} checkpoint "
                             f"(kind={ckpt.get('kind') if isinstance(ckpt, dict) else None!r})")
    return ckpt


def freeze_folded_batchnorm(model: torch.nn.Module, folded: Sequence[str]) -> None:
    """Freeze the BatchNorms of a model whose BatchNorms are folded identities (``folded`` non-empty:
    weights rebuilt from a graph by ``spacepose recover-checkpoint``); see
    :func:`spacepose.export.recover.freeze_batchnorm`."""
    if not folded:
        return
    from spacepose.export.recover import freeze_batchnorm

    n = freeze_batchnorm(model)
    log.info("%d BatchNorms frozen (weights from a graph: %d folded)", n, len(folded))


def dist_setup() -> tuple[int, int, int]:
    """(rank, world size, local rank); initialises the process group under ``torchrun``."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world > 1 and not dist.is_initialized():
        dist.init_process_group(backend="nccl" if torch.cuda.is_available() else "gloo")
    rank = dist.get_rank() if dist.is_initialized() else 0
    return rank, world if dist.is_initialized() else 1, int(os.environ.get("LOCAL_RANK", "0"))


class RunContext:
    """Where and on what a training run runs (see :func:`start_run`)."""

    def __init__(self, rank: int, world: int, local_rank: int, device: torch.device, out: Path) -> None:
        self.rank, self.world, self.local_rank, self.device, self.out = rank, world, local_rank, device, out
        self.ckpt_path = out / CHECKPOINT_NAME


def start_run(out: str | Path, *, resume: bool, threads: int = 0) -> RunContext:
    """Distributed setup, thread count, device; checks ``OUT/last.pt`` against ``resume``; makes OUT (rank 0)."""
    rank, world, local_rank = dist_setup()
    if threads > 0:
        torch.set_num_threads(threads)
    device = torch.device(f"cuda:{local_rank}" if torch.cuda.is_available() else "cpu")
    if device.type == "cuda":
        torch.cuda.set_device(device)
    ctx = RunContext(rank, world, local_rank, device, Path(out))
    if ctx.ckpt_path.exists() and not resume:
        raise SpaceposeError(f"{ctx.ckpt_path} exists: pass --resume to continue it, or choose another --out")
    if resume and not ctx.ckpt_path.exists():
        raise SpaceposeError(f"--resume given but {ctx.ckpt_path} does not exist")
    if rank == 0:
        ctx.out.mkdir(parents=True, exist_ok=True)
    return ctx


def resume_training(ckpt: dict[str, Any], cfg: Any, keys: Iterable[str], model: torch.nn.Module,
                    optimizer: torch.optim.Optimizer, scheduler: Any) -> int:
    """Check ``keys`` of ``cfg`` against the checkpoint's train_config, restore the states; -> step."""
    saved = ckpt.get("train_config", {})
    for key in keys:
        if key in saved and to_json(saved[key]) != to_json(getattr(cfg, key)):
            raise SpaceposeError(f"cannot resume: {key} differs from the checkpoint ({saved[key]!r} vs {getattr(cfg, key)!r})")
    model.load_state_dict(ckpt["model"])
    optimizer.load_state_dict(ckpt["optimizer"])
    scheduler.load_state_dict(ckpt["scheduler"])
    set_rng_state(ckpt["rng"])
    return int(ckpt["step"])


def wrap_ddp(model: torch.nn.Module, ctx: RunContext) -> torch.nn.Module:
    """``model`` itself, or its DistributedDataParallel wrapper when world > 1."""
    if ctx.world > 1:
        return torch.nn.parallel.DistributedDataParallel(
            model, device_ids=[ctx.local_rank] if ctx.device.type == "cuda" else None)
    return model


class JsonlLog:
    """``OUT/log.jsonl`` opened for append on rank 0 (a no-op elsewhere)."""

    def __init__(self, path: Path, enabled: bool) -> None:
        self._fh = open(path, "a", encoding="utf-8") if enabled else None

    def write(self, entry: dict[str, Any]) -> None:
        if self._fh is not None:
            self._fh.write(json.dumps(entry) + "\n")
            self._fh.flush()

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()


def finish_run(log_file: JsonlLog, ctx: RunContext) -> None:
    """Close the log and tear the process group down."""
    log_file.close()
    if ctx.world > 1 and dist.is_initialized():
        dist.destroy_process_group()


class SchedulePacer:
    """Keeps a step-indexed learning-rate schedule on pace with a wall-clock budget.

    A run stopped by ``time_limit_s`` before its ``steps`` would end with the learning rate still
    high. With a pacer, each scheduler step jumps the schedule ahead to
    ``max(its next step, steps * elapsed / seconds)`` (never past ``steps``), so the schedule has run
    its course when the time is up, whatever the throughput. The clock starts at construction; a
    resumed run continues the schedule from the step it had reached (the checkpoint's scheduler).
    ``step(scheduler)`` replaces ``scheduler.step()`` for any scheduler driven by ``last_epoch``
    (OneCycleLR, CyclicLR).
    """

    def __init__(self, steps: int, seconds: float) -> None:
        if steps < 1 or not seconds > 0:
            raise SpaceposeError(f"a schedule pacer needs steps >= 1 and seconds > 0 (got {steps}, {seconds})")
        self.steps, self.seconds = int(steps), float(seconds)
        self._t0 = time.perf_counter()

    def due(self) -> int:
        """The schedule step the clock asks for now."""
        return int(self.steps * (time.perf_counter() - self._t0) / self.seconds)

    def step(self, scheduler: Any) -> int:
        """Advance ``scheduler`` by one step, or to the step the clock is due at; returns its step."""
        target = max(scheduler.last_epoch + 1, min(self.due(), self.steps))
        scheduler.last_epoch = target - 1
        scheduler.step()
        return int(scheduler.last_epoch)


def run_steps(*, step: int, steps: int, batch: int, workers: int, train_set: Any, sampler: EpochSampler,
              train_step: Callable[[dict[str, Any]], tuple[dict[str, float], float, float]],
              validate: Callable[[], dict[str, float]] | None, save: Callable[[int], None], log_file: JsonlLog,
              ctx: RunContext, log_every: int, val_every: int, ckpt_every: int,
              time_limit_s: float | None = None) -> tuple[int, dict[str, float]]:
    """The epoch/batch loop both trainers share; returns (final step, last logged values).

    ``train_step(batch) -> (values, grad_norm, lr)`` does one optimiser step. Every ``log_every``
    steps a JSONL entry is written; every ``val_every`` steps ``validate()`` runs on rank 0; every
    ``ckpt_every`` steps and at exit (also on error or interrupt) ``save(step)`` is called, then the
    run is finished. Resuming mid-epoch skips the samples already seen (:class:`EpochSampler`).
    With ``time_limit_s`` the loop also ends (checkpoint saved, resumable) once that many seconds of
    this call have passed; under DDP the ranks agree on the stop (rank 0's clock decides).
    """
    batches_per_epoch = max(sampler.per_rank() // batch, 1)
    last: dict[str, float] = {}
    t_start = t_last = time.perf_counter()

    def out_of_time() -> bool:
        if time_limit_s is None:
            return False
        over = torch.tensor([float(time.perf_counter() - t_start >= time_limit_s)], device=ctx.device)
        if ctx.world > 1 and dist.is_initialized():
            dist.broadcast(over, src=0)
        return bool(over.item())

    try:
        while step < steps:
            epoch, pos = divmod(step, batches_per_epoch)
            sampler.set_epoch(epoch, skip=pos * batch)
            train_set.set_epoch(epoch)
            loader = DataLoader(train_set, batch_size=batch, sampler=sampler, num_workers=workers,
                                drop_last=True, persistent_workers=False)
            for item in loader:
                last, grad_norm, lr = train_step(item)
                step += 1
                if step % log_every == 0 or step == steps:
                    now = time.perf_counter()
                    log_file.write({"step": step, **last, "grad_norm": float(grad_norm), "lr": lr,
                                    "s_per_step": (now - t_last) / log_every, "epoch": epoch})
                    t_last = now
                    log.info("step %d loss %.4f lr %.2e", step, last["loss"], lr)
                if validate is not None and ctx.rank == 0 and (step % val_every == 0 or step == steps):
                    values = validate()
                    log_file.write({"step": step, **values})
                    last.update(values)
                if step % ckpt_every == 0:
                    save(step)
                if step >= steps:
                    break
                if out_of_time():
                    log.info("time limit of %.0f s reached at step %d", time_limit_s, step)
                    steps = step
                    break
    finally:
        save(step)
        finish_run(log_file, ctx)
    return step, last
