"""Choose a bundle's flip-decision gates from open rows by one fixed rule, and write the candidate bundle.

Sessions 33–35 re-derived the silhouette, image-route and flip-classifier gates for a new stereo graph by hand:
open rows (:mod:`spacepose.tools.open_gates`, :mod:`spacepose.tools.shard_eval`), a replay of every grid cell
(:func:`spacepose.tools.calibrate_gates.flip_gate_table`), a choice, then a check on frames rendered after it.
This tool makes the choice mechanical, so that it can be written down (committed) before the check frames exist,
and so that the same rule serves every new graph:

1. The bundle's confidence floor (``confidence.min_valid``) turns the rows' poses under it invalid: it acts after
   every gate.
2. The *reference* is the bundle's own gates replayed on the rows. Rows of another graph's open evaluation may
   stand in for the reference's own (``--reference-rows``: then its counts come from those rows).
3. A cell of :data:`GRID` is *safe* when it keeps no flip (``e_R`` > 90°) and no more wrong poses (> 0.5 m or > 20°)
   than the reference, and so does every cell one grid step away in any one gate (a cell at the edge of a flip is
   not chosen: session 35's round 1 failed that way).
4. The flip classifier's gates may only be tightened unless there are at least ``--classifier-rows`` rows
   (default 4,000): far-off poses come about once per thousand frames, and loosening them let one through in
   session 35. The same holds for the outline route's margin (``--margin-rows``, default 4,000; session 37 added
   this after a margin of 0.2 px, chosen on 1,620 rows, let a 179.9° flip through on fresh frames; ``--margin-rows
   0`` gives the choices of ``reports/wide_s37``).
5. The chosen cell is the safe one with the most poses within the bar (0.10 m and 2°), then the most kept, then the
   fewest wrong, then the nearest to the reference (fewest gates moved, then fewest grid steps). Unless it has more
   within than the reference by at least ``--min-gain`` (default 3 %), the reference is kept: a gain smaller than
   that is noise on a few thousand rows.

``python -m spacepose.tools.choose_gates ROWS... --bundle B [--reference-rows ROWS...] [--out choice.json]
[--margin-rows 4000] [--min-gain 0.03] [--write-bundle DST]``

The replay models the outline, image and classifier routes of a decision (not tracking, the polish caps or the
registration's own decision, which the open bundle closes), so the counts it predicts need the check on fresh frames.
"""

from __future__ import annotations

import argparse
import gzip
import itertools
import json
import logging
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

from spacepose.errors import BundleError, DatasetError

log = logging.getLogger(__name__)

__all__ = ["GRID", "BUNDLE_KEYS", "CLASSIFIER_GATES", "MARGIN_GATES", "Choice", "load_rows", "reference_gates", "floored",
           "replay", "choose", "write_candidate", "main"]

#: cell key -> (bundle.json section, key)
BUNDLE_KEYS: Mapping[str, tuple[str, str]] = {
    "max_chamfer_px": ("silhouette", "max_chamfer_px"), "min_margin_px": ("silhouette", "min_margin_px"),
    "image_margin": ("silhouette", "image_min_margin_px"), "image_score": ("silhouette", "image_min_score"),
    "image_veto": ("silhouette", "image_veto_score"), "image_chamfer": ("silhouette", "image_max_chamfer_px"),
    "decide_prob": ("flip_classifier", "decide_prob"), "veto_prob": ("flip_classifier", "veto_prob"),
    "flip_chamfer": ("flip_classifier", "max_chamfer_px"),
}
#: the values each gate may take (session 35's grid, ``reports/gates_s35/explore.py``); the reference's value is
#: added to its gate's list
GRID: Mapping[str, tuple[float, ...]] = {
    "max_chamfer_px": (1.0, 1.25, 1.5, 1.75, 2.0, 2.5, 3.0), "min_margin_px": (0.2, 0.3, 0.4, 0.5, 0.7, 1.0, 1.5),
    "image_margin": (0.0, 0.1, 0.2, 0.3), "image_score": (0.05, 0.1, 0.2), "image_veto": (-1.0, -0.5, 0.0),
    "image_chamfer": (0.0, 2.0, 2.5, 3.0), "decide_prob": (0.97, 0.99, 0.995, 0.999, 2.0),
    "veto_prob": (-1.0, 0.05, 0.1, 0.2), "flip_chamfer": (1.0, 1.5, 2.0, 2.5),
}
#: the classifier's gates, and the direction that tightens each (+1: a larger value decides fewer frames)
CLASSIFIER_GATES: Mapping[str, int] = {"decide_prob": +1, "veto_prob": +1, "flip_chamfer": -1}
#: the outline route's margin, and the direction that tightens it
MARGIN_GATES: Mapping[str, int] = {"min_margin_px": +1}
#: fixed for the replay, from the bundle: (cell key, section, key, default)
_FIXED = (("image_pixels", "silhouette", "image_min_pixels", 16), ("flip_pixels", "silhouette", "min_flip_pixels", 16),
          ("max_background", "silhouette", "image_max_background", 0.02),
          ("max_depth_tolerance_m", "flip_classifier", "max_depth_tolerance_m", 0.0),
          ("max_polish_deg", "flip_classifier", "max_polish_deg", 0.0))
