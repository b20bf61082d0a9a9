"""Paper Tables 5 and 6 under one small budget.

* Table 5 (fusion direction): train ``none`` / ``rgb2pt`` / ``pt2rgb`` / ``both`` with the same
  steps, seed and data, then vote poses on the test split (:func:`spacepose.tools.train_pose.validate_pose`)
  -> median / valid share of e_t, e_R per variant.
* Table 6 (ECFT cost): ECAA (additive, linear) vs vanilla (dot-product, quadratic) attention:
  MACs of one forward pass (``torch.utils.flop_counter.FlopCounterMode``; MACs = FLOPs / 2, GMACs
  reported as the paper's "FLOPs (G)" convention is ambiguous), parameters, and peak memory of
  inference and of one training step (batch 1) — ``torch.cuda.max_memory_allocated`` on a GPU, else
  the peak of live tensor bytes from the torch profiler's memory events (fresh child process,
  parameters and inputs excluded) — for several token counts (points / crop size),
  so the growth (linear vs quadratic) is visible.

``python -m spacepose.tools.ablate_pose DATASET --out runs/ablate --steps 200`` (``--skip-train``:
Table 6 only; ``--tokens 256:64,1024:128,4096:256``: n_points:crop pairs). Writes
``OUT/ablation.json`` and ``OUT/ablation.md``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import multiprocessing
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

__all__ = ["count_macs", "peak_memory_mb", "cost_table", "fusion_table", "main"]

FUSIONS = ("none", "rgb2pt", "pt2rgb", "both")


def _model_and_feeds(net: dict[str, Any]):
    import torch

    from spacepose.export.onnx_pose import example_feeds
    from spacepose.models.pose_config import PoseNetConfig
    from spacepose.models.pose_net import PoseNet
    from spacepose.pose_inputs import pose_input_names

    cfg = PoseNetConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in net.items()})
    torch.manual_seed(0)
    model = PoseNet(cfg)
    feeds = example_feeds(cfg.input_spec())
    args = [torch.from_numpy(feeds[n]) for n in pose_input_names(cfg.n_levels)]
    return model, args


def count_macs(net: dict[str, Any]) -> dict[str, float]:
    """GMACs of one batch-1 forward pass and the parameter count of a PoseNet config (dict)."""
    import torch
    from torch.utils.flop_counter import FlopCounterMode

    model, args = _model_and_feeds(net)
    model.eval()
    counter = FlopCounterMode(display=False)
    with torch.no_grad(), counter:
        model(*args)
    flops = counter.get_total_flops()
    return {"gmacs": flops / 2e9, "gflops": flops / 1e9, "params_m": sum(p.numel() for p in model.parameters()) / 1e6}


def _cpu_peak_bytes(fn) -> int:
    """Peak of live tensor bytes allocated by ``fn`` (torch profiler memory events, CPU)."""
    from torch.profiler import ProfilerActivity, profile

    with profile(activities=[ProfilerActivity.CPU], profile_memory=True) as prof:
        fn()
    events = sorted((e for e in prof.events() if e.cpu_memory_usage), key=lambda e: e.time_range.start)
    live = peak = 0
    for e in events:
        live += e.cpu_memory_usage
        peak = max(peak, live)
    return peak


def _measure(net: dict[str, Any], train: bool, queue) -> None:  # runs in a child process
    import torch

    model, args = _model_and_feeds(net)
    cuda = torch.cuda.is_available()

    def step() -> None:
        if train:
            model.train()
            out = model(*args)
            sum(o.float().square().mean() for o in out).backward()
        else:
            model.eval()
            with torch.no_grad():
                model(*args)

    if cuda:
        model, args = model.cuda(), [a.cuda() for a in args]
        torch.cuda.synchronize()
        torch.cuda.reset_peak_memory_stats()
        base = torch.cuda.memory_allocated()
        step()
        torch.cuda.synchronize()
        peak, kind = torch.cuda.max_memory_allocated() - base, "cuda_max_allocated"
    else:
        peak, kind = _cpu_peak_bytes(step), "cpu_profiler_peak_live_tensors"
    queue.put({"mb": peak / 2**20, "kind": kind})


def peak_memory_mb(net: dict[str, Any], train: bool) -> dict[str, Any]:
    """Peak memory (MiB) of one batch-1 inference (``train=False``) or training step, in a fresh process."""
    ctx = multiprocessing.get_context("spawn")
    queue = ctx.Queue()
    proc = ctx.Process(target=_measure, args=(net, train, queue))
    proc.start()
    result = queue.get(timeout=600)
    proc.join()
    return result


def cost_table(tokens: list[tuple[int, int]], base: dict[str, Any] | None = None, memory: bool = True) -> list[dict[str, Any]]:
    """Table 6 rows: for each (n_points, crop side) and attention in (ecaa, vanilla)."""
    rows = []
    for n_points, crop in tokens:
        for attention in ("ecaa", "vanilla"):
            net = {**(base or {}), "n_points": n_points, "crop_size": [crop, crop], "attention": attention}
            row = {"attention": attention, "n_points": n_points, "crop": crop,
                   "pixel_tokens_l0": (crop // 4) ** 2, **count_macs(net)}
            if memory:
                inf, tr = peak_memory_mb(net, False), peak_memory_mb(net, True)
                row.update({"inference_mb": inf["mb"], "training_mb": tr["mb"], "memory_kind": inf["kind"]})
            rows.append(row)
            log.info("%s", row)
    return rows


def fusion_table(dataset: str, out: Path, steps: int, batch: int, net: dict[str, Any], depth_source: str,
                 val_samples: int, workers: int) -> list[dict[str, Any]]:
    """Table 5 rows: train every fusion variant with the same budget, vote poses on the test split."""
    import torch

    from spacepose.models.pose_loss import PoseLossConfig
    from spacepose.tools.pose_data import PoseDataset
    from spacepose.tools.train_pose import TrainPoseConfig, load_checkpoint, model_from_checkpoint, train_pose, validate_pose

    rows = []
    for fusion in FUSIONS:
        cfg = TrainPoseConfig(dataset=dataset, out=str(out / f"fusion_{fusion}"), steps=steps, batch=batch,
                              depth_source=depth_source, fusion=fusion, net=net, val_every=10**9,
                              ckpt_every=10**9, workers=workers)
        resume = (Path(cfg.out) / "last.pt").exists()
        if not resume or load_checkpoint(Path(cfg.out) / "last.pt")["step"] < steps:
            train_pose(cfg, resume=resume)
        model, net_cfg = model_from_checkpoint(load_checkpoint(Path(cfg.out) / "last.pt"))
        val = PoseDataset(dataset, "test", net_cfg.input_spec(), cfg.data_config(False), limit=val_samples,
                          deterministic=True)
        metrics = validate_pose(model, val, torch.device("cpu"), PoseLossConfig(offset_scale=net_cfg.xyz_scale))
        rows.append({"fusion": fusion, "rgb2pt": fusion in ("rgb2pt", "both"), "pt2rgb": fusion in ("pt2rgb", "both"),
                     "steps": steps, **metrics})
        log.info("%s", rows[-1])
    return rows


def _markdown(report: dict[str, Any]) -> str:
    lines = []
    if report.get("table5"):
        lines += ["### Table 5: fusion direction", "", "| RGB→Point | Point→RGB | e_t median (m) | e_R median (°) | valid | val loss |",
                  "|---|---|---|---|---|---|"]
        for r in report["table5"]:
            lines.append(f"| {'√' if r['rgb2pt'] else ''} | {'√' if r['pt2rgb'] else ''} | {r['val_e_t_median']:.4g} | "
                         f"{r['val_e_R_median']:.4g} | {r['val_valid']:.2f} | {r['val_loss']:.4g} |")
        lines.append("")
    if report.get("table6"):
        lines += ["### Table 6: ECFT (ECAA) vs vanilla attention", "",
                  "| attention | points | crop | GMACs | params (M) | inference (MiB) | training bs1 (MiB) |",
                  "|---|---|---|---|---|---|---|"]
        for r in report["table6"]:
            lines.append(f"| {r['attention']} | {r['n_points']} | {r['crop']} | {r['gmacs']:.3f} | {r['params_m']:.2f} | "
                         f"{r.get('inference_mb', float('nan')):.1f} | {r.get('training_mb', float('nan')):.1f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m spacepose.tools.ablate_pose", description=__doc__.split("\n")[0])
    parser.add_argument("dataset", nargs="?", default=None)
    parser.add_argument("--out", type=Path, default=Path("runs/ablate_pose"))
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--batch", type=int, default=8)
    parser.add_argument("--depth-source", choices=("stereo", "gt_noisy"), default="gt_noisy")
    parser.add_argument("--net", default="{}", help="PoseNetConfig overrides as JSON")
    parser.add_argument("--val-samples", type=int, default=32)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--tokens", default="256:64,1024:128,4096:256", help="n_points:crop pairs for Table 6")
    parser.add_argument("--skip-train", action="store_true", help="Table 6 only")
    parser.add_argument("--no-memory", action="store_true", help="Table 6 without memory (MACs only)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    net = json.loads(args.net)
    args.out.mkdir(parents=True, exist_ok=True)
    report: dict[str, Any] = {"args": {k: str(v) for k, v in vars(args).items()}}
    if not args.skip_train:
        if args.dataset is None:
            parser.error("DATASET is needed for Table 5 (or pass --skip-train)")
        report["table5"] = fusion_table(args.dataset, args.out, args.steps, args.batch, net, args.depth_source,
                                        args.val_samples, args.workers)
    tokens = [tuple(int(v) for v in pair.split(":")) for pair in args.tokens.split(",") if pair]
    report["table6"] = cost_table(tokens, net, memory=not args.no_memory)
    (args.out / "ablation.json").write_text(json.dumps(report, indent=1, default=str))
    text = _markdown(report)
    (args.out / "ablation.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
