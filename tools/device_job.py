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

With ``--eval-frames N`` the job then evaluates what it trained, on the same machine's cores
(:func:`eval_commands`): it renders ``N`` fresh frames (``--eval-seed``; optionally a restyled copy too,
``--eval-restyle-seed``), puts the new graphs into a copy of ``--bundle``, opens that copy's gates
(:mod:`spacepose.tools.open_gates`) and runs ``eval-pose`` over each set's train split in parallel shards
(:mod:`spacepose.tools.shard_eval`), and ``eval-stereo`` of the candidate on the plain set's test split. One more
file comes back, ``eval.json.gz``: the open rows (``plain``, ``restyled``), the stereo metrics (``stereo``), the
graphs replaced and the seeds; the gates for the new graphs are then chosen here from those rows
(:func:`spacepose.tools.calibrate_gates.flip_gate_table`). ``--eval-reserve-s`` of ``--budget-s`` is kept from the
training for it. A call returns at most 8 files: with both kinds trained and the evaluation on, do not also write a
log into ``--out``.

The same job runs on a CPU with small numbers (the test does), which is how it is checked before a
machine is lent. The model card's "training on a lent accelerator" section has the full ``run`` call.
"""

from __future__ import annotations

import argparse
import gzip
import json
import logging
import os
import shutil
import sys
import time
from pathlib import Path
from typing import Sequence

from spacepose.export.metadata import COMMIT_ENV
from spacepose.tools.processes import log_tail, run_all, spacepose_command

log = logging.getLogger(__name__)

__all__ = ["main", "job_commands"]

_DEFAULT_BUNDLE = Path(__file__).resolve().parents[1] / "runtime" / "bundles" / "default"


def job_commands(args: argparse.Namespace, work: Path) -> dict[str, list[list[str]]]:
    """The commands of each phase (render, recover, train — run concurrently — and export)."""
    data = work / "data"
    bundle = Path(args.bundle)
    common = ["--threads", str(args.threads), "--ckpt-every", "500", "--val-every", str(args.val_every),
              "--time-limit-s", str(args.time_limit_s), "--pace-lr", "--seed", str(args.seed)]
    stereo_workers = args.loader_workers if args.stereo_workers is None else args.stereo_workers
    pose_workers = args.loader_workers if args.pose_workers is None else args.pose_workers
    flip = ["--symmetric-flip", args.pose_symmetric_flip] if args.pose_symmetric_flip else []
    stereo = spacepose_command("train-stereo", str(data), "--out", str(work / "stereo"), "--steps", str(args.stereo_steps),
                        "--batch", str(args.stereo_batch), "--train-crop", "160x160", "--init",
                        str(args.stereo_init or work / "init_stereo.pt"), "--lr", str(args.stereo_lr), "--workers",
                        str(stereo_workers), "--target-weight", str(args.target_weight), "--edge-weight",
                        str(args.edge_weight), "--photometric", args.stereo_photometric, "--oversample",
                        *args.stereo_oversample, *common)
    pose = spacepose_command("train-pose", str(data), "--out", str(work / "pose"), "--steps", str(args.pose_steps),
                      "--batch", str(args.pose_batch), "--depth-source", "gt_noisy", "--init",
                      str(work / "init_pose.pt"), "--lr-min", "1e-5", "--lr-max", str(args.pose_lr_max),
                      "--cycles", str(args.pose_cycles), "--workers", str(pose_workers), *flip, *common)
    recover = {kind: spacepose_command("recover-checkpoint", str(bundle / f"{kind}.onnx"), "--out",
                                str(work / f"init_{kind}.pt"), "--force") for kind in ("stereo", "pose")}
    export = {"stereo": spacepose_command("export-stereo", str(work / "stereo" / "last.pt"), "--out",
                                   str(work / "export" / "stereo.onnx"), "--no-manifest", "--force"),
              "pose": spacepose_command("export-pose", str(work / "pose" / "last.pt"), "--out",
                                 str(work / "export" / "pose.onnx"), "--force")}
    train = {"stereo": stereo, "pose": pose}
    return {
        "render": [spacepose_command("render", str(data), "--target", "tdrs", "--count", str(args.frames), "--size",
                              args.size, "--seed", str(args.data_seed), "--workers", str(args.render_workers))],
        "recover": [recover[kind] for kind in args.kinds if not (kind == "stereo" and args.stereo_init)],
        "train": [train[kind] for kind in args.kinds],
        "export": [export[kind] for kind in args.kinds],
    }


def _eval_seed(args: argparse.Namespace) -> int:
    """The evaluation frames' seed: ``--eval-seed``, else ``--data-seed`` + 1000."""
    return args.data_seed + 1000 if args.eval_seed is None else args.eval_seed


