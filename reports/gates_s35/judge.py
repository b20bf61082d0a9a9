"""Tables and verdict of reports/gates_s35/rule.txt (the gates re-derived on the shipped stereo graph against the
shipped gates).

    python reports/gates_s35/judge.py [RUNS]

RUNS (default ``runs/s35``) holds the reports of the commands in rule.txt: ``eval-pose`` folders
``<set>_<mode>/pose_eval.json`` and ``sequence eval`` reports ``<mode>_<name>.json``; ``mode`` is ``base`` (the
shipped bundle) or ``cand`` (rule.txt's candidate). When every run is there, its frames are cut to the columns used
here and written beside this script (``rows.json.gz``); otherwise that file is read, so the tables and the verdict
reproduce from the repository alone. Counts and tables: session 33's and 34's judges
(reports/stereo_s33/judge.py, reports/floor_s34/judge.py).
"""
from __future__ import annotations

import importlib.util
import sys
from collections import Counter
from pathlib import Path

HERE = Path(__file__).resolve().parent
_SPEC = importlib.util.spec_from_file_location("judge_s34", HERE.parent / "floor_s34" / "judge.py")
s34 = importlib.util.module_from_spec(_SPEC)                          # pose_rows, line, HEAD, print_wrong, _load
_SPEC.loader.exec_module(s34)
s33, pos32 = s34.s33, s34.pos32                                       # counts; position_table, print_table
seqs = s34._load("sequences_s35", HERE / "sequences.py")

MODES = ("base", "cand")
LABELS = {"base": "shipped", "cand": "candidate"}
SETS = {"a": (["a0", "a1", "a2"], "tdrs640_s35a (seed 3501), train frames 0-900"),
        "b": (["b"], "tdrs1280_s35b (seed 3502), its 54 train frames")}
NAMES = [n for n, *_ in seqs.sequences("check")]


def rows_of(runs: Path) -> dict[str, list[dict]]:
    files = {f"{name}_{m}": [runs / f"{stem}_{m}" / "pose_eval.json" for stem in stems]
             for name, (stems, _) in SETS.items() for m in MODES}
    files.update({f"seq_{m}_{n}": [runs / f"{m}_{n}.json"] for n in NAMES for m in MODES})
    return s34.pose_rows(runs, HERE / "rows.json.gz", files)


def group(rows: dict[str, list[dict]], name: str, mode: str) -> list[dict]:
    seq = [r for n in NAMES for r in rows[f"seq_{mode}_{n}"]]
    return {"seq": seq, "pooled": [r for s in SETS for r in rows[f"{s}_{mode}"]] + seq}.get(name) or rows[f"{name}_{mode}"]


def main(argv: list[str]) -> int:
    rows = rows_of(Path(argv[0]) if argv else Path("runs/s35"))
    c: dict[str, dict[str, dict]] = {}
    print(s34.HEAD)
    for name in list(SETS) + ["seq", "pooled"]:
        for m in MODES:
            c.setdefault(name, {})[m] = s33.counts(group(rows, name, m))
            print(s34.line(name, LABELS[m], c[name][m]))
    for name, (_, what) in SETS.items():
        print(f"  {name}: {what}")
    print(f"  seq: {len(NAMES)} sequences of 40 frames ({NAMES[0]} ... {NAMES[-1]}; reports/gates_s35/sequences.py)")
    print("(wrong: e_R > 20 deg or e_t > 0.5 m; >20: e_R > 20 deg; >90: e_R > 90 deg; within: e_t <= 0.10 m and "
          "e_R <= 2 deg; positions: frames with a valid position)")
    print()
    print("wrong valid poses (set, frame, e_R, e_t, route, chamfer, confidence):")
    for m in MODES:
        s34.print_wrong(LABELS[m], 10, [(name, r) for name in SETS for r in rows[f"{name}_{m}"]]
                        + [(n, r) for n in NAMES for r in rows[f"seq_{m}_{n}"]])
    print()
    print("valid poses by route, independent frames (a, b) / sequences:")
    for m in MODES:
        ind = Counter(r.get("decided_by") for s in SETS for r in rows[f"{s}_{m}"] if r["valid"])
        seq = Counter(r.get("decided_by") or ("tracked" if r.get("tracked") else None)
                      for r in group(rows, "seq", m) if r["valid"])
        print(f"  {LABELS[m]:<10} {dict(sorted(ind.items(), key=str))} / {dict(sorted(seq.items(), key=str))}")
    print()
    print("per regime, independent frames (valid / wrong / within):")
    for regime in ("sun", "albedo", "penumbra", "mixed"):
        cells = []
        for m in MODES:
            k = s33.counts([r for s in SETS for r in rows[f"{s}_{m}"] if r["regime"] == regime])
            cells.append(f"{LABELS[m]} {k['valid']:>4} / {k['wrong']} / {k['within']:>3}")
        print(f"  {regime:<9}" + "    ".join(cells))
    print()
    print("position-only frames (independent frames; session 32's columns):")
    tables = {}
    for m in MODES:
        tables[m] = pos32.position_table(rows["a_" + m] + rows["b_" + m])
        pos32.print_table(f"a+b {LABELS[m]}", tables[m])
    print()
    print(verdict(c, tables["base"]["all"], tables["cand"]["all"]))
    return 0


def verdict(c: dict[str, dict[str, dict]], pos_base: dict, pos_cand: dict) -> str:
    """rule.txt's clauses G1-G6."""
    base, cand = c["pooled"]["base"], c["pooled"]["cand"]
    flips = {name: per["cand"]["flips"] for name, per in c.items() if name != "pooled" and per["cand"]["flips"]}
    fails = [f"G1. valid poses > 90 deg off: {flips}"] if flips else []
    fails += [f"G2. wrong {cand['wrong']} > {base['wrong']} + 2"] if cand["wrong"] > base["wrong"] + 2 else []
    share_b, share_c = (100.0 * k["wrong"] / max(k["valid"], 1) for k in (base, cand))
    fails += [f"G2. wrong share {share_c:.2f} % > {share_b:.2f} % + 0.5"] if share_c > share_b + 0.5 else []
    fails += [f"G3. > 20 deg {cand['rotated']} > {base['rotated']} + 1"] if cand["rotated"] > base["rotated"] + 1 else []
    fails += ([f"G4. within {cand['within']} < 1.03 x {base['within']}"]
              if cand["within"] < 1.03 * base["within"] else [])
    fails += [f"G5. valid {cand['valid']} < 1.05 x {base['valid']}"] if cand["valid"] < 1.05 * base["valid"] else []
    fails += ([f"G6. position-only e_pos {pos_cand['e_pos']:.3f} > {pos_base['e_pos']:.3f} + 0.02"]
              if pos_cand["e_pos"] > pos_base["e_pos"] + 0.02 else [])
    fails += ([f"G6. position-only within tau {pos_cand['within_tau']:.3f} < {pos_base['within_tau']:.3f} - 0.03"]
              if pos_cand["within_tau"] < pos_base["within_tau"] - 0.03 else [])
    return (f"wrong share: shipped {share_b:.2f} %, candidate {share_c:.2f} %\n"
            "verdict (rule.txt): " + ("MET" if not fails else "NOT MET: " + "; ".join(fails)))


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
