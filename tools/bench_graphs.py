"""onnxruntime vs torch eager on the shipped graphs, fed the inputs the flight pipeline really builds.

The stereo and pose inputs of ``--frames`` dataset frames are recorded by running the estimator on
them (:func:`spacepose.export.quantize.record_calibration_feeds`); each graph then runs on those same
inputs in onnxruntime (the bundle's ONNX file, optionally more bundles, e.g. int8 / fp16 copies) and in
torch eager (the training checkpoint the graph was exported from), with the same thread count, in
one process per backend so that neither warms the other's caches. Median and p95 milliseconds per
call and the speed-up are printed as a markdown table and written as JSON. Timings are never
asserted in tests.

This machine's speed drifts by up to 40 % from one process to the next (session 13: the same graph
took 92 and 131 ms median in two runs a minute apart). ``--rounds N`` therefore runs every backend's
process N times, in turn (round r starts at backend r), pools all their calls for the median and
p95, so that a drift hits every backend alike. It also records each round's median and each round's
speed-up over torch eager; the median of those speed-ups is the steadier figure when the drift is
slower than a round.

    python -m spacepose.tools.bench_graphs data/tdrs640 --stereo-ckpt runs/stereo_full/last.pt \
        --pose-ckpt runs/pose_both/last.pt --threads 2 --out reports/bench_graphs.json \
        [--extra-bundle int8=runs/bundle_int8 --extra-bundle fp16=runs/bundle_fp16]
"""

from __future__ import annotations

import argparse
import json
import pickle
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["time_calls", "summarize", "run_rounds", "add_round_speedups", "main"]


def time_calls(fn, feeds: list[Any], repeats: int) -> dict[str, float]:
    """Median / p95 / mean milliseconds of ``fn(feed)`` over ``repeats`` passes over ``feeds`` (1 warm-up pass)."""
    for feed in feeds:
        fn(feed)
    times = []
    for _ in range(repeats):
        for feed in feeds:
            t0 = time.perf_counter()
            fn(feed)
            times.append((time.perf_counter() - t0) * 1e3)
    return summarize(times)


def summarize(times_ms: list[float]) -> dict[str, Any]:
    """Median / p95 / mean milliseconds and the call count of ``times_ms``, plus the times themselves."""
    arr = np.asarray(times_ms, dtype=np.float64)
    return {"median_ms": float(np.median(arr)), "p95_ms": float(np.percentile(arr, 95)), "mean_ms": float(arr.mean()),
            "calls": int(arr.size), "times_ms": [round(float(t), 3) for t in arr]}


def _worker(args: argparse.Namespace) -> None:
    with open(args.feeds, "rb") as fh:
        feeds = pickle.load(fh)[args.graph]
    if args.backend == "ort":
        from spacepose.onnx_session import make_session

        # the session options of the flight runtime: both keep onnxruntime's memory arena, the stereo
        # stage lets its workers spin (spacepose.stereo_stage.StereoMatcher, spacepose.estimator)
        session = make_session(args.onnx, threads=args.threads, spinning=args.graph == "stereo", mem_arena=True)
        outputs = [o.name for o in session.get_outputs()]
        result = time_calls(lambda f: session.run(outputs, f), feeds, args.repeats)
    else:
        import torch

        torch.set_num_threads(args.threads)
        if args.graph == "stereo":
            from spacepose.tools.train_stereo import load_checkpoint, model_from_checkpoint

            model, _ = model_from_checkpoint(load_checkpoint(args.ckpt))
            model.eval()
            iters = int(args.iters)

            def run(f):
                with torch.inference_mode():
                    return model(torch.from_numpy(f["left"]), torch.from_numpy(f["right"]), iters=iters, test_mode=True)
        else:
            from spacepose.tools.train_pose import load_checkpoint, model_from_checkpoint

            model, _ = model_from_checkpoint(load_checkpoint(args.ckpt))

            def run(f):
                with torch.inference_mode():
                    return model.forward_dict({k: torch.from_numpy(v) for k, v in f.items()})
        result = time_calls(run, feeds, args.repeats)
    print(json.dumps(result))


def _child(graph: str, backend: str, feeds_path: Path, args: argparse.Namespace, onnx_path: str | None = None,
           iters: int | None = None) -> dict[str, Any]:
    cmd = [sys.executable, "-m", "spacepose.tools.bench_graphs", "--worker", "--graph", graph, "--backend", backend,
           "--feeds", str(feeds_path), "--threads", str(args.threads), "--repeats", str(args.repeats)]
    if onnx_path:
        cmd += ["--onnx", onnx_path]
    if backend == "torch":
        cmd += ["--ckpt", str(args.stereo_ckpt if graph == "stereo" else args.pose_ckpt), "--iters", str(iters or 0)]
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        return {"error": proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else f"exit {proc.returncode}"}
    return json.loads(proc.stdout.strip().splitlines()[-1])


