"""Session 41, exploratory: a small CPU-trained network that sharpens the stereo outline against the left image.

    python reports/outline_s41/refiner.py train TRAIN.npz... --val VAL.npz... --out CKPT [--steps N] [--seed S]
    python reports/outline_s41/refiner.py eval CKPT DATA.npz...

Input per pixel of the silhouette frame (``samples.py``): the left image relative to its 90th percentile inside the
stereo outline (clipped to [0, 2]), the stereo outline (0 / 1) and the disparity over the outline's threshold
(clipped to [0, 3]). Output: a logit per pixel that the rendered target covers it. The refined outline is the
logit > 0 inside the stereo outline dilated by ``GROW`` pixels (it can cut the stereo outline's gaps and add a thin
rim, nothing far from it). Trained on random 96-pixel crops with tone, noise and blur augmentation and the eight
flips and quarter turns, BCE over the frame's own pixels (not the padding).
"""
from __future__ import annotations

import argparse
import logging
import sys
import time

import cv2
import numpy as np

GROW = 2
CROP = 96
logger = logging.getLogger("refiner")


def inputs(grey: np.ndarray, observed: np.ndarray, disp: np.ndarray) -> np.ndarray:
    """(3, n, n) float32 network input from one sample's (n, n) planes."""
    obs = (observed > 0).astype(np.float32)
    g = grey.astype(np.float32)
    ref = float(np.percentile(g[obs > 0], 90)) if obs.any() else float(np.percentile(g, 99))
    g = np.clip(g / max(ref, 1e-3), 0.0, 2.0)
    d = np.clip(disp.astype(np.float32), 0.0, 3.0)
    return np.stack([g, obs, d])


def refine(logit: np.ndarray, observed: np.ndarray, grow: int = GROW) -> np.ndarray:
    """(n, n) uint8 refined outline: ``logit`` > 0 inside ``observed`` dilated by ``grow`` pixels."""
    near = cv2.dilate((observed > 0).astype(np.uint8), np.ones((3, 3), np.uint8), iterations=grow) > 0
    return ((logit > 0) & near).astype(np.uint8)


def make_net(width: int = 16):
    import torch
    from torch import nn

    def block(cin: int, cout: int, dilation: int = 1) -> nn.Sequential:
        return nn.Sequential(nn.Conv2d(cin, cout, 3, padding=dilation, dilation=dilation, bias=False),
                             nn.BatchNorm2d(cout), nn.ReLU(inplace=True))

    class Refiner(nn.Module):
        """(B, 3, n, n) -> (B, 1, n, n) logits; n a multiple of 4."""

        def __init__(self) -> None:
            super().__init__()
            w = width
            self.e1 = nn.Sequential(block(3, w), block(w, w))
            self.e2 = nn.Sequential(nn.MaxPool2d(2), block(w, 2 * w), block(2 * w, 2 * w))
            self.e3 = nn.Sequential(nn.MaxPool2d(2), block(2 * w, 4 * w), block(4 * w, 4 * w, 2), block(4 * w, 4 * w, 4))
            self.d2 = nn.Sequential(block(6 * w, 2 * w), block(2 * w, 2 * w))
            self.d1 = nn.Sequential(block(3 * w, w), block(w, w))
            self.head = nn.Conv2d(w, 1, 1)

        def forward(self, x: torch.Tensor) -> torch.Tensor:
            import torch.nn.functional as F
            a = self.e1(x)
            b = self.e2(a)
            c = self.e3(b)
            u = F.interpolate(c, scale_factor=2.0, mode="nearest")
            u = self.d2(torch.cat([u, b], 1))
            u = F.interpolate(u, scale_factor=2.0, mode="nearest")
            u = self.d1(torch.cat([u, a], 1))
            return self.head(u) + 4.0 * (x[:, 1:2] - 0.5)   # starts near the stereo outline

    return Refiner()


def load(paths: list[str]) -> dict[str, np.ndarray]:
    parts = [np.load(p) for p in paths]
    return {k: np.concatenate([z[k] for z in parts]) for k in ("grey", "disp", "observed", "truth", "size", "valid",
                                                                "distance", "regime")}


