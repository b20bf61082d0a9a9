"""Train the outline refiner (:class:`spacepose.models.outline_refiner.OutlineRefinerNet`) on outline samples.

``spacepose train-outline TRAIN.npz... --val VAL.npz... --out runs/outline`` (samples of
:mod:`spacepose.tools.outline_data`) trains with AdamW and a cosine learning rate (a tenth warming up) on random ``--crop``-pixel crops
near the stereo outline's edge, binary cross-entropy against the rendered mask over the frame's own pixels (not the
padding), with tone (a power log-uniform in [0.4, 2.5]), blur and noise augmentation of the grey plane and the eight
flips and quarter turns. Checkpoints ``OUT/last.pt`` every ``--ckpt-every`` steps (``--resume`` continues one),
a JSON line per logged step in ``OUT/log.jsonl``, and validation every ``--val-every`` steps on the first
``--val-frames`` validation samples: the median IoU and chamfer (pixels) against the rendered mask of the stereo and
of the refined outline (:func:`spacepose.outline_refiner.refined_outline`, ``grow_px`` 2), and the share of frames
whose chamfer the refinement lowers. One CPU hour is plenty (2,000 steps of 16 crops took 10 minutes on 2 threads).
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import math
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np

HELP = "train the outline refiner (the stereo outline sharpened against the left image) on outline samples"

log = logging.getLogger(__name__)

KIND = "outline"
GROW = 2


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("data", type=Path, nargs="+", help="sample files (python -m spacepose.tools.outline_data)")
    parser.add_argument("--val", type=Path, nargs="+", required=True, help="sample files of other frames")
    parser.add_argument("--out", type=Path, default=Path("runs/outline"))
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--batch", type=int, default=16)
    parser.add_argument("--crop", type=int, default=96, help="side of the training crops (a multiple of 4)")
    parser.add_argument("--lr", type=float, default=2e-3)
    parser.add_argument("--weight-decay", type=float, default=1e-4)
    parser.add_argument("--width", type=int, default=16)
    parser.add_argument("--val-frames", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--ckpt-every", type=int, default=100)
    parser.add_argument("--val-every", type=int, default=500)
    parser.add_argument("--resume", action="store_true")


def _augment(planes: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The (3, c, c) ``planes`` with the grey plane under another tone curve, maybe blurred, with noise."""
    g = np.clip(planes[0] / 2.0, 0.0, 1.0) ** float(np.exp(rng.uniform(np.log(0.4), np.log(2.5)))) * 2.0
    if rng.random() < 0.3:
        g = cv2.GaussianBlur(g, (0, 0), float(rng.uniform(0.5, 1.2)))
    g = g + rng.normal(0.0, float(rng.uniform(0.0, 0.06)), g.shape).astype(np.float32)
    out = planes.copy()
    out[0] = np.clip(g, 0.0, 2.0)
    return out


def sample_planes(data: dict[str, np.ndarray], i: int) -> tuple[np.ndarray, np.ndarray]:
    """``(planes (3, n, n), truth (n, n) float32)`` of sample ``i`` (:func:`spacepose.outline_refiner.refiner_planes`)."""
    from spacepose.outline_refiner import refiner_planes

    n = int(data["size"][i])
    planes = refiner_planes(data["grey"][i][:n, :n].astype(np.float32), data["observed"][i][:n, :n],
                            data["disp"][i][:n, :n].astype(np.float32))
    return planes, data["truth"][i][:n, :n].astype(np.float32)


