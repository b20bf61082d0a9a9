"""Latency and peak RSS of the full stereo stage (coarse pass -> ROI -> fine pass) per frame size.

One subprocess per (backend, frame size) so that peak RSS is per configuration: the parent polls the
child's RSS with psutil every 5 ms and the child also reports ``ru_maxrss``. Backends: ``ort``
(onnxruntime, the shipped graph) and ``torch`` (the same pipeline with torch eager inference of a
checkpoint, or of a random-init model of the graph's config when no checkpoint is given).

    python -m spacepose.tools.bench_stereo --graph runtime/bundles/default/stereo.onnx --threads 2 \
        --out runs/bench_stereo.json [--checkpoint runs/stereo/last.pt]

Prints a markdown table and writes JSON. Timings are never asserted in tests.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

SIZES = ((320, 240), (640, 480), (1280, 960))


def synthetic_frame(size: tuple[int, int], seed: int = 0):
    """A textured plate on black sky at the image centre, right = left shifted by a rig-like disparity."""
    import cv2
    import numpy as np

    w, h = size
    rng = np.random.default_rng(seed)
    tex = cv2.resize(rng.uniform(30, 230, (h // 4, w // 4)).astype(np.float32), (w, h))
    d = int(round(w / 640 * 40))  # 20 m at the paper rig
    left = np.zeros((h, w), np.float32)
    left[h // 3: 2 * h // 3, w // 3: 2 * w // 3] = tex[h // 3: 2 * h // 3, w // 3: 2 * w // 3]
    right = np.zeros_like(left)
    right[:, : w - d] = left[:, d:]
    to = lambda a: np.repeat(a.astype(np.uint8)[..., None], 3, axis=2)  # noqa: E731
    return to(left), to(right)


def worker(args: argparse.Namespace) -> None:
    import resource

    import numpy as np

    from spacepose.onnx_session import read_metadata
    from spacepose.stereo_stage import StereoMatcher

    size = tuple(int(v) for v in args.size.split("x"))
    if args.backend == "ort":
        matcher = StereoMatcher(args.graph, threads=args.threads)
    else:
        import torch

        torch.set_num_threads(args.threads)
        from spacepose.models.stereo_config import StereoConfig
        from spacepose.models.tsca_stereo import TSCAStereo

        meta = read_metadata(args.graph)
        if args.checkpoint:
            from spacepose.tools.train_stereo import load_checkpoint, model_from_checkpoint

            model, _ = model_from_checkpoint(load_checkpoint(args.checkpoint))
        else:
            model = TSCAStereo(StereoConfig.from_dict(meta["config"])).eval()
        iters = int(meta["iters"])

        def infer(left, right):
            with torch.inference_mode():
                return model(torch.from_numpy(left), torch.from_numpy(right), iters=iters, test_mode=True).numpy()[0, 0]

        matcher = StereoMatcher.from_callable(infer, tuple(meta["input_size"]), iters=iters,
                                              max_disp=float(meta["max_disp"]), metadata=meta)
    left, right = synthetic_frame(size)
    matcher.match(left, right)  # warm-up
    times, statuses = [], []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        res = matcher.match(left, right)
        times.append((time.perf_counter() - t0) * 1e3)
        statuses.append(res.status)
    print(json.dumps({"median_ms": float(np.median(times)), "min_ms": float(np.min(times)), "status": statuses[-1],
                      "ru_maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}))


def measure(backend: str, size: tuple[int, int], graph: str, threads: int, repeats: int, checkpoint: str | None) -> dict:
    import psutil

    cmd = [sys.executable, "-m", "spacepose.tools.bench_stereo", "--worker", "--backend", backend,
           "--size", f"{size[0]}x{size[1]}", "--graph", graph, "--threads", str(threads), "--repeats", str(repeats)]
    if checkpoint:
        cmd += ["--checkpoint", checkpoint]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    ps = psutil.Process(proc.pid)
    peak = 0
    while proc.poll() is None:
        try:
            peak = max(peak, ps.memory_info().rss)
        except psutil.Error:
            break
        time.sleep(0.005)
    out, err = proc.communicate()
    if proc.returncode != 0:
        return {"backend": backend, "size": list(size), "error": err.strip().splitlines()[-1:] or ["failed"]}
    res = json.loads(out.strip().splitlines()[-1])
    return {"backend": backend, "size": list(size), "threads": threads, "peak_rss_mb_psutil": peak / 2**20, **res}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--graph", default=str(Path(__file__).resolve().parents[1] / "runtime/bundles/default/stereo.onnx"))
    p.add_argument("--checkpoint", default=None)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--backends", default="ort,torch")
    p.add_argument("--sizes", default=",".join(f"{w}x{h}" for w, h in SIZES))
    p.add_argument("--out", default=None, help="JSON output path")
    p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--backend", default="ort", help=argparse.SUPPRESS)
    p.add_argument("--size", default="640x480", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker:
        worker(args)
        return 0
    rows = []
    for s in args.sizes.split(","):
        size = tuple(int(v) for v in s.split("x"))
        for backend in args.backends.split(","):
            rows.append(measure(backend, size, args.graph, args.threads, args.repeats, args.checkpoint))
    print("| frame | backend | median ms | min ms | peak RSS MB (psutil) | ru_maxrss MB | status |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        if "error" in r:
            print(f"| {r['size'][0]}x{r['size'][1]} | {r['backend']} | error: {r['error']} | | | | |")
            continue
        print(f"| {r['size'][0]}x{r['size'][1]} | {r['backend']} | {r['median_ms']:.0f} | {r['min_ms']:.0f} | "
              f"{r['peak_rss_mb_psutil']:.0f} | {r['ru_maxrss_mb']:.0f} | {r['status']} |")
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps({"graph": args.graph, "threads": args.threads, "rows": rows}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