def _augment(x: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    g = x[0]
    g = np.clip(g / 2.0, 0.0, 1.0) ** float(np.exp(rng.uniform(np.log(0.4), np.log(2.5)))) * 2.0
    if rng.random() < 0.3:
        g = cv2.GaussianBlur(g, (0, 0), float(rng.uniform(0.5, 1.2)))
    g = g + rng.normal(0.0, float(rng.uniform(0.0, 0.06)), g.shape).astype(np.float32)
    x = x.copy()
    x[0] = np.clip(g, 0.0, 2.0)
    return x


def batch(data: dict, idx: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    xs, ys, ws = [], [], []
    for i in idx:
        n = int(data["size"][i])
        x = inputs(data["grey"][i][:n, :n], data["observed"][i][:n, :n], data["disp"][i][:n, :n])
        y = data["truth"][i][:n, :n].astype(np.float32)
        c = min(CROP, n - n % 4)
        # a crop centred near the outline's edge
        edge = np.argwhere(cv2.morphologyEx(data["observed"][i][:n, :n], cv2.MORPH_GRADIENT, np.ones((3, 3), np.uint8)))
        if len(edge):
            cy, cx = edge[rng.integers(len(edge))]
        else:
            cy, cx = n // 2, n // 2
        y0 = int(np.clip(cy - c // 2 + rng.integers(-c // 4, c // 4 + 1), 0, n - c))
        x0 = int(np.clip(cx - c // 2 + rng.integers(-c // 4, c // 4 + 1), 0, n - c))
        x, y = x[:, y0:y0 + c, x0:x0 + c], y[y0:y0 + c, x0:x0 + c]
        x = _augment(x, rng)
        k = int(rng.integers(4))
        x, y = np.rot90(x, k, axes=(1, 2)), np.rot90(y, k)
        if rng.random() < 0.5:
            x, y = x[:, :, ::-1], y[:, ::-1]
        xp = np.zeros((3, CROP, CROP), np.float32)
        yp = np.zeros((CROP, CROP), np.float32)
        wp = np.zeros((CROP, CROP), np.float32)
        xp[:, :c, :c], yp[:c, :c], wp[:c, :c] = x, y, 1.0
        xs.append(xp)
        ys.append(yp)
        ws.append(wp)
    return np.stack(xs), np.stack(ys)[:, None], np.stack(ws)[:, None]


def predict(net, data: dict, i: int) -> np.ndarray:
    """(n, n) logits of sample ``i`` (the frame padded to a multiple of 4)."""
    import torch
    n = int(data["size"][i])
    x = inputs(data["grey"][i][:n, :n], data["observed"][i][:n, :n], data["disp"][i][:n, :n])
    m = (n + 3) // 4 * 4
    xp = np.zeros((3, m, m), np.float32)
    xp[:, :n, :n] = x
    with torch.no_grad():
        return net(torch.from_numpy(xp[None]))[0, 0, :n, :n].numpy()


def iou(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a > 0, b > 0
    return float((a & b).sum() / max((a | b).sum(), 1))


def evaluate(net, data: dict, limit: int | None = None) -> dict[str, float]:
    from spacepose.silhouette import chamfer_px
    net.eval()
    rows = []
    for i in range(len(data["size"]) if limit is None else min(limit, len(data["size"]))):
        n = int(data["size"][i])
        obs, truth = data["observed"][i][:n, :n], data["truth"][i][:n, :n]
        ref = refine(predict(net, data, i), obs)
        rows.append((iou(obs, truth), iou(ref, truth), chamfer_px(obs, truth, 10.0), chamfer_px(ref, truth, 10.0)))
    r = np.asarray(rows)
    return {"iou_stereo": float(np.median(r[:, 0])), "iou_refined": float(np.median(r[:, 1])),
            "chamfer_stereo": float(np.median(r[:, 2])), "chamfer_refined": float(np.median(r[:, 3])),
            "better_chamfer": float(np.mean(r[:, 3] < r[:, 2])), "n": len(r)}


def train(paths: list[str], val: list[str], out: str, steps: int, seed: int, batch_size: int = 16,
          lr: float = 2e-3, width: int = 16) -> None:
    import torch
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    data, vdata = load(paths), load(val)
    net = make_net(width)
    opt = torch.optim.AdamW(net.parameters(), lr=lr, weight_decay=1e-4)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=lr, total_steps=steps, pct_start=0.1)
    t0 = time.time()
    for step in range(1, steps + 1):
        net.train()
        x, y, w = batch(data, rng.integers(len(data["size"]), size=batch_size), rng)
        logit = net(torch.from_numpy(x))
        loss = (torch.nn.functional.binary_cross_entropy_with_logits(logit, torch.from_numpy(y), reduction="none")
                * torch.from_numpy(w)).sum() / float(w.sum())
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        if step % 100 == 0 or step == steps:
            logger.info("step %d loss %.4f (%.0f s)", step, float(loss), time.time() - t0)
        if step % 500 == 0 or step == steps:
            logger.info("val %s", evaluate(net, vdata, limit=200))
            torch.save({"model": net.state_dict(), "width": width, "step": step, "seed": seed}, out)


def _load_net(path: str):
    import torch
    ck = torch.load(path, map_location="cpu")
    net = make_net(ck["width"])
    net.load_state_dict(ck["model"])
    return net.eval()


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
    if a.cmd == "train":
        torch.set_num_threads(a.threads)
        train(a.data, a.val, a.out, a.steps, a.seed, width=a.width)
    else:
        print(evaluate(_load_net(a.ckpt), load(a.data)))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
