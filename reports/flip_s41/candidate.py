"""Session 41's candidate bundle: the shipped one with session 40's flip classifier as a second graph (plan.txt,
plan2.txt).

    python reports/flip_s41/candidate.py DST AGREE [CKPT]     # DST must not exist; CKPT: runs/flip_s40n/last.pt

Copies the shipped bundle, exports CKPT to ``DST/flip2.onnx`` (``export-flip --no-manifest``) and adds
``second_file`` "flip2.onnx" and ``second_agree_prob`` AGREE to its ``flip_classifier`` section; every other key
stays as shipped.
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path


def main(dst: str, agree: str, ckpt: str = "runs/flip_s40n/last.pt") -> None:
    from spacepose.bundle import load_bundle

    src = load_bundle(None, verify_graphs=False).path
    out = Path(dst)
    if out.exists():
        raise SystemExit(f"{out} exists")
    shutil.copytree(src, out)
    subprocess.run([sys.executable, "-m", "spacepose.cli", "export-flip", ckpt, "--out", str(out / "flip2.onnx"),
                    "--no-manifest"], check=True)
    data = json.loads((out / "bundle.json").read_text())
    data["flip_classifier"].update(second_file="flip2.onnx", second_agree_prob=float(agree))
    (out / "bundle.json").write_text(json.dumps(data, indent=1) + "\n")
    load_bundle(out)                                    # it loads, and its graphs verify


if __name__ == "__main__":
    main(*sys.argv[1:4])
