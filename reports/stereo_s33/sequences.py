"""The sequences of session 33's check of session 19's GPU-trained stereo graph in the current bundle.

    python reports/stereo_s33/sequences.py explore|check [MODE ...]   # a render and an eval command per sequence and mode

``explore``: the first 12 of session 30's fit sequences (seeds 3011-3022, spent). ``check``: 12 sequences, seeds
3311-3322, rendered only after reports/stereo_s33/rule.txt was committed. The grids (distance, regime, rate) are
session 30's (reports/sequence_s30/sequences.py); 40 frames at 640x480 on the paper rig. MODE ``base`` evaluates
with the shipped bundle, ``gpu19`` with /tmp/s33/bundles/gpu19 (rule.txt says what it holds); reports go to
``runs/s33/<mode>_<name>.json``.
"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "sequence_s30"))
import sequences as s30  # noqa: E402

s30.SETS.setdefault("check_s33", (3311, 12, "seq_s"))


def sequences(which: str) -> list[tuple[str, int, int, str, int]]:
    """(name, seed, distance, regime, rate) of every sequence of ``which`` (``explore`` or ``check``)."""
    if which == "explore":
        return s30.sequences("fit")[:12]
    return s30.sequences({"check": "check_s33"}[which])


def main(argv: list[str]) -> int:
    s30.print_commands(sequences(argv[0] if argv else "explore"), argv[1:] or ["base"], "s33")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
