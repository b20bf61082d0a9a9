"""Paper Table 4 (TSCA-Stereo ablation) under one training budget.

Every variant of :data:`spacepose.models.stereo_config.VARIANTS` (IGEV baseline, +Triplet Attention,
+SECA, full) is trained from scratch with the same steps, batch, crop, seed and data, exported to ONNX
with the same iteration count and input size, and evaluated by the project's evaluation
(:func:`spacepose.tools.eval_stereo.evaluate_stereo`: the flight stereo stage on the test split, target
pixels) — so the rows differ only by the variant. Each variant's run folder is resumable.

    python -m spacepose.tools.ablate_stereo data/tdrs640 --out runs/ablate_stereo --steps 300 \
        --batch 4 --train-crop 160x160 --threads 1 --limit-eval 100

Writes ``OUT/ablation.json`` and ``OUT/ablation.md`` (EPE, D1, bad-1/3, parameters, graph latency).
The stage latency measured during evaluation shares the CPU with whatever else runs; ``--retime``
re-times every exported graph alone (onnxruntime, ``--threads``, median of 10 calls) into the table,
to be run on a quiet machine.
"""

from __future__ import annotations

import argparse
import json
import logging
import time
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

__all__ = ["variant_row", "graph_latency_ms", "format_table", "main"]


def variant_row(dataset: str, out: Path, variant: str, *, steps: int, batch: int, train_crop: tuple[int, int] | None,
                threads: int, seed: int, iters: int, size: tuple[int, int], limit_eval: int | None) -> dict[str, Any]:
    """Train (or resume), export and evaluate one variant; returns its Table 4 row."""
    from spacepose.export.onnx_stereo import export_checkpoint
    from spacepose.tools.eval_stereo import evaluate_stereo
    from spacepose.tools.train_stereo import TrainConfig, load_checkpoint, train_stereo

    run = out / variant
    ckpt = run / "last.pt"
    cfg = TrainConfig(dataset=dataset, out=str(run), steps=steps, batch=batch, variant=variant, train_crop=train_crop,
                      threads=threads, seed=seed, iters=iters, size=size, val_every=10**9, ckpt_every=100)
    t0 = time.perf_counter()
    if not ckpt.exists() or load_checkpoint(ckpt)["step"] < steps:
        train_stereo(cfg, resume=ckpt.exists())
    train_s = time.perf_counter() - t0
    state = load_checkpoint(ckpt)
    params_m = sum(v.numel() for k, v in state["model"].items()
                   if "running_" not in k and "num_batches_tracked" not in k) / 1e6
    exported = export_checkpoint(ckpt, run / "stereo.onnx", iters=iters, size=size, force=True)
    report = evaluate_stereo(dataset, exported["path"], limit=limit_eval, threads=threads)
    (run / "stereo_eval.json").write_text(json.dumps(report, indent=1, default=float))
    ours = report["ours"]["overall"]
    return {"variant": variant, "steps": int(state["step"]), "params_m": params_m, "train_s_this_call": train_s,
            "parity_px": exported["parity_max_abs_px"], "frames": report["frames"],
            "latency_ms_median": report["latency_ms_median"]["ours"],
            **{k: ours[k] for k in ("epe", "rmse", "bad1", "bad3", "d1", "density")},
            "per_regime_epe": {g.split(":", 1)[1]: v["epe"] for g, v in report["ours"].items() if g.startswith("regime:")},
            "sgbm": {k: report["sgbm"]["overall"][k] for k in ("epe", "d1")}}


def graph_latency_ms(onnx_path: str | Path, threads: int, calls: int = 10) -> float:
    """Median milliseconds of one call of a stereo graph on a textured pair (after one warm-up call)."""
    from spacepose.export.onnx_stereo import parity_inputs
    from spacepose.onnx_session import make_session, session_metadata
    from spacepose.tools.bench_graphs import time_calls

    session = make_session(onnx_path, threads=threads)
    left, right = parity_inputs(tuple(session_metadata(session)["input_size"]), disparity=12.0)
    return time_calls(lambda f: session.run(["disparity"], f), [{"left": left, "right": right}], calls)["median_ms"]


def format_table(rows: list[dict[str, Any]]) -> str:
    """Markdown Table 4: one row per variant (TA / SECA marks as in the paper)."""
    marks = {"igev": ("", ""), "ta": ("√", ""), "seca": ("", "√"), "full": ("√", "√")}
    quiet = any("graph_ms_quiet" in r for r in rows)
    lines = ["| variant | TA | SECA | params (M) | steps | EPE px | D1 % | bad-1 % | bad-3 % | stage latency ms (eval, shared CPU) |"
             + (" graph ms (quiet, alone) |" if quiet else ""),
             "|---|---|---|---|---|---|---|---|---|---|" + ("---|" if quiet else "")]
    for r in rows:
        ta, seca = marks.get(r["variant"], ("?", "?"))
        lines.append(f"| {r['variant']} | {ta} | {seca} | {r['params_m']:.2f} | {r['steps']} | {r['epe']:.2f} | "
                     f"{r['d1']:.1f} | {r['bad1']:.1f} | {r['bad3']:.1f} | {r['latency_ms_median']:.0f} |"
                     + (f" {r['graph_ms_quiet']:.0f} |" if "graph_ms_quiet" in r else (" |" if quiet else "")))
    if rows:
        s = rows[0]["sgbm"]
        lines.append(f"| StereoSGBM (same frames) | | | | | {s['epe']:.2f} | {s['d1']:.1f} | | | |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    from spacepose.cli_args import parse_size
    from spacepose.models.stereo_config import VARIANTS

    parser = argparse.ArgumentParser(prog="python -m spacepose.tools.ablate_stereo", description=__doc__.split("\n")[0])
    parser.add_argument("dataset")
    parser.add_argument("--out", type=Path, default=Path("runs/ablate_stereo"))
    parser.add_argument("--variants", default=",".join(VARIANTS), help="comma-separated subset of " + ",".join(VARIANTS))
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--batch", type=int, default=4)
    parser.add_argument("--train-crop", type=parse_size, default=None)
    parser.add_argument("--size", type=parse_size, default=(256, 256))
    parser.add_argument("--iters", type=int, default=4)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--limit-eval", type=int, default=None, help="first N test frames only")
    parser.add_argument("--retime", action="store_true", help="only re-time the exported graphs of OUT/ablation.json")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    variants = [v for v in args.variants.split(",") if v]
    unknown = sorted(set(variants) - set(VARIANTS))
    if unknown:
        parser.error(f"unknown variants {unknown}; valid: {VARIANTS}")
    if args.retime:
        report = json.loads((args.out / "ablation.json").read_text())
        for row in report["table4"]:
            row["graph_ms_quiet"] = graph_latency_ms(args.out / row["variant"] / "stereo.onnx", args.threads)
            row["graph_ms_threads"] = args.threads
        (args.out / "ablation.json").write_text(json.dumps(report, indent=1, default=float))
        (args.out / "ablation.md").write_text(format_table(report["table4"]))
        print(format_table(report["table4"]))
        return 0
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for variant in variants:
        rows.append(variant_row(args.dataset, args.out, variant, steps=args.steps, batch=args.batch,
                                train_crop=args.train_crop, threads=args.threads, seed=args.seed, iters=args.iters,
                                size=args.size, limit_eval=args.limit_eval))
        log.info("%s", rows[-1])
        report = {"args": {k: str(v) for k, v in vars(args).items()}, "table4": rows}
        (args.out / "ablation.json").write_text(json.dumps(report, indent=1, default=float))
        (args.out / "ablation.md").write_text(format_table(rows))
    print(format_table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
