"""One self-contained training job for a lent accelerator machine: render there, fine-tune, export back.

The device machine receives the working tree (at most 64 MiB: the 7.9 GB dataset cannot travel) and
has torch but neither trimesh nor embreex; it returns at most 8 files of 16 MiB. So the job renders its
own data there on the machine's CPU cores (the two packages travel as wheels), rebuilds training
checkpoints from the shipped graphs (``spacepose recover-checkpoint``) or takes carried weights
(``--stereo-init``), fine-tunes the networks ``--kinds`` names (both at once by default: two processes
sharing the GPU, each under a wall-clock limit, their learning-rate schedules paced to end by it),
exports the graphs with their parity checks, and writes them with the logs into ``--out``. With
``--budget-s`` the training gets what the whole job's budget leaves after rendering::

    python -m spacepose.tools.device_job --work /tmp/job --out "$OUT" --frames 4000 --kinds stereo \\
        --stereo-workers 14 --stereo-steps 12000 --time-limit-s 420 --budget-s 520 --render-workers 15

What comes back (``--out``, for the kinds trained): ``stereo.onnx``, ``pose.onnx``,
``stereo_weights.pt`` and ``pose_weights.pt`` (model-only state dicts, small enough to come back;
``--init`` takes them after ``spacepose recover-checkpoint`` or directly), ``stereo_log.jsonl``, ``pose_log.jsonl`` and
``job.json`` (commands, timings, final losses). ``--commit`` names the source commit the checkpoints and
graphs record (``$SPACEPOSE_COMMIT``): the copy's ``.git`` there is not the tree's. Nothing is written outside ``--work`` and ``--out``.
The same job runs on a CPU with small numbers (the test does), which is how it is checked before a
machine is lent. The model card's "training on a lent accelerator" section has the full ``run`` call.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Sequence

from spacepose.export.metadata import COMMIT_ENV

log = logging.getLogger(__name__)

__all__ = ["main", "job_commands"]

_DEFAULT_BUNDLE = Path(__file__).resolve().parents[1] / "runtime" / "bundles" / "default"


def _spacepose(*args: str) -> list[str]:
    return [sys.executable, "-m", "spacepose.cli", *args]


def job_commands(args: argparse.Namespace, work: Path) -> dict[str, list[list[str]]]:
    """The commands of each phase (render, recover, train — run concurrently — and export)."""
    data = work / "data"
    bundle = Path(args.bundle)
    common = ["--threads", str(args.threads), "--ckpt-every", "500", "--val-every", str(args.val_every),
              "--time-limit-s", str(args.time_limit_s), "--pace-lr", "--seed", str(args.seed)]
    stereo_workers = args.loader_workers if args.stereo_workers is None else args.stereo_workers
    pose_workers = args.loader_workers if args.pose_workers is None else args.pose_workers
    flip = ["--symmetric-flip", args.pose_symmetric_flip] if args.pose_symmetric_flip else []
    stereo = _spacepose("train-stereo", str(data), "--out", str(work / "stereo"), "--steps", str(args.stereo_steps),
                        "--batch", str(args.stereo_batch), "--train-crop", "160x160", "--init",
                        str(args.stereo_init or work / "init_stereo.pt"), "--lr", str(args.stereo_lr), "--workers",
                        str(stereo_workers), "--target-weight", str(args.target_weight), "--edge-weight",
                        str(args.edge_weight), "--photometric", args.stereo_photometric, "--oversample",
                        *args.stereo_oversample, *common)
    pose = _spacepose("train-pose", str(data), "--out", str(work / "pose"), "--steps", str(args.pose_steps),
                      "--batch", str(args.pose_batch), "--depth-source", "gt_noisy", "--init",
                      str(work / "init_pose.pt"), "--lr-min", "1e-5", "--lr-max", str(args.pose_lr_max),
                      "--cycles", str(args.pose_cycles), "--workers", str(pose_workers), *flip, *common)
    recover = {kind: _spacepose("recover-checkpoint", str(bundle / f"{kind}.onnx"), "--out",
                                str(work / f"init_{kind}.pt"), "--force") for kind in ("stereo", "pose")}
    export = {"stereo": _spacepose("export-stereo", str(work / "stereo" / "last.pt"), "--out",
                                   str(work / "export" / "stereo.onnx"), "--no-manifest", "--force"),
              "pose": _spacepose("export-pose", str(work / "pose" / "last.pt"), "--out",
                                 str(work / "export" / "pose.onnx"), "--force")}
    train = {"stereo": stereo, "pose": pose}
    return {
        "render": [_spacepose("render", str(data), "--target", "tdrs", "--count", str(args.frames), "--size",
                              args.size, "--seed", str(args.data_seed), "--workers", str(args.render_workers))],
        "recover": [recover[kind] for kind in args.kinds if not (kind == "stereo" and args.stereo_init)],
        "train": [train[kind] for kind in args.kinds],
        "export": [export[kind] for kind in args.kinds],
    }


def _run_all(commands: list[list[str]], logs: list[Path], env: dict[str, str] | None = None) -> list[int]:
    """Start the commands at once, each writing to its log; wait for all; their exit codes."""
    procs = []
    for cmd, path in zip(commands, logs):
        handle = path.open("w")
        procs.append((subprocess.Popen(cmd, stdout=handle, stderr=subprocess.STDOUT, env=env), handle))
    codes = []
    for proc, handle in procs:
        codes.append(proc.wait())
        handle.close()
    return codes


def _weights_only(ckpt_path: Path, out: Path) -> None:
    import torch

    ckpt = torch.load(ckpt_path, map_location="cpu", weights_only=False)
    keep = {k: v for k, v in ckpt.items() if k not in ("optimizer", "scheduler", "rng")}
    torch.save(keep, out)


def _with_time_limit(cmd: list[str], seconds: float) -> list[str]:
    """``cmd`` with the value of its ``--time-limit-s`` replaced."""
    i = cmd.index("--time-limit-s")
    return [*cmd[:i + 1], f"{seconds:.0f}", *cmd[i + 2:]]


def _collect(work: Path, out: Path, *, weights: bool) -> None:
    """Copy the logs, and the model-only weights or the exported graphs, from ``work`` into ``out``."""
    for kind in ("stereo", "pose"):
        run = work / kind
        if (run / "log.jsonl").is_file():
            shutil.copyfile(run / "log.jsonl", out / f"{kind}_log.jsonl")
        if weights and (run / "last.pt").is_file():
            _weights_only(run / "last.pt", out / f"{kind}_weights.pt")
        graph = work / "export" / f"{kind}.onnx"
        if not weights and graph.is_file():
            shutil.copyfile(graph, out / f"{kind}.onnx")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m spacepose.tools.device_job", description=__doc__.split("\n")[0])
    p.add_argument("--work", type=Path, required=True, help="scratch folder (data, runs); created")
    p.add_argument("--out", type=Path, required=True, help="folder for what comes back (graphs, weights, logs)")
    p.add_argument("--bundle", default=str(_DEFAULT_BUNDLE), help="bundle whose graphs the fine-tuning starts from")
    p.add_argument("--frames", type=int, default=3000)
    p.add_argument("--size", default="640x480")
    p.add_argument("--data-seed", type=int, default=11, help="dataset seed (not the shipped data's 1: new frames)")
    p.add_argument("--render-workers", type=int, default=14)
    p.add_argument("--loader-workers", type=int, default=6, help="DataLoader workers per training process")
    p.add_argument("--stereo-workers", type=int, default=None, help="DataLoader workers of the stereo run "
                   "(default: --loader-workers)")
    p.add_argument("--pose-workers", type=int, default=None, help="DataLoader workers of the pose run "
                   "(default: --loader-workers)")
    p.add_argument("--pose-symmetric-flip", choices=("x", "y", "z"), default=None,
                   help="train-pose --symmetric-flip (the flip-aware keypoint loss)")
    p.add_argument("--pose-cycles", type=int, default=3)
    p.add_argument("--threads", type=int, default=0, help="torch threads per training process (0: default)")
    p.add_argument("--stereo-steps", type=int, default=20000)
    p.add_argument("--pose-steps", type=int, default=20000)
    p.add_argument("--stereo-batch", type=int, default=16)
    p.add_argument("--pose-batch", type=int, default=16)
    p.add_argument("--stereo-lr", type=float, default=2e-4)
    p.add_argument("--stereo-init", default=None, help="start the stereo run from these weights (a returned "
                   "stereo_weights.pt carried along) instead of the bundle's graph")
    p.add_argument("--stereo-oversample", nargs="+", default=["mixed=3", "penumbra=2"],
                   help="train-stereo --oversample")
    p.add_argument("--stereo-photometric", choices=("mild", "wide"), default="wide",
                   help="train-stereo --photometric (default wide since session 36: one look per sample shared by "
                        "both views; it beat mild on plain and restyled test frames at the same CPU budget)")
    p.add_argument("--pose-lr-max", type=float, default=1e-3)
    p.add_argument("--target-weight", type=float, default=4.0)
    p.add_argument("--edge-weight", type=float, default=3.0, help="train-stereo --edge-weight (session 6's recipe)")
    p.add_argument("--time-limit-s", type=float, default=360.0, help="wall-clock limit of each training process; "
                   "both learning-rate schedules are paced to end by it (train-* --pace-lr)")
    p.add_argument("--kinds", nargs="+", choices=("stereo", "pose"), default=["stereo", "pose"],
                   help="which networks to fine-tune (the others' loader workers and GPU time go to these)")
    p.add_argument("--budget-s", type=float, default=None,
                   help="wall-clock budget of the whole job: the training time limit becomes what is left of it "
                        "after rendering and recovery, less --export-reserve-s (at most --time-limit-s)")
    p.add_argument("--export-reserve-s", type=float, default=75.0)
    p.add_argument("--val-every", type=int, default=1000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--commit", default=None, help="the source commit the checkpoints and graphs record (the local "
                   "HEAD, written into the call): the device copy's .git is not the tree's; sets $SPACEPOSE_COMMIT")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    args = build_parser().parse_args(argv)
    work, out = args.work, args.out
    env = {**os.environ, COMMIT_ENV: args.commit} if args.commit else None   # for every phase's process
    work.mkdir(parents=True, exist_ok=True)
    out.mkdir(parents=True, exist_ok=True)
    (work / "export").mkdir(exist_ok=True)
    phases = job_commands(args, work)
    report: dict = {"args": {k: str(v) for k, v in vars(args).items()}, "phases": {}}
    ok = True
    trained = tuple(args.kinds)
    t_job = time.perf_counter()
    for name, commands in phases.items():
        if name == "train" and args.budget_s is not None:
            left = args.budget_s - (time.perf_counter() - t_job) - args.export_reserve_s
            limit = max(30.0, min(args.time_limit_s, left))
            commands = [_with_time_limit(cmd, limit) for cmd in commands]
            report["train_time_limit_s"] = round(limit, 1)
            log.info("training time limit %.0f s", limit)
        if name == "export":   # export what trained, both at once
            commands = [cmd for kind, cmd in zip(args.kinds, commands) if kind in trained]
        t0 = time.perf_counter()
        logs = [work / f"{name}_{i}.log" for i in range(len(commands))]
        codes = _run_all(commands, logs, env) if name in ("train", "export") else [
            _run_all([cmd], [path], env)[0] for cmd, path in zip(commands, logs)]
        seconds = time.perf_counter() - t0
        tails = [path.read_text(errors="replace")[-1500:] for path in logs]
        report["phases"][name] = {"seconds": round(seconds, 1), "exit_codes": codes,
                                  "commands": [" ".join(c) for c in commands], "log_tails": tails}
        log.info("%s: %.0f s, exit codes %s", name, seconds, codes)
        ok = ok and not any(codes)
        if name == "train":    # weights come back even if the export or the call's time limit fails later
            trained = tuple(kind for kind, code in zip(args.kinds, codes) if code == 0)
            _collect(work, out, weights=True)
        (out / "job.json").write_text(json.dumps({**report, "ok": None}, indent=2))
        if (name in ("render", "recover") and any(codes)) or not trained:
            break
    _collect(work, out, weights=False)
    report["ok"] = ok
    (out / "job.json").write_text(json.dumps(report, indent=2))
    return 0 if ok else 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
