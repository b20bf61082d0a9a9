"""The compact rows the session-25 report scripts count: from the runs when they are all there, else committed.

``compact_rows(files, rows_path, keys)``: ``files`` maps a set's name to the run JSON files (each
``{"frames": [...]}``) whose frames make it up. When every file exists, each frame is cut to ``keys`` (and kept
when ``keep`` says so), and the rows are written to ``rows_path`` (gzip with no timestamp, so that the same rows
give the same bytes) and returned; otherwise the rows committed at ``rows_path`` are read.
"""

from __future__ import annotations

import gzip
import json
from pathlib import Path
from typing import Callable, Sequence


def compact_rows(files: dict[str, list[Path]], rows_path: Path, keys: Sequence[str],
                 keep: Callable[[dict], bool] = lambda row: True) -> dict[str, list[dict]]:
    if all(f.is_file() for fs in files.values() for f in fs):
        rows = {name: [{k: r[k] for k in keys} for f in fs for r in json.loads(f.read_text())["frames"] if keep(r)]
                for name, fs in files.items()}
        with open(rows_path, "wb") as raw, gzip.GzipFile(fileobj=raw, mode="wb", mtime=0) as fh:
            fh.write(json.dumps(rows).encode())
        return rows
    with gzip.open(rows_path, "rt") as fh:
        return json.load(fh)
