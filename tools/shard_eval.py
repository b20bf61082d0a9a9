"""A pose evaluation split into shards run side by side, its rows merged into one compact file.

``spacepose eval-pose`` runs one frame at a time on one core (about a frame a second at 640x480 here). Choosing
gates for a new graph needs thousands of frames evaluated with the gates open (:mod:`spacepose.tools.open_gates`),
so this runs ``K`` ``eval-pose`` processes (one thread each) over consecutive slices of the split and merges their
rows, in the split's order, into one gzipped JSON file that :mod:`spacepose.tools.calibrate_gates` reads like a
``pose_eval.json`` (``"frames"``: the rows; ``"overall"``: :func:`spacepose.tools.eval_pose.summarise` of them). Floats
keep 6 significant digits, and the gzip header no time stamp, so the same rows give the same bytes.

``python -m spacepose.tools.shard_eval DATASET --out ROWS.json.gz [--bundle B] [--split train] [--skip S]
[--limit N] [--workers K] [--work DIR] [--force]``

On the accelerator machine's 16 cores (:mod:`spacepose.tools.device_job`, ``--eval-frames``) this is what turns a
freshly trained graph into open rows within the same call. Nothing is overwritten without ``--force``; a shard that
fails leaves no merged file, and its log (in ``--work``, kept when given) says why.
"""

from __future__ import annotations

import argparse
import gzip
import json
import logging
import math
import tempfile
from pathlib import Path
from typing import Any, Sequence

from spacepose.errors import DatasetError
from spacepose.tools.processes import log_tail, run_all, spacepose_command

log = logging.getLogger(__name__)

__all__ = ["shard_slices", "shard_commands", "compact", "merge_shards", "shard_eval", "write_rows", "main"]

#: significant digits the merged rows keep
DIGITS = 6


def shard_slices(frames: int, workers: int) -> list[tuple[int, int]]:
    """``(skip, count)`` of at most ``workers`` consecutive, nearly equal, non-empty slices of ``frames`` frames."""
    if frames < 0 or workers < 1:
        raise ValueError(f"need frames >= 0 and workers >= 1, got {frames} and {workers}")
    k = min(workers, frames)
    if k == 0:
        return []
    base, extra = divmod(frames, k)
    out, start = [], 0
    for i in range(k):
        n = base + (1 if i < extra else 0)
        out.append((start, n))
        start += n
    return out


def shard_commands(dataset: Path, work: Path, slices: Sequence[tuple[int, int]], *, split: str, skip: int,
                   bundle: Path | None) -> list[list[str]]:
    """One ``spacepose eval-pose`` command per slice (offset by ``skip``), writing into ``work/shard_KK``."""
    extra = ["--bundle", str(bundle)] if bundle is not None else []
    return [spacepose_command("eval-pose", str(dataset), "--split", split, "--skip", str(skip + start), "--limit",
                              str(count), "--threads", "1", "--overlays", "0", "--out", str(work / f"shard_{i:02d}"),
                              *extra)
            for i, (start, count) in enumerate(slices)]


