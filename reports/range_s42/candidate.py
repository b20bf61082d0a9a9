"""Session 42's candidate bundle: the shipped one with the range fit (plan.txt).

    python reports/range_s42/candidate.py DST     # DST must not exist

Copies the shipped bundle and adds the ``range_fit`` section with :class:`spacepose.range_fit.RangeFitConfig`'s
defaults written out (window 7 px, offsets +-1.0 px in steps of 0.1 px, z-buffer cell 3 px and 0.25 m, residuals
under 3 px, at least 30 samples, 2 steps, moves up to 1.0 m); nothing else changes.
"""
from __future__ import annotations

import dataclasses
import json
import shutil
import sys
from pathlib import Path


def main(dst: str) -> None:
    from spacepose.bundle import load_bundle
    from spacepose.range_fit import RangeFitConfig

    src = load_bundle(None, verify_graphs=False).path
    out = Path(dst)
    if out.exists():
        raise SystemExit(f"{out} exists")
    shutil.copytree(src, out)
    data = json.loads((out / "bundle.json").read_text())
    data["range_fit"] = dataclasses.asdict(RangeFitConfig())
    (out / "bundle.json").write_text(json.dumps(data, indent=1) + "\n")
    if load_bundle(out).range_fit != RangeFitConfig():            # it loads, and its graphs verify
        raise SystemExit(f"{out}: the range_fit section did not load as written")


if __name__ == "__main__":
    main(*sys.argv[1:2])
