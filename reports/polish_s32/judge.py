"""Table and verdict of reports/polish_s32/rule.txt (the polish cap in sequences, session 32).

    python reports/polish_s32/judge.py [RUNS]              # rule.txt (round 1)
    python reports/polish_s32/judge.py --round2 [RUNS]     # rule2.txt (round 2)

RUNS (default ``runs/s32``) holds ``sequence eval`` reports, made by the commands that
``python reports/polish_s32/sequences.py fit base nocap trackcap`` and ``... check base nocap trackcap`` print, run
from commit d1b5aa0 (the fit sequences' ``base`` and ``nocap`` runs from 43afab7, which behaves the same without the
new key): ``base_<name>.json`` with the shipped bundle (``silhouette.max_decided_polish_deg`` 3.0),
``nocap_<name>.json`` with a copy of it whose key is 0.0 (no cap: session 30's behaviour), ``trackcap_<name>.json``
with a copy that adds ``silhouette.max_refused_track_polish_deg`` 3.0 (the candidate of rule.txt). When every run is there,
the frames are cut to the columns used here and written to ``rows.json.gz`` beside this script; otherwise that
committed file is read, so the verdict reproduces from the repository alone. The fit sequences (seeds 3011-3034,
session 30's) were explored before the rule was written; the check sequences (seeds 3201-3216) were rendered after
it was committed.

Round 2 (rule2.txt) reads ``base_<name>.json`` and ``trackcap2_<name>.json`` of the ``check2`` sequences (seeds
3231-3246; ``python reports/polish_s32/sequences.py check2 base trackcap2``, run from commit 88cd5d0; ``trackcap2`` is
that commit's default bundle with ``silhouette.max_refused_track_polish_deg`` 3.0) and keeps its rows in
``rows2.json.gz``.

The table's columns are session 30's (``reports/sequence_s30/judge.py``). "What the cap changed" compares the two
runs frame by frame.
"""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "position_s25"))
sys.path.insert(0, str(HERE.parent / "sequence_s30"))
from _rows import compact_rows  # noqa: E402
from judge import HEAD, KEYS, _line, summary  # noqa: E402  (reports/sequence_s30/judge.py)

from spacepose.bundle import load_bundle  # noqa: E402
from spacepose.tools.eval_pose import BAR_R_DEG, BAR_T_M  # noqa: E402

_spec = importlib.util.spec_from_file_location("sequences_s32", HERE / "sequences.py")
s32 = importlib.util.module_from_spec(_spec)   # reports/polish_s32/sequences.py (s30's has the same name)
_spec.loader.exec_module(s32)

MODES = ("base", "nocap", "trackcap")
MODES2 = ("base", "trackcap2")
LABELS = {"base": "cap 3 (shipped)", "nocap": "no cap", "trackcap": "cap + tracked", "trackcap2": "cap + tracked"}
EXTRA = ("decided_by", "confidence", "status", "detail")


def wrong(r: dict) -> bool:
    return r["e_R"] > 20.0 or r["e_t"] > 0.5


def within(r: dict) -> bool:
    return r["e_t"] <= BAR_T_M and r["e_R"] <= BAR_R_DEG


def changes(rows: dict[str, list[dict]], which: str, before: str, after: str
            ) -> dict[str, list[tuple[str, dict, dict]]]:
    """Frames whose outcome differs from mode ``before`` to mode ``after``: ``lost`` (valid in ``before`` only),
    ``gained`` (in ``after`` only), ``moved`` (valid in both, another pose or route); each ``(sequence, before's
    row, after's row)``."""
    out: dict[str, list[tuple[str, dict, dict]]] = {"lost": [], "gained": [], "moved": []}
    for name, *_ in s32.sequences(which):
        for a, b in zip(rows[f"{before}_{name}"], rows[f"{after}_{name}"]):
            if a["valid"] and not b["valid"]:
                out["lost"].append((name, a, b))
            elif b["valid"] and not a["valid"]:
                out["gained"].append((name, a, b))
            elif a["valid"] and (a["e_R"] != b["e_R"] or a["e_t"] != b["e_t"] or a["tracked"] != b["tracked"]):
                out["moved"].append((name, a, b))
    return out


def _route(r: dict) -> str:
    return "tracked" if r["tracked"] else (r["decided_by"] or "-")


def print_changes(rows: dict[str, list[dict]], which: str, before: str, after: str) -> None:
    ch = changes(rows, which, before, after)
    print(f"{which}: what changed, frame by frame ({LABELS[before]} -> {LABELS[after]}):")
    for kind, items in ch.items():
        n_wrong = sum(wrong(a if kind != "gained" else b) for _, a, b in items)
        n_within = sum(within(a if kind != "gained" else b) for _, a, b in items)
        print(f"  {kind:<7}{len(items):>4} poses, of them wrong {n_wrong}, within the bar {n_within}")
        for name, a, b in items:
            src = a if kind != "gained" else b
            after = (f" -> {_route(b)} {b['e_R']:.1f} deg {b['e_t']:.2f} m" if kind == "moved" else "")
            print(f"    {name} {src['frame']} {_route(src)} {src['e_R']:.1f} deg {src['e_t']:.2f} m{after}"
                  + (f"  ({b['detail'][:90]})" if kind == "lost" else ""))


