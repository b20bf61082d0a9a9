"""An *open* copy of a bundle: its decision gates opened, so that one evaluation yields rows to choose gates from.

A new stereo graph moves the outlines that the silhouette, image-route and flip-classifier gates were set on
(model card, sessions 33–35), so every new graph needs its gates re-derived: evaluate fresh frames with the gates
open, then replay candidate gates over the rows (:func:`spacepose.tools.calibrate_gates.flip_gate_table`) and
judge the chosen ones on frames rendered after the choice. The copy opens what session 35's open bundle opened
(:data:`OPEN_GATES`): the outline route's chamfer and margin, the image route's and the classifier's limits; it
closes the registration's own decision (``min_margin`` 0.99), so every decision goes through the outline stage;
and it drops the confidence floor (``confidence.min_valid``), which any replay applies afterwards.

``python -m spacepose.tools.open_gates SRC DST``

Nothing in ``SRC`` is touched; ``DST`` must not exist.
"""

from __future__ import annotations

import argparse
import json
import logging
import shutil
from pathlib import Path
from typing import Any, Mapping, Sequence

from spacepose.errors import BundleError

log = logging.getLogger(__name__)

__all__ = ["OPEN_GATES", "write_open_bundle", "main"]

#: the values an open bundle gets, by ``bundle.json`` section (session 35's ``reports/gates_s35/open_bundle.py``)
OPEN_GATES: Mapping[str, Mapping[str, Any]] = {
    "silhouette": {"max_chamfer_px": 100.0, "min_margin_px": 0.0, "image_min_pixels": 0, "image_veto_score": -1.0,
                   "image_max_chamfer_px": 0.0, "min_flip_pixels": 0},
    "flip_classifier": {"decide_prob": 2.0, "veto_prob": -1.0},
    "registration": {"min_margin": 0.99},
}


def write_open_bundle(src: str | Path, dst: str | Path) -> Path:
    """Copy the bundle folder ``src`` to ``dst`` with :data:`OPEN_GATES` set and no confidence floor; returns ``dst``.

    Raises:
        BundleError: ``src`` has no ``bundle.json`` or lacks a section :data:`OPEN_GATES` sets, or ``dst`` exists.
    """
    src, dst = Path(src), Path(dst)
    if not (src / "bundle.json").is_file():
        raise BundleError(f"{src} is not a bundle folder (no bundle.json)")
    if dst.exists():
        raise BundleError(f"{dst} exists; an open bundle is written to a new folder only")
    doc = json.loads((src / "bundle.json").read_text(encoding="utf-8"))
    missing = [name for name in OPEN_GATES if not isinstance(doc.get(name), dict)]
    if missing:
        raise BundleError(f"{src}/bundle.json has no {', '.join(missing)} section: nothing to open there")
    shutil.copytree(src, dst)
    for name, values in OPEN_GATES.items():
        doc[name].update(values)
    if isinstance(doc.get("confidence"), dict):
        doc["confidence"].pop("min_valid", None)
    (dst / "bundle.json").write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    log.info("open bundle written to %s", dst)
    return dst


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m spacepose.tools.open_gates", description=__doc__.split("\n\n")[0])
    p.add_argument("src", type=Path, help="bundle folder to copy")
    p.add_argument("dst", type=Path, help="new folder for the open copy")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    try:
        write_open_bundle(args.src, args.dst)
    except BundleError as exc:
        raise SystemExit(f"error: {exc}") from exc
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
