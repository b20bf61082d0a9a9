"""The sequences of session 34's check (reports/floor_s34/rule.txt).

    python reports/floor_s34/sequences.py check [MODE ...]   # a render and an eval command per sequence and mode

``check``: 12 sequences, seeds 3411-3422, rendered only after reports/floor_s34/rule.txt was committed;
``check2``: 12 sequences, seeds 3451-3462, rendered only after reports/floor_s34/rule2.txt was committed. The grids
(distance, regime, rate) are session 30's (reports/sequence_s30/sequences.py); 40 frames at 640x480 on the paper
rig. MODE ``base`` evaluates with the shipped bundle, any other (``cand``, ``floor``) with /tmp/s34/bundles/MODE
(rule.txt and rule2.txt say what they hold); reports go to ``runs/s34/<mode>_<name>.json``.
"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "sequence_s30"))
import sequences as s30  # noqa: E402

s30.SETS.setdefault("check_s34", (3411, 12, "seq_t"))
s30.SETS.setdefault("check2_s34", (3451, 12, "seq_v"))


def sequences(which: str) -> list[tuple[str, int, int, str, int]]:
    """(name, seed, distance, regime, rate) of every sequence of ``which`` (``check`` or ``check2``)."""
    return s30.sequences({"check": "check_s34", "check2": "check2_s34"}[which])


def main(argv: list[str]) -> int:
    s30.print_commands(sequences(argv[0] if argv else "check"), argv[1:] or ["base"], "s34")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