WRONG_T_M, WRONG_R_DEG = 0.5, 20.0


@dataclass(frozen=True)
class Choice:
    """What :func:`choose` found: the ``reference`` and ``chosen`` cells with their counts (``kept``, ``within``,
    ``wrong``, ``flips``, ...), the number of ``safe`` cells, the ``top`` safe cells, whether the classifier's
    gates (and the outline margin: ``margin_may_loosen``) were allowed to loosen, and whether the chosen cell is
    safe itself (``chosen_safe``: not so when the
    reference's gates are kept but, on another graph's rows, keep a flip or more wrong poses than the reference;
    such a graph should not ship with them)."""

    reference: dict[str, Any]
    chosen: dict[str, Any]
    safe: int
    cells: int
    top: list[dict[str, Any]]
    classifier_may_loosen: bool
    chosen_safe: bool = True
    margin_may_loosen: bool = True

    @property
    def changed(self) -> dict[str, tuple[float, float]]:
        """Gate -> (reference value, chosen value) for every gate the choice moves."""
        return {k: (self.reference[k], self.chosen[k]) for k in GRID if self.reference[k] != self.chosen[k]}


def load_rows(paths: Sequence[str | Path]) -> list[dict[str, Any]]:
    """The rows of every file: a report's ``frames`` (``pose_eval.json``, or gzipped like
    :mod:`spacepose.tools.shard_eval`'s) or a bare list of rows (``reports/gates_s35/open_rows.json.gz``)."""
    rows: list[dict[str, Any]] = []
    for path in map(Path, paths):
        raw = path.read_bytes()
        doc = json.loads(gzip.decompress(raw) if path.suffix == ".gz" else raw)
        found = doc.get("frames") if isinstance(doc, dict) else doc     # a report, or a bare list of rows
        if not isinstance(found, list) or not all(isinstance(r, dict) for r in found):
            raise DatasetError(f"{path} holds no rows (a report's 'frames' or a list of rows)")
        rows.extend(found)
    return rows


def _bundle_doc(bundle: str | Path) -> dict[str, Any]:
    path = Path(bundle) / "bundle.json"
    if not path.is_file():
        raise BundleError(f"{bundle} is not a bundle folder (no bundle.json)")
    doc = json.loads(path.read_text(encoding="utf-8"))
    for section in ("silhouette", "flip_classifier"):
        if not isinstance(doc.get(section), dict):
            raise BundleError(f"{path} has no {section} section")
    return doc


def reference_gates(bundle: str | Path) -> tuple[dict[str, float], dict[str, float], float]:
    """``(gates, fixed, floor)`` of ``bundle``: its values of the :data:`GRID` gates, the replay's fixed settings and
    its confidence floor (0 when it has none)."""
    doc = _bundle_doc(bundle)
    gates = {}
    for cell, (section, key) in BUNDLE_KEYS.items():
        if key not in doc[section]:
            raise BundleError(f"{bundle}/bundle.json: {section}.{key} is missing")
        gates[cell] = float(doc[section][key])
    fixed = {cell: float(doc[section].get(key, default)) for cell, section, key, default in _FIXED}
    floor = float(doc.get("confidence", {}).get("min_valid", 0.0))
    return gates, fixed, floor


def floored(rows: Sequence[dict[str, Any]], floor: float) -> list[dict[str, Any]]:
    """``rows`` with every valid pose whose confidence is under ``floor`` turned invalid."""
    return [dict(r, valid=False) if r.get("valid") and not r.get("confidence", 0.0) >= floor else r for r in rows]


