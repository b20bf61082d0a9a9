"""Tables and verdict of reports/gates_s35/rule.txt (the gates re-derived on the shipped stereo graph against the
shipped gates).

    python reports/gates_s35/judge.py [RUNS]            # round 1: rule.txt
    python reports/gates_s35/judge.py --round2 [RUNS]   # round 2: rule2.txt (its own sets, cand2 against base)

RUNS (default ``runs/s35``) holds the reports of the commands in rule.txt: ``eval-pose`` folders
``<set>_<mode>/pose_eval.json`` and ``sequence eval`` reports ``<mode>_<name>.json``; ``mode`` is ``base`` (the
shipped bundle) or ``cand`` (rule.txt's candidate). When every run is there, its frames are cut to the columns used
here and written beside this script (``rows.json.gz``; round 2: ``rows2.json.gz``, sets ``c*``, ``d`` and the
``check2`` sequences, mode ``cand2`` for the candidate); otherwise that file is read, so the tables and the verdict
reproduce from the repository alone. Counts and tables: session 33's and 34's judges
(reports/stereo_s33/judge.py, reports/floor_s34/judge.py).
"""
from __future__ import annotations

import gzip
import importlib.util
import json
import sys
from collections import Counter
from pathlib import Path

HERE = Path(__file__).resolve().parent
_SPEC = importlib.util.spec_from_file_location("judge_s34", HERE.parent / "floor_s34" / "judge.py")
s34 = importlib.util.module_from_spec(_SPEC)                          # pose_rows, line, HEAD, print_wrong, _load
_SPEC.loader.exec_module(s34)
s33, pos32 = s34.s33, s34.pos32                                       # counts; position_table, print_table
seqs = s34._load("sequences_s35", HERE / "sequences.py")
explore = s34._load("explore_s35", HERE / "explore.py")             # write_compact

LABELS = {"base": "shipped", "cand": "candidate", "cand2": "candidate 2"}
#: per round: the sets (name: folder stems, what), the sequences, the candidate's mode, the rows file, the rule, the
#: clauses' letter and the least within / valid ratios
ROUNDS = {
    1: {"sets": {"a": (["a0", "a1", "a2"], "tdrs640_s35a (seed 3501), train frames 0-900"),
                 "b": (["b"], "tdrs1280_s35b (seed 3502), its 54 train frames")},
        "names": [n for n, *_ in seqs.sequences("check")], "seq_set": "check", "cand": "cand",
        "rows": "rows.json.gz", "rule": "rule.txt", "letter": "G", "within": 1.03, "valid": 1.05},
    2: {"sets": {"a2": (["c0", "c1", "c2"], "tdrs640_s35c (seed 3541), train frames 0-900"),
                 "b2": (["d"], "tdrs1280_s35d (seed 3542), its 54 train frames")},
        "names": [n for n, *_ in seqs.sequences("check2")], "seq_set": "check2", "cand": "cand2",
        "rows": "rows2.json.gz", "rule": "rule2.txt", "letter": "H", "within": 1.05, "valid": 1.08}}


def rows_of(runs: Path, rnd: dict) -> dict[str, list[dict]]:
    modes = ("base", rnd["cand"])
    files = {f"{name}_{m}": [runs / f"{stem}_{m}" / "pose_eval.json" for stem in stems]
             for name, (stems, _) in rnd["sets"].items() for m in modes}
    files.update({f"seq_{m}_{n}": [runs / f"{m}_{n}.json"] for n in rnd["names"] for m in modes})
    path = HERE / rnd["rows"]
    rows = s34.pose_rows(runs, path, files)         # cut from the runs and written when they are all there
    if all(f.is_file() for fs in files.values() for f in fs):
        explore.write_compact(path, rows)
    with gzip.open(path, "rt") as fh:                # the tables always come from the committed (compact) rows
        return json.load(fh)


def group(rows: dict[str, list[dict]], rnd: dict, name: str, mode: str) -> list[dict]:
    seq = [r for n in rnd["names"] for r in rows[f"seq_{mode}_{n}"]]
    pooled = [r for s in rnd["sets"] for r in rows[f"{s}_{mode}"]] + seq
    return {"seq": seq, "pooled": pooled}.get(name) or rows[f"{name}_{mode}"]


