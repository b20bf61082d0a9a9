"""The sequences of session 41's outline-refiner check (reports/outline_s41/plan.txt).

    python reports/outline_s41/sequences.py render        # render + restyle commands
    python reports/outline_s41/sequences.py eval MODE...  # eval commands (base: the shipped bundle; else
                                                          # /tmp/s41/bundles/MODE)

12 sequences seq_m00..seq_m11, seeds 4421-4432, on session 30's grids (reports/sequence_s30/sequences.py), 40
frames at 640x480 on the paper rig; their restyled copies seq_mr00..seq_mr11 (restyle seeds 4441-4452, a style per
frame). Reports go to ``runs/s41/<mode>_<name>.json``.
"""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

_spec = importlib.util.spec_from_file_location("tone_s38_sequences",
                                               Path(__file__).resolve().parent.parent / "tone_s38" / "sequences.py")
_s38 = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_s38)          # session 38's commands, and session 30's grids through it


if __name__ == "__main__":
    raise SystemExit(_s38.check_main(sys.argv[1:], "check_s41o", 4421, "seq_m", 4441, "s41"))
