"""The sequences of session 41's check (reports/flip_s41/plan.txt).

    python reports/flip_s41/sequences.py [--round 2] render        # render + restyle commands
    python reports/flip_s41/sequences.py [--round 2] eval MODE...  # eval commands (base: the shipped bundle; else
                                                                   # /tmp/s41/bundles/MODE)

12 sequences seq_w00..seq_w11, seeds 4121-4132, on session 30's grids (reports/sequence_s30/sequences.py), 40
frames at 640x480 on the paper rig; their restyled copies seq_wr00..seq_wr11 (restyle seeds 4141-4152, a style per
frame). Round 2 (plan2.txt): seq_k00..seq_k11, seeds 4221-4232, restyled seq_kr00..seq_kr11 (restyle seeds
4241-4252). Reports go to ``runs/s41/<mode>_<name>.json``.
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
    if sys.argv[1:3] == ["--round", "2"]:
        raise SystemExit(_s38.check_main(sys.argv[3:], "check_s41b", 4221, "seq_k", 4241, "s41"))
    raise SystemExit(_s38.check_main(sys.argv[1:], "check_s41", 4121, "seq_w", 4141, "s41"))
