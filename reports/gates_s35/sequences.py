"""The sequences of session 35's check (reports/gates_s35/rule.txt).

    python reports/gates_s35/sequences.py check|check2 [MODE ...]   # a render and an eval command per sequence and mode

``check``: 12 sequences, seeds 3511-3522, rendered only after reports/gates_s35/rule.txt was committed; ``check2``:
12 sequences, seeds 3551-3562, rendered only after reports/gates_s35/rule2.txt was committed. The grids
(distance, regime, rate) are session 30's (reports/sequence_s30/sequences.py); 40 frames at 640x480 on the paper
rig. MODE ``base`` evaluates with the shipped bundle, any other (``cand``, ``cand2``) with /tmp/s35/bundles/MODE
(rule.txt and rule2.txt say what they hold); reports go to ``runs/s35/<mode>_<name>.json``.
"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "sequence_s30"))
import sequences as s30  # noqa: E402

s30.SETS.setdefault("check_s35", (3511, 12, "seq_x"))
s30.SETS.setdefault("check2_s35", (3551, 12, "seq_y"))


def sequences(which: str = "check") -> list[tuple[str, int, int, str, int]]:
    """(name, seed, distance, regime, rate) of every sequence of ``which`` (``check`` or ``check2``)."""
    return s30.sequences({"check": "check_s35", "check2": "check2_s35"}[which])


def main(argv: list[str]) -> int:
    s30.print_commands(sequences(argv[0] if argv else "check"), argv[1:] or ["base"], "s35")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
