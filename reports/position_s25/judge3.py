"""Round 3 of session 25 (``plan3.txt``): the window from a position-only frame, on 13 fresh sequences.

    python reports/position_s25/judge3.py [RUNS]

reads ``RUNS/seq/{S,C}/seq_m{K}.json`` (default ``runs/s25``) when all exist and writes the compact rows beside this
file (``seq_rows.json.gz``); else reads those committed rows. Prints per sequence and pooled valid / wrong / flips
and the mean stereo-stage time, then the verdict of the plan's rule.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from _rows import compact_rows

HERE = Path(__file__).resolve().parent
SEQS = [f"seq_m{k}" for k in range(1, 14)]
HIGH = {"seq_m11", "seq_m12", "seq_m13"}
KEYS = ("frame", "valid", "status", "tracked", "e_t", "e_R", "position_valid", "stereo_ms")


def load(runs: Path) -> dict[str, dict[str, list[dict]]]:
    files = {f"{b}/{s}": [runs / "seq" / b / f"{s}.json"] for b in ("S", "C") for s in SEQS}
    rows = compact_rows(files, HERE / "seq_rows.json.gz", KEYS)
    return {b: {s: rows[f"{b}/{s}"] for s in SEQS} for b in ("S", "C")}


def wrong(r: dict) -> bool:
    return r["valid"] and (r["e_R"] > 20.0 or r["e_t"] > 0.5)


def main() -> int:
    data = load(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("runs/s25"))
    tot = {b: [0, 0, 0] for b in data}
    print(f"{'sequence':<10}{'S valid/wrong/flip':>20}{'C valid/wrong/flip':>20}{'S stereo ms':>13}{'C stereo ms':>13}")
    new_flips = []
    ms = {b: [] for b in data}
    for s in SEQS:
        cells = []
        for b in ("S", "C"):
            rows = data[b][s]
            v = sum(r["valid"] for r in rows)
            w = sum(wrong(r) for r in rows)
            f = sum(r["valid"] and r["e_R"] > 90.0 for r in rows)
            tot[b][0] += v; tot[b][1] += w; tot[b][2] += f
            cells.append(f"{v}/{w}/{f}")
            if s in HIGH:
                ms[b] += [r["stereo_ms"] for r in rows]
        for rs, rc in zip(data["S"][s], data["C"][s]):
            if rc["valid"] and rc["e_R"] > 90.0 and not (rs["valid"] and rs["e_R"] > 90.0):
                new_flips.append((s, rc["frame"], rc["e_R"]))
        t = [np.mean([r["stereo_ms"] for r in data[b][s]]) for b in ("S", "C")]
        print(f"{s:<10}{cells[0]:>20}{cells[1]:>20}{t[0]:>13.1f}{t[1]:>13.1f}")
    print(f"{'pooled':<10}{'/'.join(map(str, tot['S'])):>20}{'/'.join(map(str, tot['C'])):>20}")
    pos = {b: sum(r["position_valid"] for s in SEQS for r in data[b][s]) for b in data}
    print(f"position-valid frames: S {pos['S']}, C {pos['C']} of {sum(len(data['S'][s]) for s in SEQS)}")
    m_s, m_c = float(np.mean(ms["S"])), float(np.mean(ms["C"]))
    c1 = tot["C"][0] >= 0.97 * tot["S"][0] and tot["C"][1] <= tot["S"][1]
    c2 = not new_flips
    c3 = m_c < m_s
    print(f"1. valid {tot['C'][0]} >= 0.97 x {tot['S'][0]} and wrong {tot['C'][1]} <= {tot['S'][1]}: {'met' if c1 else 'NOT met'}")
    print(f"2. flips only C reports: {new_flips or 'none'}: {'met' if c2 else 'NOT met'}")
    print(f"3. 1280x960 mean stereo stage {m_c:.1f} ms (C) < {m_s:.1f} ms (S): {'met' if c3 else 'NOT met'}")
    print("verdict:", "met, position_window becomes the default" if c1 and c2 and c3 else "NOT met, position_window stays off")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