def main(argv: list[str]) -> int:
    rnd = ROUNDS[2 if "--round2" in argv else 1]
    argv = [a for a in argv if a != "--round2"]
    rows = rows_of(Path(argv[0]) if argv else Path("runs/s35"), rnd)
    sets, names, modes = rnd["sets"], rnd["names"], ("base", rnd["cand"])
    independent = lambda m: [r for s in sets for r in rows[f"{s}_{m}"]]   # noqa: E731
    c: dict[str, dict[str, dict]] = {}
    print(s34.HEAD)
    for name in list(sets) + ["seq", "pooled"]:
        for m in modes:
            c.setdefault(name, {})[m] = s33.counts(group(rows, rnd, name, m))
            print(s34.line(name, LABELS[m], c[name][m]))
    for name, (_, what) in sets.items():
        print(f"  {name}: {what}")
    print(f"  seq: {len(names)} sequences of 40 frames ({names[0]} ... {names[-1]}; reports/gates_s35/sequences.py "
          f"{rnd['seq_set']})")
    print("(wrong: e_R > 20 deg or e_t > 0.5 m; >20: e_R > 20 deg; >90: e_R > 90 deg; within: e_t <= 0.10 m and "
          "e_R <= 2 deg; positions: frames with a valid position)")
    print()
    print("wrong valid poses (set, frame, e_R, e_t, route, chamfer, confidence):")
    for m in modes:
        s34.print_wrong(LABELS[m], 12, [(name, r) for name in sets for r in rows[f"{name}_{m}"]]
                        + [(n, r) for n in names for r in rows[f"seq_{m}_{n}"]])
    print()
    print("valid poses by route, independent frames / sequences:")
    for m in modes:
        ind = Counter(r.get("decided_by") for r in independent(m) if r["valid"])
        seq = Counter(r.get("decided_by") or ("tracked" if r.get("tracked") else None)
                      for r in group(rows, rnd, "seq", m) if r["valid"])
        print(f"  {LABELS[m]:<12} {dict(sorted(ind.items(), key=str))} / {dict(sorted(seq.items(), key=str))}")
    print()
    print("per regime, independent frames (valid / wrong / within):")
    for regime in ("sun", "albedo", "penumbra", "mixed"):
        cells = []
        for m in modes:
            k = s33.counts([r for r in independent(m) if r["regime"] == regime])
            cells.append(f"{LABELS[m]} {k['valid']:>4} / {k['wrong']} / {k['within']:>3}")
        print(f"  {regime:<9}" + "    ".join(cells))
    print()
    print("position-only frames (independent frames; session 32's columns):")
    tables = {}
    for m in modes:
        tables[m] = pos32.position_table(independent(m))
        pos32.print_table(f"{'+'.join(sets)} {LABELS[m]}", tables[m])
    print()
    print(verdict(rnd, {name: {"base": per["base"], "cand": per[rnd["cand"]]} for name, per in c.items()},
                  tables["base"]["all"], tables[rnd["cand"]]["all"]))
    return 0


def verdict(rnd: dict, c: dict[str, dict[str, dict]], pos_base: dict, pos_cand: dict) -> str:
    """The round's clauses (rule.txt: G1-G6, rule2.txt: H1-H6; ``c``'s candidate under ``cand``)."""
    x, base, cand = rnd["letter"], c["pooled"]["base"], c["pooled"]["cand"]
    flips = {name: per["cand"]["flips"] for name, per in c.items() if name != "pooled" and per["cand"]["flips"]}
    fails = [f"{x}1. valid poses > 90 deg off: {flips}"] if flips else []
    fails += [f"{x}2. wrong {cand['wrong']} > {base['wrong']} + 2"] if cand["wrong"] > base["wrong"] + 2 else []
    share_b, share_c = (100.0 * k["wrong"] / max(k["valid"], 1) for k in (base, cand))
    fails += [f"{x}2. wrong share {share_c:.2f} % > {share_b:.2f} % + 0.5"] if share_c > share_b + 0.5 else []
    fails += ([f"{x}3. > 20 deg {cand['rotated']} > {base['rotated']} + 1"]
              if cand["rotated"] > base["rotated"] + 1 else [])
    fails += ([f"{x}4. within {cand['within']} < {rnd['within']:.2f} x {base['within']}"]
              if cand["within"] < rnd["within"] * base["within"] else [])
    fails += ([f"{x}5. valid {cand['valid']} < {rnd['valid']:.2f} x {base['valid']}"]
              if cand["valid"] < rnd["valid"] * base["valid"] else [])
    fails += ([f"{x}6. position-only e_pos {pos_cand['e_pos']:.3f} > {pos_base['e_pos']:.3f} + 0.02"]
              if pos_cand["e_pos"] > pos_base["e_pos"] + 0.02 else [])
    fails += ([f"{x}6. position-only within tau {pos_cand['within_tau']:.3f} < {pos_base['within_tau']:.3f} - 0.03"]
              if pos_cand["within_tau"] < pos_base["within_tau"] - 0.03 else [])
    return (f"wrong share: shipped {share_b:.2f} %, candidate {share_c:.2f} %\n"
            f"verdict ({rnd['rule']}): " + ("MET" if not fails else "NOT MET: " + "; ".join(fails)))


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
