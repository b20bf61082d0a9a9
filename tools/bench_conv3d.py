"""Benchmark: one Conv3d layer in torch eager, in onnxruntime as exported, and in onnxruntime in the
2-D form of :mod:`spacepose.export.conv3d_as_2d` (why the stereo export rewrites its 3-D convolutions).

    python -m spacepose.tools.bench_conv3d --threads 1 --json reports/bench_conv3d.json

The layers are the TSCA-Stereo regulariser's at the shipped 256x256 graph input (cost volume
24 x 64 x 64 at 1/4). Prints a table of median milliseconds; timings are never asserted in tests.
"""

from __future__ import annotations

import argparse
import io
import json
from pathlib import Path

import numpy as np

from spacepose.tools.bench_graphs import time_calls

__all__ = ["LAYERS", "bench_layer", "main"]

#: name -> (in, out, kernel, stride, padding, groups, input shape (B, C, D, H, W))
LAYERS = {
    "SECA key, depthwise 5^3 (32 ch, 1/8)": (32, 32, 5, 1, 2, 32, (1, 32, 12, 32, 32)),
    "SECA key, depthwise 5^3 (16 ch, 1/8)": (16, 16, 5, 1, 2, 16, (1, 16, 12, 32, 32)),
    "SECA query, depthwise 3^3 (32 ch, 1/8)": (32, 32, 3, 1, 1, 32, (1, 32, 12, 32, 32)),
    "encoder, depthwise 3^3 stride 2 (16 ch, 1/4)": (16, 16, 3, 2, 1, 16, (1, 16, 24, 64, 64)),
    "stem, dense 3^3 (16 ch, 1/4)": (16, 16, 3, 1, 1, 1, (1, 16, 24, 64, 64)),
}


def _median_ms(fn, runs: int) -> float:
    """Median ms of ``fn()`` over ``runs`` calls after one warm-up (:func:`time_calls`)."""
    return time_calls(lambda _: fn(), [None], runs)["median_ms"]


def bench_layer(spec: tuple, threads: int, runs: int = 10) -> dict[str, float]:
    """Median ms of torch eager, onnxruntime (Conv3d as exported) and onnxruntime (2-D form), and the
    max |difference| of the 2-D form's onnxruntime output from torch."""
    import onnxruntime as ort
    import torch
    from torch import nn

    from spacepose.export.conv3d_as_2d import Conv3dAs2d

    c_in, c_out, k, s, p, g, shape = spec
    torch.manual_seed(0)
    torch.set_num_threads(threads)
    conv = nn.Conv3d(c_in, c_out, k, s, p, groups=g).eval()
    x = torch.randn(shape)
    with torch.no_grad():
        want = conv(x).numpy()
        out = {"torch_eager_ms": _median_ms(lambda: conv(x), runs)}
    for label, module in (("ort_conv3d_ms", conv), ("ort_2d_form_ms", Conv3dAs2d(conv))):
        buf = io.BytesIO()
        torch.onnx.export(module, (x,), buf, opset_version=17, dynamo=False, input_names=["x"])
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = threads
        session = ort.InferenceSession(buf.getvalue(), opts, providers=["CPUExecutionProvider"])
        feeds = {"x": x.numpy()}
        out[label] = _median_ms(lambda: session.run(None, feeds), runs)
        if label == "ort_2d_form_ms":
            out["max_abs_diff"] = float(np.max(np.abs(session.run(None, feeds)[0] - want)))
    return out


def main(argv: list[str] | None = None) -> int:
    import warnings

    parser = argparse.ArgumentParser(prog="python -m spacepose.tools.bench_conv3d", description=__doc__.split("\n")[0])
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--json", type=Path, default=None, help="also write the rows here")
    args = parser.parse_args(argv)
    rows = {}
    print("| layer | torch eager ms | onnxruntime Conv3d ms | onnxruntime 2-D form ms | max abs diff |")
    print("|---|---|---|---|---|")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, spec in LAYERS.items():
            r = rows[name] = bench_layer(spec, args.threads, args.runs)
            print(f"| {name} | {r['torch_eager_ms']:.2f} | {r['ort_conv3d_ms']:.2f} | {r['ort_2d_form_ms']:.2f} "
                  f"| {r['max_abs_diff']:.1e} |", flush=True)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"threads": args.threads, "runs": args.runs, "layers": rows}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