def replay(rows: Sequence[dict[str, Any]], values: Mapping[str, Sequence[float]], fixed: Mapping[str, float]
           ) -> list[dict[str, Any]]:
    """The counts of every cell of the grid ``values`` (gate -> values) on ``rows``, cell values included
    (:func:`spacepose.tools.calibrate_gates.flip_gate_table`, the classifier's gates swept inside each call)."""
    from spacepose.tools.calibrate_gates import flip_gate_table

    outer = [n for n in GRID if n not in CLASSIFIER_GATES]
    out = []
    for combo in itertools.product(*(values[n] for n in outer)):
        cell = dict(zip(outer, combo))
        if not cell["image_veto"] < cell["image_score"]:
            continue
        table = flip_gate_table(rows, values["decide_prob"], values["veto_prob"], values["flip_chamfer"],
                                max_chamfer_px=cell["max_chamfer_px"], min_margin_px=cell["min_margin_px"],
                                image_margin=cell["image_margin"], image_score=cell["image_score"],
                                image_pixels=int(fixed["image_pixels"]), image_veto=cell["image_veto"],
                                image_chamfer=cell["image_chamfer"], flip_pixels=int(fixed["flip_pixels"]),
                                max_background=fixed["max_background"], max_e_t=WRONG_T_M, max_e_r=WRONG_R_DEG,
                                max_depth_tolerance_m=fixed["max_depth_tolerance_m"],
                                max_polish_deg=fixed["max_polish_deg"])
        for r in table:
            out.append({**cell, "decide_prob": r["decide_prob"], "veto_prob": r["veto_prob"],
                        "flip_chamfer": r["max_chamfer_px"],
                        **{k: r[k] for k in ("kept", "within", "wrong", "flips", "decided", "vetoed", "e_t_mean",
                                             "e_R_mean")}})
    return out


def _values(reference: Mapping[str, float], fixed_directions: Mapping[str, int], grid: Mapping[str, Sequence[float]]
            ) -> dict[str, list[float]]:
    """Each gate's values: ``grid``'s and the reference's; a gate of ``fixed_directions`` only at the reference's
    value or tighter (the direction's sign)."""
    values = {}
    for gate in GRID:
        vals = sorted(set(grid[gate]) | {reference[gate]})
        if gate in fixed_directions:
            vals = [v for v in vals if fixed_directions[gate] * (v - reference[gate]) >= 0]
        values[gate] = vals
    return values


def choose(rows: Sequence[dict[str, Any]], bundle: str | Path, *, reference_rows: Sequence[dict[str, Any]] | None = None,
           classifier_rows: int = 4000, margin_rows: int = 4000, min_gain: float = 0.03, top: int = 20,
           grid: Mapping[str, Sequence[float]] | None = None) -> Choice:
    """The rule of the module docstring on ``rows`` (open rows of the candidate graph) for ``bundle``'s gates, over
    ``grid`` (default :data:`GRID`; gate -> values, the reference's value added to each)."""
    grid = GRID if grid is None else grid
    if set(grid) != set(GRID):
        raise ValueError(f"grid must name the gates {sorted(GRID)}, got {sorted(grid)}")
    reference, fixed, floor = reference_gates(bundle)
    rows = floored(rows, floor)
    if not any(r.get("valid") for r in rows):
        raise DatasetError("no row holds a pose: open rows are needed (spacepose.tools.open_gates)")
    ref_rows = floored(reference_rows, floor) if reference_rows is not None else rows
    if not reference["image_veto"] < reference["image_score"]:
        raise BundleError(f"{bundle}: silhouette.image_veto_score must be under image_min_score")
    ref = replay(ref_rows, {n: (reference[n],) for n in GRID}, fixed)[0]
    may_loosen = len(rows) >= classifier_rows
    tighten_only = {**({} if may_loosen else CLASSIFIER_GATES), **({} if len(rows) >= margin_rows else MARGIN_GATES)}
    values = _values(reference, tighten_only, grid)
    names = list(GRID)
    table = replay(rows, values, fixed)
    index = {tuple(r[n] for n in names): r for r in table}

    def ok(r: Mapping[str, Any]) -> bool:
        return r["flips"] == 0 and r["wrong"] <= ref["wrong"]

    def neighbours_ok(r: Mapping[str, Any]) -> bool:
        for i, n in enumerate(names):
            j = values[n].index(r[n])
            for k in (j - 1, j + 1):
                if 0 <= k < len(values[n]):
                    key = tuple(values[n][k] if m == i else r[names[m]] for m in range(len(names)))
                    if key in index and index[key]["flips"] > 0:
                        return False
        return True

    def moved(r: Mapping[str, Any]) -> tuple[int, int]:
        """Gates moved, then grid steps moved in all: the nearer to the reference, the better."""
        steps = [abs(values[n].index(r[n]) - values[n].index(reference[n])) for n in names]
        return sum(s > 0 for s in steps), sum(steps)

    safe = [r for r in table if ok(r) and neighbours_ok(r)]
    safe.sort(key=lambda r: (-r["within"], -r["kept"], r["wrong"], moved(r)))
    same = index.get(tuple(reference[n] for n in names))
    gains = bool(safe) and safe[0]["within"] > ref["within"] and safe[0]["within"] >= (1.0 + min_gain) * ref["within"]
    chosen = safe[0] if gains else dict(same or ref)
    return Choice(reference=ref, chosen=chosen, safe=len(safe), cells=len(table), top=safe[:top],
                  classifier_may_loosen=may_loosen, chosen_safe=ok(chosen),
                  margin_may_loosen=len(rows) >= margin_rows)