def make_batch(data: dict[str, np.ndarray], idx: np.ndarray, crop: int, rng: np.random.Generator
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(B, 3, crop, crop) planes, (B, 1, crop, crop) truth and (B, 1, crop, crop) weights (0 on padding): a crop
    of each sample near a random point of its stereo outline's edge, augmented, turned and mirrored."""
    xs, ys, ws = [], [], []
    kernel = np.ones((3, 3), np.uint8)
    for i in idx:
        planes, truth = sample_planes(data, int(i))
        n = planes.shape[1]
        c = min(crop, n - n % 4)
        edge = np.argwhere(cv2.morphologyEx((planes[1] > 0).astype(np.uint8), cv2.MORPH_GRADIENT, kernel))
        cy, cx = edge[rng.integers(len(edge))] if len(edge) else (n // 2, n // 2)
        y0 = int(np.clip(cy - c // 2 + rng.integers(-(c // 4), c // 4 + 1), 0, n - c))
        x0 = int(np.clip(cx - c // 2 + rng.integers(-(c // 4), c // 4 + 1), 0, n - c))
        x, y = _augment(planes[:, y0:y0 + c, x0:x0 + c], rng), truth[y0:y0 + c, x0:x0 + c]
        k = int(rng.integers(4))
        x, y = np.rot90(x, k, axes=(1, 2)), np.rot90(y, k)
        if rng.random() < 0.5:
            x, y = x[:, :, ::-1], y[:, ::-1]
        xp, yp, wp = np.zeros((3, crop, crop), np.float32), np.zeros((crop, crop), np.float32), \
            np.zeros((crop, crop), np.float32)
        xp[:, :c, :c], yp[:c, :c], wp[:c, :c] = x, y, 1.0
        xs.append(xp)
        ys.append(yp)
        ws.append(wp)
    return np.stack(xs), np.stack(ys)[:, None], np.stack(ws)[:, None]


def frame_logits(model: Any, planes: np.ndarray) -> np.ndarray:
    """(n, n) logits of the torch ``model`` on one frame's (3, n, n) ``planes`` (zero-padded to a multiple of 4)."""
    import torch

    n = planes.shape[1]
    m = -(-n // 4) * 4
    feed = np.zeros((1, 3, m, m), np.float32)
    feed[0, :, :n, :n] = planes
    with torch.no_grad():
        return model(torch.from_numpy(feed))[0, 0, :n, :n].numpy()


def evaluate(model: Any, data: dict[str, np.ndarray], limit: int) -> dict[str, float]:
    """Median IoU and chamfer (pixels, capped at 10) against the rendered mask of the stereo and the refined
    outline over the first ``limit`` samples, and the share whose chamfer the refinement lowers."""
    from spacepose.outline_refiner import refined_outline
    from spacepose.silhouette import chamfer_px

    def iou(a: np.ndarray, b: np.ndarray) -> float:
        return float((a & b).sum() / max((a | b).sum(), 1))

    model.eval()
    rows = []
    for i in range(min(limit, len(data["size"]))):
        planes, truth = sample_planes(data, i)
        obs = planes[1] > 0
        ref = refined_outline(frame_logits(model, planes), obs.astype(np.uint8), GROW) > 0
        tru = truth > 0
        rows.append((iou(obs, tru), iou(ref, tru), chamfer_px(obs.astype(np.uint8), tru.astype(np.uint8), 10.0),
                     chamfer_px(ref.astype(np.uint8), tru.astype(np.uint8), 10.0)))
    model.train()
    r = np.asarray(rows)
    return {"iou_stereo": float(np.median(r[:, 0])), "iou_refined": float(np.median(r[:, 1])),
            "chamfer_stereo": float(np.median(r[:, 2])), "chamfer_refined": float(np.median(r[:, 3])),
            "lowered": float(np.mean(r[:, 3] < r[:, 2])), "n": len(r)}


def run(args: argparse.Namespace) -> int:
    import torch

    from spacepose.errors import SpaceposeError
    from spacepose.models.outline_refiner import OutlineRefinerConfig, OutlineRefinerNet
    from spacepose.tools.outline_data import load_outline_samples
    from spacepose.tools.training_common import JsonlLog, atomic_save, load_checkpoint, seed_all, start_run

    if args.steps < 1 or args.batch < 1 or args.crop < 16 or args.crop % 4:
        raise SpaceposeError("--steps and --batch must be >= 1 and --crop a multiple of 4, >= 16")
    ctx = start_run(args.out, resume=args.resume, threads=max(1, args.threads))
    out, ckpt_path = ctx.out, ctx.ckpt_path
    train, val = load_outline_samples(args.data), load_outline_samples(args.val)
    config = OutlineRefinerConfig(width=args.width)
    seed_all(args.seed)
    model = OutlineRefinerNet(config)
    optim = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=args.weight_decay)
    warm = max(1, args.steps // 10)
    sched = torch.optim.lr_scheduler.LambdaLR(
        optim, lambda k: min(1.0, (k + 1) / warm) * 0.5 * (1.0 + math.cos(math.pi * min(k, args.steps) / args.steps)))
    step = 0
    if args.resume:
        ckpt = load_checkpoint(ckpt_path, kind=KIND)
        model.load_state_dict(ckpt["model"])
        optim.load_state_dict(ckpt["optimizer"])
        sched.load_state_dict(ckpt["scheduler"])
        step = int(ckpt["step"])
    log_file = JsonlLog(out / "log.jsonl", True)
    n = len(train["size"])
    t_start, running = time.perf_counter(), []

    def save() -> None:
        atomic_save({"kind": KIND, "model": model.state_dict(), "optimizer": optim.state_dict(),
                     "scheduler": sched.state_dict(), "step": step, "net_config": dataclasses.asdict(config),
                     "train_config": {k: str(v) for k, v in vars(args).items() if not k.startswith("_")},
                     "samples": n}, ckpt_path)

    model.train()
    while step < args.steps:
        rng = np.random.default_rng([args.seed, step])
        x, y, w = make_batch(train, rng.integers(0, n, size=args.batch), args.crop, rng)
        logit = model(torch.from_numpy(x))
        weight = torch.from_numpy(w)
        loss = (torch.nn.functional.binary_cross_entropy_with_logits(logit, torch.from_numpy(y), reduction="none")
                * weight).sum() / weight.sum()
        optim.zero_grad(set_to_none=True)
        loss.backward()
        optim.step()
        sched.step()
        step += 1
        running.append(float(loss.detach()))
        if step % 50 == 0:
            log_file.write({"step": step, "loss": float(np.mean(running)), "lr": sched.get_last_lr()[0],
                            "elapsed_s": time.perf_counter() - t_start})
            log.info("step %d loss %.4f", step, np.mean(running))
            running = []
        if step % args.val_every == 0 or step == args.steps:
            metrics = evaluate(model, val, args.val_frames)
            log_file.write({"step": step, "val": metrics})
            log.info("step %d val %s", step, metrics)
        if step % args.ckpt_every == 0 or step == args.steps:
            save()
    log_file.close()
    return 0
