"""Benchmark the classical baseline (SGBM -> FPFH + RANSAC -> ICP) on a rendered dataset.

    .venv/bin/python tools/bench_classical.py DATASET [--split test] [--limit N] [--json OUT.json]

Reads ``DATASET/rig.yaml``, ``left/``, ``right/`` and ``labels.jsonl`` (CONVENTIONS layout), runs
:func:`spacepose.tools.classical_pose.estimate_classical` on each frame of the split and prints
valid %, mean/median e_t (m) and e_R (deg) over valid frames, the number of 180-degree flips
(valid frames with e_R > 90 deg) and the mean latency; writes the summary and per-frame rows as JSON.
Needs the ``[baseline]`` extra (Open3D).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

FLIP_DEG = 90.0


def summarise(rows: list[dict]) -> dict:
    """valid %, error statistics over valid frames, flip count, latency."""
    valid = [r for r in rows if r["valid"]]
    e_t = np.array([r["e_t"] for r in valid], float)
    e_r = np.array([r["e_R"] for r in valid], float)
    lat = np.array([r["timings_ms"]["total"] for r in rows], float)

    def stat(a, fn):
        return float(fn(a)) if len(a) else None

    return {
        "frames": len(rows),
        "valid": len(valid),
        "valid_pct": 100.0 * len(valid) / max(len(rows), 1),
        "e_t_mean_m": stat(e_t, np.mean),
        "e_t_median_m": stat(e_t, np.median),
        "e_R_mean_deg": stat(e_r, np.mean),
        "e_R_median_deg": stat(e_r, np.median),
        "flips": int(np.sum(e_r > FLIP_DEG)),
        "e_t_median_m_without_flips": stat(e_t[e_r <= FLIP_DEG], np.median),
        "e_R_median_deg_without_flips": stat(e_r[e_r <= FLIP_DEG], np.median),
        "latency_mean_ms": stat(lat, np.mean),
        "latency_median_ms": stat(lat, np.median),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dataset", type=Path)
    parser.add_argument("--split", default="test", choices=("test", "train", "all"))
    parser.add_argument("--limit", type=int, default=20, help="frames to run (default 20; 0 = all)")
    parser.add_argument("--target", default="tdrs")
    parser.add_argument("--json", type=Path, default=None, help="output JSON (default DATASET/bench_classical.json)")
    args = parser.parse_args(argv)

    from spacepose.calibration.rig import load_rig
    from spacepose.imageio import read_image
    from spacepose.metrics import rotation_error_deg, translation_error
    from spacepose.tools.classical_pose import ClassicalConfig, estimate_classical, model_cloud
    from spacepose.tools.dataset import iter_labels
    from spacepose.tools.targets import load_target

    config = ClassicalConfig()
    rig = load_rig(args.dataset / "rig.yaml")
    K = np.asarray(rig.M1, dtype=np.float64)  # the dataset's frames are ideal: raw = rectified
    points, normals = model_cloud(load_target(args.target), n=config.model_points, seed=0)
    labels = [lab for lab in iter_labels(args.dataset) if args.split == "all" or lab["split"] == args.split]
    if args.limit:
        labels = labels[: args.limit]
    if not labels:
        print(f"no {args.split} frames in {args.dataset}", file=sys.stderr)
        return 1

    rows = []
    print(f"{'frame':>8} {'regime':>8} {'z_m':>6} {'valid':>5} {'fit':>5} {'e_t_m':>7} {'e_R_deg':>7} {'ms':>6}")
    for lab in labels:
        name = lab["frame"]
        left = read_image(args.dataset / "left" / f"{name}.png")
        right = read_image(args.dataset / "right" / f"{name}.png")
        result = estimate_classical(left, right, K, rig.baseline_m, points, normals, config)
        R_gt, t_gt = np.asarray(lab["R"], float), np.asarray(lab["t"], float)
        row = {
            "frame": name,
            "regime": lab.get("regime"),
            "z_m": float(t_gt[2]),
            "valid": result.valid,
            "status": result.status,
            "fitness": result.fitness,
            "rmse_m": result.rmse if np.isfinite(result.rmse) else None,
            "n_points": result.n_points,
            "e_t": translation_error(t_gt, result.t),
            "e_R": rotation_error_deg(R_gt, result.R),
            "timings_ms": {k: round(v, 2) for k, v in result.timings_ms.items()},
        }
        rows.append(row)
        print(f"{name:>8} {str(row['regime']):>8} {row['z_m']:6.1f} {int(row['valid']):5d} {row['fitness']:5.2f} "
              f"{row['e_t']:7.3f} {row['e_R']:7.1f} {row['timings_ms']['total']:6.0f}", flush=True)

    summary = summarise(rows)
    fmt = lambda v, p: "-" if v is None else f"{v:.{p}f}"  # noqa: E731
    print()
    print(f"valid {summary['valid']}/{summary['frames']} ({summary['valid_pct']:.0f} %)  flips (valid, e_R > {FLIP_DEG:g}°): {summary['flips']}")
    print(f"e_t mean {fmt(summary['e_t_mean_m'], 3)} m  median {fmt(summary['e_t_median_m'], 3)} m | "
          f"e_R mean {fmt(summary['e_R_mean_deg'], 2)}°  median {fmt(summary['e_R_median_deg'], 2)}° (valid frames)")
    print(f"latency mean {fmt(summary['latency_mean_ms'], 0)} ms  median {fmt(summary['latency_median_ms'], 0)} ms per frame")
    out = args.json or (args.dataset / "bench_classical.json")
    payload = {
        "dataset": str(args.dataset),
        "split": args.split,
        "config": dataclasses.asdict(config),
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count(), "omp_num_threads": os.environ.get("OMP_NUM_THREADS")},
        "created": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "summary": summary,
        "frames": rows,
    }
    Path(out).write_text(json.dumps(payload, indent=2))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
