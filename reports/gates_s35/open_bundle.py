"""Write session 35's open bundle: the default bundle with the outline, image-route and classifier gates open, the
registration's margin closed and no confidence floor (reports/gates_s35/rule.txt).

    python reports/gates_s35/open_bundle.py OUT_DIR        # e.g. /tmp/s35/bundles/open
"""
from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

DEFAULT = Path(__file__).resolve().parents[2] / "runtime" / "bundles" / "default"
OPEN = {"silhouette": {"max_chamfer_px": 100.0, "min_margin_px": 0.0, "image_min_pixels": 0, "image_veto_score": -1.0,
                       "image_max_chamfer_px": 0.0, "min_flip_pixels": 0},
        "flip_classifier": {"decide_prob": 2.0, "veto_prob": -1.0},
        "registration": {"min_margin": 0.99}}


def main(argv: list[str]) -> int:
    out = Path(argv[0])
    if out.exists():
        raise SystemExit(f"{out} exists; not overwritten")
    shutil.copytree(DEFAULT, out)
    bundle = json.loads((out / "bundle.json").read_text())
    for section, values in OPEN.items():
        bundle[section].update(values)
    bundle["confidence"].pop("min_valid", None)
    (out / "bundle.json").write_text(json.dumps(bundle, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
