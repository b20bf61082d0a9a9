"""The sequences of session 32's look at the polish cap (``silhouette.max_decided_polish_deg``) in sequences.

    python reports/polish_s32/sequences.py fit|check|check2 [MODE ...]   # one render and one eval command per sequence and mode

``fit``: session 30's 24 fit sequences (seeds 3011-3034, spent), rendered again. ``check``: 16 sequences, seeds
3201-3216, rendered only after reports/polish_s32/rule.txt was committed. ``check2``: 16 sequences, seeds 3231-3246,
rendered only after reports/polish_s32/rule2.txt was committed. The grids (distance, regime, rate) are
session 30's (reports/sequence_s30/sequences.py); 40 frames at 640x480 on the paper rig. Each sequence is evaluated
with the shipped bundle (``runs/s32/base_<name>.json``) and with copies of it (``runs/s32/<mode>_<name>.json``,
bundles in /tmp/s32/bundles/<mode>; ``nocap``: ``max_decided_polish_deg`` 0, the session-30 behaviour).
"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "sequence_s30"))
import sequences as s30  # noqa: E402

s30.SETS.setdefault("check_s32", (3201, 16, "seq_p"))
s30.SETS.setdefault("check2_s32", (3231, 16, "seq_q"))
WHICH = {"fit": "fit", "check": "check_s32", "check2": "check2_s32"}


def sequences(which: str) -> list[tuple[str, int, int, str, int]]:
    """(name, seed, distance, regime, rate) of every sequence of ``which`` (``fit``, ``check`` or ``check2``)."""
    return s30.sequences(WHICH[which])


def main(argv: list[str]) -> int:
    which = argv[0] if argv else "fit"
    s30.print_commands(sequences(which), argv[1:] or ["base"], "s32")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
