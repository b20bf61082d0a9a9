"""What a floor on ``PoseResult.confidence`` would cost an integrator (session 33), from the committed rows.

    python reports/stereo_s33/confidence_floor.py

``PoseResult.confidence`` is the calibrated probability that a valid pose is within 0.10 m and 2 deg (session 30).
A navigation filter may take only poses above a floor. For floors of 0.02-0.2 this prints how many of the shipped
bundle's valid poses a floor drops, and how many of those are wrong (off by > 20 deg or > 0.5 m), more than 20 deg
off in rotation, or within the bar. It uses two sets of rows, each the shipped bundle's (mode ``base``) over
independent frames and sequences: ``rows_explore.json.gz`` (1,670 spent frames) and ``rows.json.gz`` (1,134
frames rendered for reports/stereo_s33/rule.txt). Nothing in the runtime applies such a floor; the poses stay valid.
"""
from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
FLOORS = (0.02, 0.03, 0.05, 0.08, 0.10, 0.15, 0.20)


def valid_rows(path: Path, mode: str = "base") -> list[dict]:
    """The valid rows of ``mode`` in a judge rows file (independent sets ``<set>_<mode>``, ``seq_<mode>_<name>``)."""
    with gzip.open(path, "rt") as fh:
        rows = json.load(fh)
    return [r for k, rs in rows.items() if k.endswith(f"_{mode}") or k.startswith(f"seq_{mode}_")
            for r in rs if r["valid"]]


def table(valid: list[dict]) -> list[dict[str, float]]:
    """Per floor: the poses kept and dropped, and what the dropped ones were."""
    conf = np.array([r["confidence"] for r in valid])
    wrong = np.array([r["e_R"] > 20.0 or r["e_t"] > 0.5 for r in valid])
    rot = np.array([r["e_R"] > 20.0 for r in valid])
    within = np.array([r["e_R"] <= 2.0 and r["e_t"] <= 0.10 for r in valid])
    out = []
    for floor in FLOORS:
        drop = conf < floor
        out.append({"floor": floor, "kept": int((~drop).sum()), "dropped": int(drop.sum()),
                    "wrong_dropped": int((drop & wrong).sum()), "wrong_kept": int((~drop & wrong).sum()),
                    "rotation_dropped": int((drop & rot).sum()), "within_dropped": int((drop & within).sum())})
    return out


def main() -> int:
    for name, what in (("rows_explore.json.gz", "spent sets, 1,670 frames"),
                       ("rows.json.gz", "the rule's fresh sets, 1,134 frames")):
        valid = valid_rows(HERE / name)
        wrong = sum(r["e_R"] > 20.0 or r["e_t"] > 0.5 for r in valid)
        within = sum(r["e_R"] <= 2.0 and r["e_t"] <= 0.10 for r in valid)
        print(f"{what} ({name}), the shipped bundle: {len(valid)} valid poses, {wrong} wrong, {within} within the bar")
        print(f"  {'floor':>6}{'kept':>6}{'dropped':>9}{'wrong dropped':>15}{'wrong kept':>12}{'> 20 deg dropped':>18}"
              f"{'within dropped':>16}")
        for row in table(valid):
            print(f"  {row['floor']:>6.2f}{row['kept']:>6}{row['dropped']:>9}{row['wrong_dropped']:>15}"
                  f"{row['wrong_kept']:>12}{row['rotation_dropped']:>18}{row['within_dropped']:>16}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
