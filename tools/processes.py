"""Child processes run side by side, each writing to its own log: what the batch jobs (the accelerator job,
sharded evaluations) share."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Mapping, Sequence

__all__ = ["spacepose_command", "run_all", "log_tail"]


def spacepose_command(*args: str) -> list[str]:
    """``spacepose ARGS`` run by this interpreter (``python -m spacepose.cli``), whatever the PATH holds."""
    return [sys.executable, "-m", "spacepose.cli", *args]


def run_all(commands: Sequence[Sequence[str]], logs: Sequence[Path], env: Mapping[str, str] | None = None
            ) -> list[int]:
    """Start every command at once, each writing stdout and stderr to its log; wait for all; their exit codes."""
    if len(commands) != len(logs):
        raise ValueError(f"{len(commands)} commands but {len(logs)} logs")
    procs = []
    try:
        for cmd, path in zip(commands, logs):
            handle = Path(path).open("w")
            procs.append((subprocess.Popen(list(cmd), stdout=handle, stderr=subprocess.STDOUT,
                                           env=dict(env) if env is not None else None), handle))
    except BaseException:
        for proc, handle in procs:
            proc.kill()
            proc.wait()
            handle.close()
        raise
    codes = []
    for proc, handle in procs:
        codes.append(proc.wait())
        handle.close()
    return codes


def log_tail(path: Path, chars: int = 1500) -> str:
    """The last ``chars`` characters of a log ('' when it is missing)."""
    try:
        return Path(path).read_text(errors="replace")[-chars:]
    except OSError:
        return ""
