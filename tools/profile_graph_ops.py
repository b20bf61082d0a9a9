"""Where an ONNX graph spends its time in onnxruntime: kernel time per operator type (and 3-D vs 2-D convs).

    python -m spacepose.tools.profile_graph_ops runtime/bundles/default/stereo.onnx --threads 2 --runs 4

Feeds random inputs of the graph's static shapes, runs it with onnxruntime's profiler, and prints the
milliseconds per run and share of each operator type; Conv and ConvTranspose are split by kernel rank.
Timings are never asserted in tests.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import tempfile

import numpy as np

__all__ = ["op_profile", "main"]


def op_profile(path: str, threads: int = 2, runs: int = 4) -> list[tuple[str, float, float]]:
    """``[(op type, ms per run, share of kernel time)]``, largest first."""
    import onnx
    import onnxruntime as ort

    rank = {}
    for node in onnx.load(path, load_external_data=False).graph.node:
        if node.op_type in ("Conv", "ConvTranspose"):
            attrs = {a.name: onnx.helper.get_attribute_value(a) for a in node.attribute}
            rank[node.name] = len(attrs.get("kernel_shape", [])) or None
    with tempfile.TemporaryDirectory() as tmp:
        opts = ort.SessionOptions()
        opts.enable_profiling = True
        opts.profile_file_prefix = os.path.join(tmp, "ort")
        opts.intra_op_num_threads = threads
        session = ort.InferenceSession(path, opts, providers=["CPUExecutionProvider"])
        rng = np.random.default_rng(0)
        feeds = {}
        for i in session.get_inputs():
            shape = [d if isinstance(d, int) else 1 for d in i.shape]
            feeds[i.name] = (rng.integers(0, 4, shape) if "int" in i.type else rng.uniform(0, 255, shape)).astype(
                np.int64 if "int64" in i.type else np.float32)
        session.run(None, feeds)  # warm-up, profiled too: subtract by counting runs + 1
        for _ in range(runs):
            session.run(None, feeds)
        with open(session.end_profiling()) as fh:
            events = json.load(fh)
    total = collections.Counter()
    for e in events:
        if e.get("cat") == "Node" and e["name"].endswith("_kernel_time"):
            op = e["args"]["op_name"]
            node = e["name"][: -len("_kernel_time")]
            r = rank.get(node) or rank.get(node.replace("_fused", ""))
            if op in ("Conv", "FusedConv", "ConvTranspose") and r:
                op = f"{op} {r}-D"
            total[op] += e["dur"]
    all_us = sum(total.values()) or 1
    return [(op, us / (runs + 1) / 1e3, us / all_us) for op, us in total.most_common()]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m spacepose.tools.profile_graph_ops", description=__doc__.split("\n")[0])
    parser.add_argument("graph")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--runs", type=int, default=4)
    parser.add_argument("--top", type=int, default=15)
    args = parser.parse_args(argv)
    rows = op_profile(args.graph, args.threads, args.runs)
    print("| op | ms / run | share |\n|---|---|---|")
    for op, ms, share in rows[: args.top]:
        print(f"| {op} | {ms:.1f} | {100 * share:.1f} % |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