def round2(runs: Path) -> int:
    """rule2.txt: the candidate against the shipped bundle on the 16 ``check2`` sequences."""
    names = [name for name, *_ in s32.sequences("check2")]
    files = {f"{m}_{n}": [runs / f"{m}_{n}.json"] for n in names for m in MODES2}
    rows = compact_rows(files, HERE / "rows2.json.gz", KEYS + EXTRA, defaults={"roi": None})
    bundle = load_bundle(None, verify_graphs=False)
    res = {}
    print(HEAD)
    for mode in MODES2:
        res[mode] = summary([r for n in names for r in rows[f"{mode}_{n}"]], bundle)
        print(_line("check2", LABELS[mode], res[mode]))
    print()
    print_changes(rows, "check2", "base", "trackcap2")
    old, new = res["base"], res["trackcap2"]
    lost_within = sum(within(a) for _, a, _ in changes(rows, "check2", "base", "trackcap2")["lost"])
    fails = [f"C1. > 90 deg {new['flips']} > 0"] if new["flips"] > 0 else []
    fails += [f"C2. wrong {new['wrong']} > {old['wrong']}"] if new["wrong"] > old["wrong"] else []
    fails += [f"C3. within {new['within']} < {old['within']} - 2"] if new["within"] < old["within"] - 2 else []
    fails += [f"C4. valid {new['valid']} < 0.94 x {old['valid']}"] if new["valid"] < 0.94 * old["valid"] else []
    fails += ([f"C5. mean e_R {new['e_R_mean']:.4f} > {old['e_R_mean']:.4f} + 0.05"]
              if new["e_R_mean"] > old["e_R_mean"] + 0.05 else [])
    fails += [f"C6. {lost_within} dropped poses within the bar > 1"] if lost_within > 1 else []
    print()
    print(f"mean e_R: shipped {old['e_R_mean']:.4f}, candidate {new['e_R_mean']:.4f} deg")
    print("verdict (rule2.txt, the 16 check2 sequences, candidate max_refused_track_polish_deg 3.0): "
          + ("MET" if not fails else "NOT MET: " + "; ".join(fails)))
    return 0


def main(argv: list[str]) -> int:
    if argv[:1] == ["--round2"]:
        return round2(Path(argv[1]) if len(argv) > 1 else Path("runs/s32"))
    runs = Path(argv[0]) if argv else Path("runs/s32")
    sets = ("fit", "check")
    files = {f"{m}_{n}": [runs / f"{m}_{n}.json"] for w in sets for n, *_ in s32.sequences(w) for m in MODES}
    rows = compact_rows(files, HERE / "rows.json.gz", KEYS + EXTRA, defaults={"roi": None})
    bundle = load_bundle(None, verify_graphs=False)
    results = {}
    print(HEAD)
    for which in sets:
        for mode in MODES:
            frames = [r for name, *_ in s32.sequences(which) for r in rows[f"{mode}_{name}"]]
            results[which, mode] = summary(frames, bundle)
            print(_line(which, LABELS[mode], results[which, mode]))
    print("(wrong: e_R > 20 deg or e_t > 0.5 m; within: e_t <= 0.10 m and e_R <= 2 deg; the other columns as in "
          "reports/sequence_s30/judge.py)")
    for which in sets:
        for before, after in (("nocap", "base"), ("base", "trackcap")):
            print()
            print_changes(rows, which, before, after)
    print()
    print(verdict(results["check", "nocap"], results["check", "base"], results["check", "trackcap"]))
    return 0


def verdict(nocap: dict, shipped: dict, cand: dict) -> str:
    """rule.txt's clauses on the 16 check sequences: part A (the shipped cap against none) and part B (the
    candidate, ``max_refused_track_polish_deg`` 3.0, against the shipped bundle)."""
    a = [f"A1. > 90 deg {shipped['flips']} > 0"] if shipped["flips"] > 0 else []
    a += [f"A2. wrong {shipped['wrong']} > {nocap['wrong']}"] if shipped["wrong"] > nocap["wrong"] else []
    a += [f"A3. valid {shipped['valid']} < 0.95 x {nocap['valid']}"] if shipped["valid"] < 0.95 * nocap["valid"] else []
    a += [f"A4. within {shipped['within']} < {nocap['within']} - 3"] if shipped["within"] < nocap["within"] - 3 else []
    b = [f"B1. > 90 deg {cand['flips']} > 0"] if cand["flips"] > 0 else []
    b += [f"B2. wrong {cand['wrong']} > {shipped['wrong']}"] if cand["wrong"] > shipped["wrong"] else []
    b += [f"B3. within {cand['within']} < {shipped['within']} - 2"] if cand["within"] < shipped["within"] - 2 else []
    b += [f"B4. valid {cand['valid']} < 0.94 x {shipped['valid']}"] if cand["valid"] < 0.94 * shipped["valid"] else []
    b += ([f"B5. mean e_R {cand['e_R_mean']:.3f} > {shipped['e_R_mean']:.3f}"]
          if cand["e_R_mean"] > shipped["e_R_mean"] else [])
    return ("verdict (rule.txt, the 16 check sequences):\n  A, the shipped cap against none: "
            + ("MET" if not a else "NOT MET: " + "; ".join(a))
            + "\n  B, the candidate (max_refused_track_polish_deg 3.0) against the shipped bundle: "
            + ("MET" if not b else "NOT MET: " + "; ".join(b)))


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
