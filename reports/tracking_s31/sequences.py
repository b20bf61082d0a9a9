"""The sequences of session 31's look at the tracking route's chamfer gate.

    python reports/tracking_s31/sequences.py fit|check   # one render and one eval command per sequence and mode

``fit``: session 30's 24 fit sequences (seeds 3011-3034, spent), rendered again. ``check``: 16 sequences, seeds
3101-3116, rendered only after reports/tracking_s31/rule.txt was committed. The grids (distance, regime, rate)
are session 30's (reports/sequence_s30/sequences.py); 40 frames at 640x480 on the paper rig. Each sequence is
evaluated with the shipped bundle (``runs/s31/base_<name>.json``) and with the candidate, a copy of it whose
``silhouette.track_max_chamfer_px`` is set (``runs/s31/<mode>_<name>.json``, bundles in /tmp/s31/bundles/<mode>).
"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "sequence_s30"))
import sequences as s30  # noqa: E402

s30.SETS.setdefault("check_s31", (3101, 16, "seq_e"))
WHICH = {"fit": "fit", "check": "check_s31"}


def sequences(which: str) -> list[tuple[str, int, int, str, int]]:
    """(name, seed, distance, regime, rate) of every sequence of ``which`` (``fit`` or ``check``)."""
    return s30.sequences(WHICH[which])


def main(argv: list[str]) -> int:
    which = argv[0] if argv else "fit"
    s30.print_commands(sequences(which), argv[1:] or ["base"], "s31")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
