"""Session 38's candidate bundle: the shipped one with ``flip_classifier.decide_tone_gamma`` 2.0 (rule.txt).

    python reports/tone_s38/candidate.py DST      # DST must not exist
"""
from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

GAMMA = 2.0


def main(dst: str) -> None:
    from spacepose.bundle import load_bundle

    src = load_bundle(None, verify_graphs=False).path
    out = Path(dst)
    if out.exists():
        raise SystemExit(f"{out} exists")
    shutil.copytree(src, out)
    path = out / "bundle.json"
    data = json.loads(path.read_text(encoding="utf-8"))
    data["flip_classifier"]["decide_tone_gamma"] = GAMMA
    path.write_text(json.dumps(data, indent=1), encoding="utf-8")
    load_bundle(out)                                    # it loads, and its graphs verify


if __name__ == "__main__":
    main(sys.argv[1])
