"""Where onnxruntime wins or loses against torch eager inside the stereo network, block by block.

Each block of TSCA-Stereo (the feature / correlation prefix, the whole regulariser, each of the
regulariser's stages and the classifier, and the whole network) is exported alone, in the form the
stereo exporter gives it (:func:`spacepose.export.conv3d_as_2d.rewrite_conv3d` with the export flags
of a graph's metadata, or the current exporter's defaults), and run on the inputs the real network
feeds it (captured from one forward pass of a textured pair). torch eager runs the original block.
Both run in one process, in alternating chunks of calls (:func:`time_pair`), so the machine's drift
hits them alike; the table gives the median milliseconds and torch eager / onnxruntime. The whole
network's row is a check against ``python -m spacepose.tools.bench_graphs``, which runs each backend in
a process of its own. Timings are never asserted in tests.

    python -m spacepose.tools.bench_stereo_blocks --checkpoint runs/stereo_ft_s6e/last.pt \
        --graph runtime/bundles/default/stereo.onnx --threads 2 --calls 20 --out reports/bench_stereo_blocks.json

Session 14 found with it that the regulariser was the one block onnxruntime ran slower than torch
eager (0.88x; its dense stem layers 0.57x), which led to the Winograd depth form of its dense 3x3x3
convolutions (after: 1.01x); the 1/4-resolution transposed convolution is now the block that loses most.
"""

from __future__ import annotations

import argparse
import json
import logging
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["REGULARIZER_BLOCKS", "capture_block_inputs", "time_pair", "bench_blocks", "main"]

log = logging.getLogger(__name__)

#: the regulariser's stages timed one by one (module names inside ``model.regularizer``)
REGULARIZER_BLOCKS = ("stem.0", "stem.1", "encoders.0", "encoders.1", "encoders.2", "decoders.0.up",
                      "decoders.0.aggregate", "decoders.1.up", "decoders.1.aggregate", "decoders.2.up",
                      "decoders.2.aggregate", "classifier")


def capture_block_inputs(model, left, right, names=REGULARIZER_BLOCKS) -> dict[str, tuple]:
    """The positional inputs each named regulariser block receives in one forward pass of ``model``
    (eval mode, 1 iteration) on the (1, 3, H, W) ``left`` / ``right`` tensors."""
    import torch

    modules = dict(model.regularizer.named_modules())
    captured: dict[str, tuple] = {}
    hooks = [modules[n].register_forward_pre_hook(lambda m, args, n=n: captured.setdefault(n, args) and None)
             for n in names if n in modules]
    try:
        with torch.no_grad():
            model(left, right, iters=1, test_mode=True)
    finally:
        for h in hooks:
            h.remove()
    return captured


def time_pair(torch_fn, session, feeds: dict[str, np.ndarray], args: tuple, calls: int,
              chunk: int = 5) -> tuple[float, float]:
    """Median ms of ``calls`` calls of ``session.run(None, feeds)`` and of ``torch_fn(*args)``, taken in
    alternating chunks of ``chunk`` timed calls, each chunk after one untimed call: the machine's drift
    hits both alike, and neither runtime's worker threads, still spinning after its last call, are
    timed against the other's first."""
    import torch

    ort_ms: list[float] = []
    torch_ms: list[float] = []

    def run(fn, out: list[float], n: int) -> None:
        fn()
        for _ in range(n):
            t0 = time.perf_counter()
            fn()
            out.append((time.perf_counter() - t0) * 1e3)

    with torch.no_grad():
        while len(ort_ms) < calls:
            n = min(chunk, calls - len(ort_ms))
            run(lambda: session.run(None, feeds), ort_ms, n)
            run(lambda: torch_fn(*args), torch_ms, n)
    return float(np.median(ort_ms)), float(np.median(torch_ms))


def _session(module, args: tuple, threads: int):
    """``module`` exported on ``args`` and loaded as the runtime loads its stereo graph
    (:func:`spacepose.onnx_session.make_session` with the arena and spinning that stops when run()
    returns, so onnxruntime's workers do not slow the torch calls that follow); and its input names."""
    import torch

    from spacepose.onnx_session import make_session

    names = [f"x{i}" for i in range(len(args))]
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "block.onnx"
        torch.onnx.export(module, args, str(path), opset_version=17, dynamo=False, input_names=names)
        return make_session(path, threads=threads, mem_arena=True, spinning=True), names


