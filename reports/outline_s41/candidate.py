"""Session 41's candidate bundle: the shipped one with the outline refiner (plan.txt).

    python reports/outline_s41/candidate.py DST CKPT     # DST must not exist; CKPT: runs/outline_s41/last.pt

Copies the shipped bundle, exports CKPT to ``DST/outline.onnx`` (``spacepose export-outline``, which writes the
``outline_refiner`` section) and sets that section's ``grow_px`` 2 and ``keep_centre`` 1; nothing else changes.
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path


def main(dst: str, ckpt: str) -> None:
    from spacepose.bundle import load_bundle

    src = load_bundle(None, verify_graphs=False).path
    out = Path(dst)
    if out.exists():
        raise SystemExit(f"{out} exists")
    shutil.copytree(src, out)
    subprocess.run([sys.executable, "-m", "spacepose.cli", "export-outline", ckpt, "--out", str(out / "outline.onnx")],
                   check=True)
    data = json.loads((out / "bundle.json").read_text())
    data["outline_refiner"].update(grow_px=2, keep_centre=1)
    (out / "bundle.json").write_text(json.dumps(data, indent=1) + "\n")
    if load_bundle(out).outline_refiner is None:            # it loads, and its graphs verify
        raise SystemExit(f"{out}: no outline_refiner section")


if __name__ == "__main__":
    main(*sys.argv[1:3])