def compact(value: Any, digits: int = DIGITS) -> Any:
    """``value`` with every finite float rounded to ``digits`` significant digits (containers walked)."""
    if isinstance(value, float):
        return float(f"{value:.{digits}g}") if math.isfinite(value) else value
    if isinstance(value, dict):
        return {k: compact(v, digits) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [compact(v, digits) for v in value]
    return value


def merge_shards(work: Path, shards: int) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """The rows of ``work/shard_00 .. shard_{shards-1}``'s ``pose_eval.json``, in order, and the first one's
    header (dataset, bundle, split)."""
    rows: list[dict[str, Any]] = []
    header: dict[str, Any] = {}
    for i in range(shards):
        path = work / f"shard_{i:02d}" / "pose_eval.json"
        doc = json.loads(path.read_text())
        if not header:
            header = {k: doc.get(k) for k in ("dataset", "bundle", "split", "focal_px")}
        rows.extend(doc["frames"])
    return rows, header


def write_rows(doc: dict[str, Any], out: Path) -> None:
    """``doc`` as gzipped JSON at ``out``, floats compacted, no time stamp in the header."""
    data = json.dumps(compact(doc), separators=(",", ":"), allow_nan=True).encode()
    out.parent.mkdir(parents=True, exist_ok=True)
    with out.open("wb") as raw, gzip.GzipFile(filename="", mode="wb", fileobj=raw, mtime=0) as gz:
        gz.write(data)


def shard_eval(dataset: str | Path, out: str | Path, *, bundle: str | Path | None = None, split: str = "train",
               skip: int = 0, limit: int | None = None, workers: int = 2, work: str | Path | None = None,
               force: bool = False) -> dict[str, Any]:
    """Evaluate ``split`` frames ``[skip, skip + limit)`` of ``dataset`` in ``workers`` shards; write the merged
    rows to ``out`` and return what was written.

    Raises:
        DatasetError: ``out`` exists without ``force``, the slice holds no frame, or a shard failed (with the
            tail of its log).
    """
    from spacepose.tools.eval_pose import summarise
    from spacepose.tools.pose_data import read_pose_labels

    dataset, out = Path(dataset), Path(out)
    if out.exists() and not force:
        raise DatasetError(f"{out} exists; pass force=True (--force) to replace it")
    if skip < 0 or (limit is not None and limit < 0):
        raise DatasetError(f"skip and limit must be >= 0, got {skip} and {limit}")
    total = len(read_pose_labels(dataset, split)[skip:])
    frames = total if limit is None else min(limit, total)
    slices = shard_slices(frames, workers)
    if not slices:
        raise DatasetError(f"{dataset}: no {split} frames from {skip} on")
    with tempfile.TemporaryDirectory(prefix="shard_eval_") as scratch:
        folder = Path(work) if work is not None else Path(scratch)
        folder.mkdir(parents=True, exist_ok=True)
        commands = shard_commands(dataset, folder, slices, split=split, skip=skip,
                                  bundle=Path(bundle) if bundle is not None else None)
        logs = [folder / f"shard_{i:02d}.log" for i in range(len(commands))]
        log.info("%d frames of %s in %d shards", frames, dataset, len(commands))
        codes = run_all(commands, logs)
        failed = [i for i, code in enumerate(codes) if code != 0]
        if failed:
            raise DatasetError(f"shard {failed[0]} of {len(codes)} failed (exit {codes[failed[0]]}): "
                               f"{log_tail(logs[failed[0]], 800)}")
        rows, header = merge_shards(folder, len(commands))
    doc = {**header, "skip": skip, "limit": limit, "workers": len(slices), "frames": rows,
           "overall": summarise(rows)}
    write_rows(doc, out)
    log.info("%d rows written to %s", len(rows), out)
    return doc


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m spacepose.tools.shard_eval", description=__doc__.split("\n\n")[0])
    p.add_argument("dataset", type=Path)
    p.add_argument("--out", type=Path, required=True, help="merged rows (.json.gz)")
    p.add_argument("--bundle", type=Path, default=None, help="bundle folder (default: the shipped one)")
    p.add_argument("--split", default="train")
    p.add_argument("--skip", type=int, default=0, help="leave out the split's first frames")
    p.add_argument("--limit", type=int, default=None, help="at most this many frames after --skip")
    p.add_argument("--workers", type=int, default=2, help="eval-pose processes, one thread each")
    p.add_argument("--work", type=Path, default=None, help="keep the shards' reports and logs here")
    p.add_argument("--force", action="store_true", help="replace an existing --out")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    try:
        doc = shard_eval(args.dataset, args.out, bundle=args.bundle, split=args.split, skip=args.skip,
                         limit=args.limit, workers=args.workers, work=args.work, force=args.force)
    except DatasetError as exc:
        raise SystemExit(f"error: {exc}") from exc
    overall = doc["overall"]
    log.info("valid %.1f %% of %d frames", 100.0 * overall.get("valid_fraction", float("nan")), len(doc["frames"]))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
