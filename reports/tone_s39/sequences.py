"""The sequences of session 39's check (reports/tone_s39/rule.txt).

    python reports/tone_s39/sequences.py render        # render + restyle commands
    python reports/tone_s39/sequences.py eval MODE...  # eval commands (base: the shipped bundle; else /tmp/s39/bundles/MODE)

12 sequences seq_y00..seq_y11, seeds 3921-3932, on session 30's grids (reports/sequence_s30/sequences.py), 40
frames at 640x480 on the paper rig; their restyled copies seq_yr00..seq_yr11 (restyle seeds 3941-3952, a style per
frame). Reports go to ``runs/s39/<mode>_<name>.json``.
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
    raise SystemExit(_s38.check_main(sys.argv[1:], "check_s39", 3921, "seq_y", 3941, "s39"))
