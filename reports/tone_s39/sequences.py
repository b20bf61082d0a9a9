"""The sequences of session 39's check (reports/tone_s39/rule.txt).

    python reports/tone_s39/sequences.py render        # render + restyle commands
    python reports/tone_s39/sequences.py eval MODE...  # eval commands (base: the shipped bundle; else /tmp/s39/bundles/MODE)

12 sequences seq_y00..seq_y11, seeds 3921-3932, on session 30's grids (reports/sequence_s30/sequences.py), 40
frames at 640x480 on the paper rig; their restyled copies seq_yr00..seq_yr11 (restyle seeds 3941-3952, a style per
frame). Reports go to ``runs/s39/<mode>_<name>.json``.
"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "sequence_s30"))
import sequences as s30  # noqa: E402

s30.SETS.setdefault("check_s39", (3921, 12, "seq_y"))
RESTYLE_SEED = 3941


def sequences() -> list[tuple[str, int, int, str, int]]:
    """(name, seed, distance, regime, rate) of every plain sequence."""
    return s30.sequences("check_s39")


def main(argv: list[str]) -> int:
    what, modes = (argv[0] if argv else "render"), argv[1:] or ["base"]
    for i, (name, seed, distance, regime, rate) in enumerate(sequences()):
        restyled = name.replace("seq_y", "seq_yr")
        if what == "render":
            print(f"python -m spacepose.tools.sequence render data/{name} --frames 40 --distance {distance} "
                  f"--rate {rate} --regime {regime} --seed {seed} && python -m spacepose.tools.restyle data/{name} "
                  f"data/{restyled} --seed {RESTYLE_SEED + i} --split test")
            continue
        for folder in (name, restyled):
            for mode in modes:
                bundle = "" if mode == "base" else f" --bundle /tmp/s39/bundles/{mode}"
                print(f"python -m spacepose.tools.sequence eval data/{folder} --threads 1{bundle} "
                      f"--json runs/s39/{mode}_{folder}.json")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
