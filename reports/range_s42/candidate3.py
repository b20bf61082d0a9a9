"""Session 42, round 3's bundles (plan3.txt), from the shipped bundle and the committed fits of round 2.

    python reports/range_s42/candidate3.py ROOT      # ROOT must not exist: ROOT/conf, ROOT/pos, ROOT/both

* conf: the uncertainty, tails and confidence constants of ``fit2_*.json`` (round 2's candidate, rounded to 4
  decimals as there) with the confidence floor ``min_valid`` 0.22;
* pos: the shipped bundle with ``range_fit.positions`` 1;
* both: conf with ``range_fit.positions`` 1.
"""
from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
MIN_VALID = 0.22


def _fit(name: str) -> dict:
    return {k: round(float(v), 4) for k, v in json.loads((HERE / f"fit2_{name}.json").read_text())["fit"].items()}


def main(root: str) -> None:
    from spacepose.bundle import load_bundle

    src = load_bundle(None, verify_graphs=False).path
    out = Path(root)
    if out.exists():
        raise SystemExit(f"{out} exists")
    for name in ("conf", "pos", "both"):
        shutil.copytree(src, out / name)
        data = json.loads((out / name / "bundle.json").read_text())
        if name in ("conf", "both"):
            data["uncertainty"] = {**data["uncertainty"], **_fit("uncertainty"), **_fit("tails")}
            data["confidence"] = {**data["confidence"], **_fit("confidence"), "min_valid": MIN_VALID}
        if name in ("pos", "both"):
            data["range_fit"] = {**data["range_fit"], "positions": 1}
        (out / name / "bundle.json").write_text(json.dumps(data, indent=1) + "\n")
        b = load_bundle(out / name)                                     # it loads, and its graphs verify
        print(name, b.confidence, b.uncertainty, b.range_fit, sep="\n  ")


if __name__ == "__main__":
    main(sys.argv[1])
