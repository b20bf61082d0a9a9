"""The compact rows the position report scripts (sessions 25 and 26) count: from the runs when they are all there,
else committed; and the table row they print for a group of them.

``compact_rows(files, rows_path, keys)``: ``files`` maps a set's name to the run JSON files (each
``{"frames": [...]}``) whose frames make it up. When every file exists, each frame is cut to ``keys`` (and kept
when ``keep`` says so; a key the frame lacks takes its value from ``defaults``, and without one there is an
error), and the rows are written to ``rows_path`` (gzip with no timestamp, so that the same rows give the same
bytes) and returned; otherwise the rows committed at ``rows_path`` are read.

``position_stats(rows)``: frames, valid poses, position-valid frames and their share, e_pos mean / median / p95 /
max over them and the share within ``depth_tolerance_m`` (columns of ``STATS_HEAD``).
"""

from __future__ import annotations

import gzip
import json
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

STATS_HEAD = (f"{'frames':>5} {'valid':>5} {'pos':>5} {'share':>6} {'mean':>6} {'median':>6} {'p95':>6} {'max':>6} "
              f"{'<=tau':>7}")


def compact_rows(files: dict[str, list[Path]], rows_path: Path, keys: Sequence[str],
                 keep: Callable[[dict], bool] = lambda row: True,
                 defaults: Mapping[str, Any] | None = None) -> dict[str, list[dict]]:
    defaults = defaults or {}
    if all(f.is_file() for fs in files.values() for f in fs):
        rows = {name: [{k: r[k] if k in r or k not in defaults else defaults[k] for k in keys}
                       for f in fs for r in json.loads(f.read_text())["frames"] if keep(r)]
                for name, fs in files.items()}
        with open(rows_path, "wb") as raw, gzip.GzipFile(fileobj=raw, mode="wb", mtime=0) as fh:
            fh.write(json.dumps(rows).encode())
        return rows
    with gzip.open(rows_path, "rt") as fh:
        return json.load(fh)


def position_stats(rows: list[dict]) -> str:
    pos = [r for r in rows if r["position_valid"]]
    if not pos:
        return f"{len(rows):>5} {sum(r['valid'] for r in rows):>5} {0:>5}"
    e = np.array([r["e_pos"] for r in pos])
    tau = np.array([r["depth_tolerance_m"] for r in pos])
    return (f"{len(rows):>5} {sum(r['valid'] for r in rows):>5} {len(pos):>5} {100 * len(pos) / len(rows):>5.1f}% "
            f"{e.mean():>6.3f} {np.median(e):>6.3f} {np.percentile(e, 95):>6.3f} {e.max():>6.2f} "
            f"{100 * np.mean(e <= tau):>6.1f}%")
