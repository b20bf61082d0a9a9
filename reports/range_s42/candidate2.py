"""Session 42's second candidate: the shipped bundle (with the range fit) with its uncertainty, tails and confidence
constants fitted again on the rows of round 1's candidate (plan2.txt).

    python reports/range_s42/candidate2.py DST ROWS...   # DST must not exist; ROWS: runs/s42/check_cand_{plain,rest}.json.gz

Three fits of ``spacepose.tools.calibrate_uncertainty``, in order, each on ROWS (their outputs beside this file,
``fit2_{uncertainty,tails,confidence}.json``): the six constants of the ``uncertainty`` section (``--fit``), then its
``tail_dof`` against those sigmas (``--tails --fit``), then the ``confidence`` section's ``bias`` and ``slope`` with
those sigmas (``--confidence --fit``); each constant rounded to 4 decimals, as the shipped ones. Nothing else changes
(the confidence floor ``min_valid`` is kept: a floor is chosen, not fitted).
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _fit(rows: list[str], flags: list[str], bundle: Path, name: str) -> dict:
    out = HERE / f"fit2_{name}.json"
    subprocess.run([sys.executable, "-m", "spacepose.tools.calibrate_uncertainty", *rows, "--fit", *flags,
                    "--bundle", str(bundle), "--json", str(out)], check=True, stdout=subprocess.DEVNULL)
    doc = json.loads(out.read_text())
    return {k: round(float(v), 4) for k, v in doc["fit"].items()}


def _update(bundle: Path, section: str, values: dict) -> None:
    data = json.loads((bundle / "bundle.json").read_text())
    data[section] = {**data[section], **values}
    (bundle / "bundle.json").write_text(json.dumps(data, indent=1) + "\n")


def main(dst: str, rows: list[str]) -> None:
    from spacepose.bundle import load_bundle

    src = load_bundle(None, verify_graphs=False).path
    out = Path(dst)
    if out.exists():
        raise SystemExit(f"{out} exists")
    shutil.copytree(src, out)
    _update(out, "uncertainty", _fit(rows, [], out, "uncertainty"))
    _update(out, "uncertainty", _fit(rows, ["--tails"], out, "tails"))
    _update(out, "confidence", _fit(rows, ["--confidence"], out, "confidence"))
    model = load_bundle(out)                                        # it loads, and its graphs verify
    print(json.dumps({"uncertainty": model.uncertainty.__dict__, "confidence": model.confidence.__dict__}, indent=1))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2:])
