"""Benchmark the renderer: stereo samples per second at 640x480 and 1280x960.

``python -m spacepose.tools.bench_render [--frames N] [--workers 2] [--out bench_render.json]``

For each size it renders N frames of a fresh dataset (degradations and file writing included)
with the given worker count, and N frames in one process with a per-stage split
(ray casting + shading vs. degradations + writing). Prints a table and writes JSON.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

SIZES = ((640, 480), (1280, 960))


def _single_process(target: str, size, frames: int) -> dict:
    from spacepose.calibration.rig import paper_rig

    from .dataset import FRAME_FILES, RenderConfig, _setup, render_frame, write_frame

    setup = _setup(target, paper_rig(*size), RenderConfig(target=target, count=frames, size=size))
    render_frame(setup["target"], setup["camera"], setup["sampler"], 0, frames)  # warm up (BVH, caches)
    root = Path(tempfile.mkdtemp(prefix="bench_render_"))
    try:
        for folder in FRAME_FILES:
            (root / folder).mkdir()
        t_render = t_write = 0.0
        for i in range(frames):
            t0 = time.perf_counter()
            frame = render_frame(setup["target"], setup["camera"], setup["sampler"], 0, i)
            t1 = time.perf_counter()
            write_frame(root, frame)
            t_write += time.perf_counter() - t1
            t_render += t1 - t0
    finally:
        shutil.rmtree(root, ignore_errors=True)
    return {"render_s_per_frame": t_render / frames, "write_s_per_frame": t_write / frames, "samples_per_s_1proc": frames / (t_render + t_write)}


def _dataset(target: str, size, frames: int, workers: int) -> dict:
    from .dataset import RenderConfig, render_dataset

    root = Path(tempfile.mkdtemp(prefix="bench_render_ds_")) / "ds"
    try:
        t0 = time.perf_counter()
        render_dataset(root, RenderConfig(target=target, count=frames, size=size), workers=workers)
        elapsed = time.perf_counter() - t0
    finally:
        shutil.rmtree(root.parent, ignore_errors=True)
    return {"dataset_s": elapsed, "samples_per_s_workers": frames / elapsed}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=40)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--target", default="tdrs")
    parser.add_argument("--out", default="bench_render.json")
    args = parser.parse_args(argv)
    rows = []
    for size in SIZES:
        n = args.frames if size[0] <= 640 else max(4, args.frames // 4)
        row = {"size": f"{size[0]}x{size[1]}", "frames": n, "workers": args.workers}
        row.update(_single_process(args.target, size, n))
        row.update(_dataset(args.target, size, n, args.workers))
        rows.append(row)
    print(f"{'size':>10} {'frames':>6} {'render s':>9} {'write s':>8} {'1 proc /s':>9} {f'{args.workers} workers /s':>13}  (incl. pool start)")
    for r in rows:
        print(f"{r['size']:>10} {r['frames']:>6} {r['render_s_per_frame']:9.3f} {r['write_s_per_frame']:8.3f} {r['samples_per_s_1proc']:9.2f} {r['samples_per_s_workers']:13.2f}")
    result = {"target": args.target, "cpu_count": os.cpu_count(), "python": sys.version.split()[0], "machine": platform.machine(), "rows": rows}
    Path(args.out).write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
