"""Session 42: the confidence floor for round 3 (plan3.txt), chosen on round 2's open rows (F2+R2, spent).

    python reports/range_s42/floor_choice.py

Round 2's candidate reported every pose whose refitted confidence reached 0.08, so its rows hold every pose any floor
of 0.08 or more would report. The rule: the floor is the highest confidence of a wrong pose in those rows (wrong: e_t
> 0.5 m or e_R > 20 deg) rounded up to 0.01, plus 0.01. Printed: valid, wrong, within and poses more than 5 deg off
at floors from 0.08 to 0.30, and the choice.
"""
from __future__ import annotations

import gzip
import json
import math
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def main() -> None:
    rows = [r for s in ("plain", "rest")
            for r in json.loads(gzip.decompress((HERE / f"check2_cand_{s}.json.gz").read_bytes()))["frames"]
            if r["valid"]]
    c = np.array([r["confidence"] for r in rows])
    e_t, e_r = np.array([r["e_t"] for r in rows]), np.array([r["e_R"] for r in rows])
    wrong, within = (e_t > 0.5) | (e_r > 20.0), (e_t <= 0.10) & (e_r <= 2.0)
    print(f"{len(rows)} valid poses of round 2's candidate on F2+R2; confidences of the wrong ones: "
          f"{np.round(np.sort(c[wrong]), 3).tolist()}; lowest confidence {c.min():.3f}")
    print("| floor | valid | wrong | within | > 5 deg off |")
    print("|---|---|---|---|---|")
    for f in (0.08, 0.15, 0.20, 0.21, 0.22, 0.25, 0.30):
        m = c >= f
        print(f"| {f:.2f} | {int(m.sum())} | {int((wrong & m).sum())} | {int((within & m).sum())} | "
              f"{int(((e_r > 5.0) & m).sum())} |")
    floor = math.ceil(float(c[wrong].max()) * 100 - 1e-9) / 100 + 0.01 if wrong.any() else 0.08
    print(f"chosen floor: {floor:.2f}")


if __name__ == "__main__":
    main()
