"""Session 40's candidate bundle: the shipped one with flip.onnx exported from a train-flip checkpoint (rule.txt).

    python reports/flip_s40/candidate.py DST [CKPT]     # DST must not exist; CKPT: runs/flip_s40n/last.pt

The shipped bundle's ``flip_classifier`` section (every gate) is kept as it is (``export-flip --no-manifest``).
"""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path


def main(dst: str, ckpt: str = "runs/flip_s40n/last.pt") -> None:
    from spacepose.bundle import load_bundle

    src = load_bundle(None, verify_graphs=False).path
    out = Path(dst)
    if out.exists():
        raise SystemExit(f"{out} exists")
    shutil.copytree(src, out)
    subprocess.run([sys.executable, "-m", "spacepose.cli", "export-flip", ckpt, "--out", str(out / "flip.onnx"),
                    "--no-manifest", "--force"], check=True)
    load_bundle(out)                                    # it loads, and its graphs verify


if __name__ == "__main__":
    main(*sys.argv[1:3])
