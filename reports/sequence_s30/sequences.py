"""The sequences of session 30's look at the uncertainty and confidence of poses in sequences (tracking).

    python reports/sequence_s30/sequences.py fit|check|check2   # one render and one eval command per sequence

``fit``: 24 sequences, seeds 3011-3034 (spent for exploration and fitting). ``check``: 16 sequences, seeds
3051-3066, rendered only after reports/sequence_s30/rule.txt was committed. ``check2``: 16 sequences, seeds
3071-3086, rendered only after reports/sequence_s30/rule2.txt was committed. Each: 40 frames at
640x480 on the paper rig; the distance, regime and rate cycle over the grids below, so that every set mixes them.
The eval uses the shipped bundle with the prior, as a flight computer runs it (``sequence eval``).
"""
from __future__ import annotations

import sys

DISTANCES = (12, 16, 20, 24, 28, 32, 36, 40)
REGIMES = ("sun", "albedo", "penumbra", "mixed")
RATES = (1, 2, 3)
SETS = {"fit": (3011, 24, "seq_f"), "check": (3051, 16, "seq_c"), "check2": (3071, 16, "seq_d")}


def sequences(which: str) -> list[tuple[str, int, int, str, int]]:
    """(name, seed, distance, regime, rate) of every sequence of ``which``."""
    first, count, prefix = SETS[which]
    return [(f"{prefix}{i:02d}", first + i, DISTANCES[i % 8], REGIMES[(i + i // 8) % 4], RATES[i % 3])
            for i in range(count)]


def print_commands(sequences_: list[tuple[str, int, int, str, int]], modes: list[str], session: str) -> None:
    """A render command per sequence and an eval command per sequence and mode, for the later sessions' scripts:
    ``base`` with the shipped bundle, any other mode with ``/tmp/<session>/bundles/<mode>``; reports to
    ``runs/<session>/<mode>_<name>.json``."""
    for name, seed, distance, regime, rate in sequences_:
        print(f"python -m spacepose.tools.sequence render data/{name} --frames 40 --distance {distance} --rate {rate} "
              f"--regime {regime} --seed {seed}")
        for mode in modes:
            bundle = "" if mode == "base" else f" --bundle /tmp/{session}/bundles/{mode}"
            print(f"python -m spacepose.tools.sequence eval data/{name} --threads 1{bundle} "
                  f"--json runs/{session}/{mode}_{name}.json")


def main(argv: list[str]) -> int:
    for name, seed, distance, regime, rate in sequences(argv[0] if argv else "fit"):
        print(f"python -m spacepose.tools.sequence render data/{name} --frames 40 --distance {distance} --rate {rate} "
              f"--regime {regime} --seed {seed}")
        print(f"python -m spacepose.tools.sequence eval data/{name} --threads 1 --json runs/s30/{name}.json")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