def run_rounds(jobs: list[tuple[str, str, dict[str, Any]]], child, rounds: int) -> list[dict[str, Any]]:
    """One row per job, ``{"graph", "backend", median_ms, p95_ms, mean_ms, calls, round_medians_ms}``
    (or ``"error"``), from ``rounds`` runs of every job's ``child(graph, kwargs)``, each round's order
    rotated by one job within each graph; the times of all rounds are pooled."""
    times: dict[int, list[float]] = {i: [] for i in range(len(jobs))}
    medians: dict[int, list[float]] = {i: [] for i in range(len(jobs))}
    errors: dict[int, str] = {}
    for r in range(max(int(rounds), 1)):
        for graph in dict.fromkeys(job[0] for job in jobs):
            ids = [i for i, job in enumerate(jobs) if job[0] == graph]
            for i in ids[r % len(ids):] + ids[:r % len(ids)]:
                if i in errors:
                    continue
                result = child(graph, jobs[i][2])
                if "error" in result:
                    errors[i] = result["error"]
                    continue
                times[i] += result["times_ms"]
                medians[i].append(result["median_ms"])
    rows = []
    for i, (graph, label, _) in enumerate(jobs):
        if i in errors:
            rows.append({"graph": graph, "backend": label, "error": errors[i]})
        else:
            rows.append({"graph": graph, "backend": label, **summarize(times[i]), "round_medians_ms": medians[i]})
    return rows


def _torch_row(rows: list[dict[str, Any]], graph: str) -> dict[str, Any] | None:
    """The torch eager row of ``graph`` that has timings, if any."""
    return next((x for x in rows if x["graph"] == graph and x["backend"].startswith("torch") and "median_ms" in x),
                None)


def add_round_speedups(rows: list[dict[str, Any]]) -> None:
    """Set ``row["round_speedups"]``: per round, torch eager's median over the row's (same graph), for
    rows that ran every round, as torch did."""
    for r in rows:
        torch_row = _torch_row(rows, r["graph"])
        if torch_row is not None and "median_ms" in r and len(r["round_medians_ms"]) == len(torch_row["round_medians_ms"]):
            r["round_speedups"] = [t / m for t, m in zip(torch_row["round_medians_ms"], r["round_medians_ms"])]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m spacepose.tools.bench_graphs", description=__doc__.split("\n")[0])
    parser.add_argument("dataset", nargs="?")
    parser.add_argument("--bundle", default=None, help="bundle folder (default: shipped)")
    parser.add_argument("--stereo-ckpt", type=Path, default=None)
    parser.add_argument("--pose-ckpt", type=Path, default=None)
    parser.add_argument("--extra-bundle", action="append", default=[], help="NAME=FOLDER: also time its ONNX graphs")
    parser.add_argument("--frames", type=int, default=4)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--rounds", type=int, default=1,
                        help="run every backend's process this many times, in turn, and pool the calls")
    parser.add_argument("--out", type=Path, default=None)
    # worker mode (one backend in a fresh process)
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--graph", choices=("stereo", "pose"), help=argparse.SUPPRESS)
    parser.add_argument("--backend", choices=("ort", "torch"), help=argparse.SUPPRESS)
    parser.add_argument("--feeds", help=argparse.SUPPRESS)
    parser.add_argument("--onnx", help=argparse.SUPPRESS)
    parser.add_argument("--ckpt", help=argparse.SUPPRESS)
    parser.add_argument("--iters", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        _worker(args)
        return 0
    if args.dataset is None:
        parser.error("DATASET is needed")

    from spacepose.bundle import load_bundle
    from spacepose.export.quantize import record_calibration_feeds
    from spacepose.onnx_session import read_metadata

    bundle = load_bundle(args.bundle)
    stereo_feeds, pose_feeds = record_calibration_feeds(bundle.path, args.dataset, args.frames, split="test")
    iters = int(read_metadata(bundle.stereo_path)["iters"])
    with tempfile.TemporaryDirectory() as tmp:
        feeds_path = Path(tmp) / "feeds.pkl"
        with open(feeds_path, "wb") as fh:
            pickle.dump({"stereo": stereo_feeds, "pose": pose_feeds}, fh)
        bundles = [("fp32", bundle)] + [(name, load_bundle(folder)) for name, folder in
                                        (item.split("=", 1) for item in args.extra_bundle)]
        jobs = []  # (graph, backend label, child kwargs)
        for graph, ckpt in (("stereo", args.stereo_ckpt), ("pose", args.pose_ckpt)):
            for name, b in bundles:
                path = str(b.stereo_path if graph == "stereo" else b.pose_path)
                jobs.append((graph, f"onnxruntime {name}", {"backend": "ort", "onnx_path": path}))
            if ckpt is not None:
                jobs.append((graph, "torch eager fp32", {"backend": "torch", "iters": iters}))
        rows = run_rounds(jobs, lambda graph, kw: _child(graph, kw["backend"], feeds_path, args,
                                                         onnx_path=kw.get("onnx_path"), iters=kw.get("iters")),
                          args.rounds)
    add_round_speedups(rows)
    lines = ["| graph | backend | calls | median ms | p95 ms | torch eager / this (median) | round medians ms "
             "| per-round speed-ups (median) |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        torch_row = _torch_row(rows, r["graph"])
        if "median_ms" not in r:
            lines.append(f"| {r['graph']} | {r['backend']} | — | error: {r.get('error')} | | | | |")
            continue
        ratio = f"{torch_row['median_ms'] / r['median_ms']:.2f}×" if torch_row else "—"
        per_round = " / ".join(f"{m:.0f}" for m in r.get("round_medians_ms", []))
        speedups = r.get("round_speedups") or []
        paired = (" / ".join(f"{v:.2f}" for v in speedups) + f" ({float(np.median(speedups)):.2f}×)") if speedups else "—"
        lines.append(f"| {r['graph']} | {r['backend']} | {r['calls']} | {r['median_ms']:.1f} | {r['p95_ms']:.1f} | {ratio} "
                     f"| {per_round} | {paired} |")
    text = "\n".join(lines)
    print(text)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps({"args": {k: str(v) for k, v in vars(args).items()}, "rows": rows,
                                        "stereo_calls": len(stereo_feeds), "pose_calls": len(pose_feeds)}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