def write_candidate(bundle: str | Path, dst: str | Path, choice: Choice) -> Path:
    """A copy of ``bundle`` in the new folder ``dst`` with the chosen gates (nothing else changes)."""
    bundle, dst = Path(bundle), Path(dst)
    if dst.exists():
        raise BundleError(f"{dst} exists; the candidate is written to a new folder only")
    doc = _bundle_doc(bundle)
    shutil.copytree(bundle, dst)
    for cell, (section, key) in BUNDLE_KEYS.items():
        value = choice.chosen[cell]
        doc[section][key] = int(value) if float(value).is_integer() and isinstance(doc[section][key], int) else value
    (dst / "bundle.json").write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    return dst


def _line(r: Mapping[str, Any]) -> str:
    return ("  ".join(f"{r[c]:g}" for c in GRID) + f"  | kept {r['kept']:>4} within {r['within']:>4} "
            f"wrong {r['wrong']:>3} flips {r['flips']:>2}")


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m spacepose.tools.choose_gates", description=__doc__.split("\n\n")[0])
    p.add_argument("rows", nargs="+", type=Path, help="open rows of the candidate graph (pose_eval.json[.gz])")
    p.add_argument("--bundle", type=Path, required=True, help="the bundle whose gates are the reference")
    p.add_argument("--reference-rows", nargs="+", type=Path, default=None,
                   help="rows of the reference bundle's own open evaluation on the same frames")
    p.add_argument("--classifier-rows", type=int, default=4000,
                   help="rows needed before the classifier's gates may loosen")
    p.add_argument("--margin-rows", type=int, default=4000,
                   help="rows needed before the outline route's margin may loosen (0: always, as in session 37's rules)")
    p.add_argument("--min-gain", type=float, default=0.03,
                   help="relative gain in poses within the bar below which the reference is kept")
    p.add_argument("--out", type=Path, default=None, help="write the choice as JSON here")
    p.add_argument("--write-bundle", type=Path, default=None, help="write the candidate bundle to this new folder")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    try:
        rows = load_rows(args.rows)
        ref_rows = load_rows(args.reference_rows) if args.reference_rows else None
        choice = choose(rows, args.bundle, reference_rows=ref_rows, classifier_rows=args.classifier_rows,
                        margin_rows=args.margin_rows, min_gain=args.min_gain)
        if args.write_bundle is not None:
            write_candidate(args.bundle, args.write_bundle, choice)
    except (BundleError, DatasetError, OSError, json.JSONDecodeError) as exc:
        raise SystemExit(f"error: {exc}") from exc
    print("columns: " + "  ".join(GRID))
    print(f"reference ({'its own rows' if ref_rows is not None else 'these rows'}):\n{_line(choice.reference)}")
    print(f"{choice.cells} cells, {choice.safe} safe; classifier gates may loosen: {choice.classifier_may_loosen}; "
          f"outline margin may loosen: {choice.margin_may_loosen}")
    for r in choice.top:
        print(_line(r))
    print(f"chosen:\n{_line(choice.chosen)}\nmoved: {choice.changed or 'nothing'}")
    if not choice.chosen_safe:
        print("warning: the chosen gates keep a flip or more wrong poses than the reference on these rows")
    if args.out is not None:
        args.out.write_text(json.dumps({"reference": choice.reference, "chosen": choice.chosen, "safe": choice.safe,
                                        "cells": choice.cells, "top": choice.top, "changed": choice.changed,
                                        "classifier_may_loosen": choice.classifier_may_loosen,
                                        "chosen_safe": choice.chosen_safe}, indent=1) + "\n")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