def eval_commands(args: argparse.Namespace, work: Path) -> dict[str, list[list[str]]]:
    """The evaluation's commands (``--eval-frames``): render fresh frames, restyle them (``--eval-restyle-seed``),
    then pose rows of the open candidate bundle (``work/eval/bundle_open``, :func:`_candidate_bundles`) on each set's
    train split, and the stereo metrics of the candidate on the plain set's test split."""
    ev = work / "eval"
    data, restyled = ev / "data", ev / "data_restyled"
    seed = _eval_seed(args)
    workers = str(args.render_workers if args.eval_workers is None else args.eval_workers)

    def pose(folder: Path, name: str) -> list[str]:
        return [sys.executable, "-m", "spacepose.tools.shard_eval", str(folder), "--out", str(ev / f"open_{name}.json.gz"),
                "--bundle", str(ev / "bundle_open"), "--split", "train", "--workers", workers,
                "--work", str(ev / f"shards_{name}"), "--force"]

    stereo = [spacepose_command("eval-stereo", str(data), "--bundle", str(ev / "bundle"), "--limit",
                                str(args.eval_stereo_frames), "--threads", "1", "--out", str(ev / "stereo"))]
    return {
        "render": [spacepose_command("render", str(data), "--target", "tdrs", "--count", str(args.eval_frames),
                                     "--size", args.eval_size or args.size, "--seed", str(seed), "--workers",
                                     str(args.render_workers), "--no-depth")],
        "restyle": ([[sys.executable, "-m", "spacepose.tools.restyle", str(data), str(restyled), "--seed",
                      str(args.eval_restyle_seed)]] if args.eval_restyle_seed is not None else []),
        "plain": [pose(data, "plain"), *(stereo if args.eval_stereo_frames > 0 else [])],
        "restyled": [pose(restyled, "restyled")] if args.eval_restyle_seed is not None else [],
    }


def _candidate_bundles(bundle: Path, work: Path, trained: Sequence[str]) -> list[str]:
    """``work/eval/bundle``: a copy of ``bundle`` with the exported graphs of ``trained`` in place of its own, and
    ``work/eval/bundle_open``, its open copy (:func:`spacepose.tools.open_gates.write_open_bundle`); the graphs
    replaced."""
    from spacepose.tools.open_gates import write_open_bundle

    ev = work / "eval"
    for folder in (ev / "bundle", ev / "bundle_open"):
        if folder.exists():
            shutil.rmtree(folder)
    shutil.copytree(bundle, ev / "bundle")
    replaced = []
    for kind in trained:
        graph = work / "export" / f"{kind}.onnx"
        if graph.is_file():
            shutil.copyfile(graph, ev / "bundle" / f"{kind}.onnx")
            replaced.append(f"{kind}.onnx")
    write_open_bundle(ev / "bundle", ev / "bundle_open")
    return replaced


