"""Session 41, exploratory: the outline refiner as first trained, before ``spacepose train-outline`` existed.

    python reports/outline_s41/refiner.py train TRAIN.npz... --val VAL.npz... --out CKPT [--steps N] [--seed S]
    python reports/outline_s41/refiner.py eval CKPT DATA.npz...

The network, its input planes, the training batches (crops, augmentation) and the validation are the product's
(:class:`spacepose.models.outline_refiner.OutlineRefinerNet`, :func:`spacepose.outline_refiner.refiner_planes`,
:mod:`spacepose.tools.train_outline`); they give the exploratory checkpoint ``runs/s41/refiner_a.pt`` the same
logits and the same batches as the code it was trained with (checked on 5 validation frames and one batch). What
differs from ``train-outline``: a one-cycle learning rate, one random generator for the whole run, and a checkpoint
of only the weights. Validation lines then named the share of frames whose chamfer the refinement lowers
``better_chamfer`` (``lowered`` now).
"""
from __future__ import annotations

import argparse
import logging
import sys
import time

import numpy as np

logger = logging.getLogger("refiner")


def _load_net(path: str):
    """The exploratory checkpoint's network (eval mode)."""
    import torch

    from spacepose.models.outline_refiner import OutlineRefinerConfig, OutlineRefinerNet

    ck = torch.load(path, map_location="cpu")
    net = OutlineRefinerNet(OutlineRefinerConfig(width=ck["width"]))
    net.load_state_dict(ck["model"])
    return net.eval()


def train(paths: list[str], val: list[str], out: str, steps: int, seed: int, batch_size: int = 16,
          lr: float = 2e-3, width: int = 16, crop: int = 96) -> None:
    import torch

    from spacepose.models.outline_refiner import OutlineRefinerConfig, OutlineRefinerNet
    from spacepose.tools.outline_data import load_outline_samples
    from spacepose.tools.train_outline import evaluate, make_batch

    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    data, vdata = load_outline_samples(paths), load_outline_samples(val)
    net = OutlineRefinerNet(OutlineRefinerConfig(width=width))
    opt = torch.optim.AdamW(net.parameters(), lr=lr, weight_decay=1e-4)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=lr, total_steps=steps, pct_start=0.1)
    t0 = time.time()
    for step in range(1, steps + 1):
        net.train()
        x, y, w = make_batch(data, rng.integers(len(data["size"]), size=batch_size), crop, rng)
        logit = net(torch.from_numpy(x))
        loss = (torch.nn.functional.binary_cross_entropy_with_logits(logit, torch.from_numpy(y), reduction="none")
                * torch.from_numpy(w)).sum() / float(w.sum())
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        if step % 100 == 0 or step == steps:
            logger.info("step %d loss %.4f (%.0f s)", step, float(loss.detach()), time.time() - t0)
        if step % 500 == 0 or step == steps:
            logger.info("val %s", evaluate(net, vdata, 200))
            torch.save({"model": net.state_dict(), "width": width, "step": step, "seed": seed}, out)


def main(argv: list[str]) -> int:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("train")
    t.add_argument("data", nargs="+")
    t.add_argument("--val", nargs="+", required=True)
    t.add_argument("--out", required=True)
    t.add_argument("--steps", type=int, default=2000)
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--width", type=int, default=16)
    t.add_argument("--threads", type=int, default=2)
    e = sub.add_parser("eval")
    e.add_argument("ckpt")
    e.add_argument("data", nargs="+")
    a = p.parse_args(argv)
    import torch

    from spacepose.tools.outline_data import load_outline_samples
    from spacepose.tools.train_outline import evaluate

    if a.cmd == "train":
        torch.set_num_threads(a.threads)
        train(a.data, a.val, a.out, a.steps, a.seed, width=a.width)
    else:
        data = load_outline_samples(a.data)
        print(evaluate(_load_net(a.ckpt), data, len(data["size"])))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