def bench_blocks(model, flags: dict[str, bool], size: tuple[int, int], iters: int, *, threads: int = 2,
                 calls: int = 20, blocks=REGULARIZER_BLOCKS) -> list[dict[str, Any]]:
    """Rows ``{"block", "input_shape", "onnxruntime_ms", "torch_ms", "speedup", "max_abs_diff"}`` for the
    prefix, the regulariser, each of ``blocks`` and the whole network at ``size`` (W, H) and ``iters``;
    ``max_abs_diff``: the exported block's first output in onnxruntime against the original's in torch."""
    import torch
    from torch import nn

    from spacepose.export.conv3d_as_2d import rewrite_conv3d
    from spacepose.export.onnx_stereo import StereoExportWrapper, parity_inputs
    from spacepose.models.cost_volume import groupwise_correlation

    torch.set_num_threads(threads)
    model = model.eval()
    fast = rewrite_conv3d(model, convs=flags.get("conv3d_as_2d", True),
                          transposed=flags.get("conv_transpose3d_as_2d", True),
                          narrow=flags.get("narrow_conv3d_as_2d", True),
                          winograd=flags.get("conv3d_depth_winograd", True),
                          polyphase=flags.get("conv_transpose3d_polyphase", True))
    left, right = (torch.from_numpy(a) for a in parity_inputs(size))

    class Prefix(nn.Module):
        def __init__(self, m):
            super().__init__()
            self.m = m

        def forward(self, left, right):
            m = self.m
            feats = m.features(torch.cat([m.normalise(left), m.normalise(right)], 0))
            volume = groupwise_correlation(feats.matching[:1], feats.matching[1:], m.cfg.groups, m.cfg.num_disp)
            return (volume,) + tuple(f[:1] for f in feats.pyramid)

    class Regularise(nn.Module):
        def __init__(self, m):
            super().__init__()
            self.m = m

        def forward(self, volume, *features):
            gev = self.m.regularizer(volume, list(features))
            return gev, self.m.regularizer.classify(gev)

    with torch.no_grad():
        prefix_out = Prefix(model)(left, right)
    inputs = capture_block_inputs(model, left, right, blocks)
    jobs: list[tuple[str, nn.Module, nn.Module, tuple]] = [
        ("prefix (features + correlation)", Prefix(model), Prefix(fast), (left, right)),
        ("regularizer + classifier", Regularise(model), Regularise(fast), prefix_out)]
    slow_mods, fast_mods = dict(model.regularizer.named_modules()), dict(fast.regularizer.named_modules())
    jobs += [(f"regularizer.{n}", slow_mods[n], fast_mods[n], inputs[n]) for n in blocks if n in inputs]
    jobs.append((f"whole network, {iters} iterations", StereoExportWrapper(model, iters),
                 StereoExportWrapper(fast, iters), (left, right)))
    rows = []
    for name, slow, quick, args in jobs:
        session, names = _session(quick.eval(), args, threads)
        feeds = {k: a.numpy() for k, a in zip(names, args)}
        with torch.no_grad():
            want = slow.eval()(*args)
        want = want[0] if isinstance(want, (tuple, list)) else want
        diff = float(np.max(np.abs(session.run(None, feeds)[0] - want.numpy())))
        ort_ms, torch_ms = time_pair(slow, session, feeds, args, calls)
        rows.append({"block": name, "input_shape": list(args[0].shape), "onnxruntime_ms": ort_ms,
                     "torch_ms": torch_ms, "speedup": torch_ms / ort_ms, "max_abs_diff": diff})
        log.info("%s: onnxruntime %.2f ms, torch %.2f ms", name, ort_ms, torch_ms)
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m spacepose.tools.bench_stereo_blocks",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--checkpoint", type=Path, required=True, help="stereo training checkpoint")
    parser.add_argument("--graph", type=Path, default=None,
                        help="an exported stereo graph whose export flags, input size and iterations to use "
                             "(default: the current exporter's flags, 256x256, the checkpoint config's iterations)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--calls", type=int, default=20)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")

    from spacepose.tools.train_stereo import load_checkpoint, model_from_checkpoint

    model, config = model_from_checkpoint(load_checkpoint(args.checkpoint))
    flags: dict[str, bool] = {}
    size, iters = (256, 256), int(config.iters)
    if args.graph is not None:
        from spacepose.onnx_session import read_metadata

        meta = read_metadata(args.graph)
        flags = {k: bool(v) for k, v in (meta.get("export") or {}).items()}
        for key in ("conv3d_as_2d", "conv_transpose3d_as_2d", "narrow_conv3d_as_2d", "conv3d_depth_winograd",
                    "conv_transpose3d_polyphase"):
            flags.setdefault(key, False)            # an option absent from an older graph's metadata was off
        size, iters = tuple(int(v) for v in meta["input_size"]), int(meta["iters"])
    rows = bench_blocks(model, flags, size, iters, threads=args.threads, calls=args.calls)
    print("| block | input | onnxruntime ms | torch eager ms | torch / onnxruntime | max abs diff |\n"
          "|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['block']} | {'x'.join(map(str, r['input_shape']))} | {r['onnxruntime_ms']:.2f} | "
              f"{r['torch_ms']:.2f} | {r['speedup']:.2f}x | {r['max_abs_diff']:.1e} |")
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps({"args": {k: str(v) for k, v in vars(args).items()}, "flags": flags,
                                        "size": list(size), "iters": iters, "rows": rows}, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