def _evaluate(args: argparse.Namespace, work: Path, out: Path, trained: Sequence[str],
              env: dict[str, str] | None) -> dict:
    """Run :func:`eval_commands` step by step and write ``out/eval.json.gz``: the open rows of each set (``plain``,
    ``restyled`` or ``None``), the candidate's stereo metrics (``stereo``: ``ours`` and ``sgbm``, or ``None``), the
    graphs replaced and the seeds. Returns the phase's report (``exit_codes`` of every command run)."""
    from spacepose.tools.shard_eval import write_rows

    ev = work / "eval"
    ev.mkdir(parents=True, exist_ok=True)
    steps = eval_commands(args, work)
    replaced = _candidate_bundles(Path(args.bundle), work, trained)
    if not replaced:   # nothing was exported: the rows would be the old bundle's, under the new graphs' name
        log.warning("evaluate: no exported graph, nothing evaluated")
        return {"exit_codes": [1], "commands": [], "log_tails": ["no exported graph to evaluate"]}
    codes: list[int] = []
    tails: list[str] = []
    for name, commands in steps.items():
        if not commands:
            continue
        logs = [ev / f"{name}_{i}.log" for i in range(len(commands))]
        step_codes = run_all(commands, logs, env)
        codes += step_codes
        tails += [log_tail(path) for path in logs]
        log.info("evaluate/%s: exit codes %s", name, step_codes)
        if name in ("render", "restyle") and any(step_codes):
            break

    def rows(name: str) -> dict | None:
        path = ev / f"open_{name}.json.gz"
        return json.loads(gzip.decompress(path.read_bytes())) if path.is_file() else None

    stereo_path = ev / "stereo" / "stereo_eval.json"
    stereo = json.loads(stereo_path.read_text()) if stereo_path.is_file() else None
    doc = {"graphs_replaced": replaced, "bundle": str(args.bundle),
           "eval_seed": _eval_seed(args),
           "restyle_seed": args.eval_restyle_seed, "plain": rows("plain"), "restyled": rows("restyled"),
           "stereo": {k: stereo.get(k) for k in ("ours", "sgbm", "frames")} if stereo else None}
    write_rows(doc, out / "eval.json.gz")
    return {"exit_codes": codes, "commands": [" ".join(c) for cmds in steps.values() for c in cmds],
            "log_tails": tails}


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
    p.add_argument("--eval-frames", type=int, default=0, help="after the export, render this many fresh frames and "
                   "evaluate the new graphs on them with the gates open (0: no evaluation; module docstring)")
    p.add_argument("--eval-seed", type=int, default=None, help="seed of the evaluation frames (default: --data-seed "
                   "+ 1000, never the training frames')")
    p.add_argument("--eval-size", default=None, help="size of the evaluation frames (default: --size)")
    p.add_argument("--eval-workers", type=int, default=None, help="eval-pose processes (default: --render-workers)")
    p.add_argument("--eval-restyle-seed", type=int, default=None, help="also evaluate a restyled copy of the "
                   "evaluation frames (spacepose.tools.restyle with this seed)")
    p.add_argument("--eval-stereo-frames", type=int, default=150, help="test-split frames of the evaluation set "
                   "for eval-stereo (0: none)")
    p.add_argument("--eval-reserve-s", type=float, default=180.0, help="with --eval-frames, seconds of --budget-s "
                   "kept from the training for the evaluation")
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
            reserve = args.export_reserve_s + (args.eval_reserve_s if args.eval_frames > 0 else 0.0)
            left = args.budget_s - (time.perf_counter() - t_job) - reserve
            limit = max(30.0, min(args.time_limit_s, left))
            commands = [_with_time_limit(cmd, limit) for cmd in commands]
            report["train_time_limit_s"] = round(limit, 1)
            log.info("training time limit %.0f s", limit)
        if name == "export":   # export what trained, both at once
            commands = [cmd for kind, cmd in zip(args.kinds, commands) if kind in trained]
        t0 = time.perf_counter()
        logs = [work / f"{name}_{i}.log" for i in range(len(commands))]
        codes = run_all(commands, logs, env) if name in ("train", "export") else [
            run_all([cmd], [path], env)[0] for cmd, path in zip(commands, logs)]
        seconds = time.perf_counter() - t0
        tails = [log_tail(path) for path in logs]
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
    if args.eval_frames > 0 and trained:
        t0 = time.perf_counter()
        phase = _evaluate(args, work, out, trained, env)
        report["phases"]["evaluate"] = {"seconds": round(time.perf_counter() - t0, 1), **phase}
        log.info("evaluate: %.0f s, exit codes %s", report["phases"]["evaluate"]["seconds"], phase["exit_codes"])
        ok = ok and not any(phase["exit_codes"])
    report["ok"] = ok
    (out / "job.json").write_text(json.dumps(report, indent=2))
    return 0 if ok else 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
