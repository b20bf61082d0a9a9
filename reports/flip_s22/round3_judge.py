"""Counts and verdict of reports/flip_s22/ship_rule_round3.txt (candidate C against the shipped bundle S).

    python reports/flip_s22/round3_judge.py RUNS OLD_S

RUNS: round 2's run folder (``seq/NAME_{S,C}.json`` from ``sequence eval``; ``val8{a,b}_{S,Cp}`` and
``v1280c_{S,Cp}`` from ``eval-pose``: on independent frames C = C'). OLD_S: ``reports/flip_s21/sequences.tar.gz``
unpacked (``old/NAME_default.json``, ``fresh/dN_default.json``: S on the 29 older sequences), and
``reports/flip_s22/sequences_e_round1.tar.gz`` unpacked beside them (``fresh_e/eN_default.json``: round 1's S runs).
"""
import json
import sys
from pathlib import Path

MAX_E_T, MAX_E_R, FLIP_DEG = 0.5, 20.0, 90.0
runs, old = Path(sys.argv[1]), Path(sys.argv[2])
seq = runs / "seq"
OLD = ["sun14", "penumbra20", "albedo12", "sun18", "mixed12", "sun16b", "albedo24b", "mixed30b", "penumbra15b"]
OLD += [f"c{i}" for i in range(1, 11)] + [f"d{i}" for i in range(1, 11)]
E, F, G = ([f"{p}{i}" for i in range(1, n + 1)] for p, n in (("e", 10), ("f", 20), ("g", 20)))


def rows(path):
    return json.loads(Path(path).read_text())["frames"]


def wrong(r):
    return r["e_R"] > MAX_E_R or r["e_t"] > MAX_E_T


def s_path(name):
    if name in OLD:
        return old / ("fresh" if name.startswith("d") else "old") / f"{name}_default.json"
    return seq / f"{name}_S.json"


def compare(names):
    """Pooled counts of S and C over the sequences ``names`` and the rule's (a), (b), (c)."""
    c = {k: dict(valid=0, wrong=0, right=0, far=0, tracked=0) for k in ("S", "C")}
    new_far = 0
    for name in names:
        s_rows, c_rows = rows(s_path(name)), rows(seq / f"{name}_C.json")
        s_far = {r["frame"] for r in s_rows if r["valid"] and r["e_R"] > FLIP_DEG}
        for key, frames in (("S", s_rows), ("C", c_rows)):
            for r in frames:
                if not r["valid"]:
                    continue
                c[key]["valid"] += 1
                c[key]["wrong"] += wrong(r)
                c[key]["right"] += not wrong(r)
                c[key]["far"] += r["e_R"] > FLIP_DEG
                c[key]["tracked"] += bool(r.get("tracked"))
        new_far += sum(1 for r in c_rows if r["valid"] and r["e_R"] > FLIP_DEG and r["frame"] not in s_far)
    ok = new_far == 0 and c["C"]["wrong"] <= c["S"]["wrong"] and c["C"]["right"] >= 0.9 * c["S"]["right"]
    for key in ("S", "C"):
        x = c[key]
        print(f"    {key}: {x['valid']} valid ({x['tracked']} tracked), {x['right']} right, {x['wrong']} wrong, "
              f"{x['far']} > 90 deg")
    print(f"    (a) new > 90 deg: {new_far}; (b) wrong {c['C']['wrong']} <= {c['S']['wrong']}; "
          f"(c) right {c['C']['right']} >= 0.9 x {c['S']['right']} = {0.9 * c['S']['right']:.1f}: "
          f"{'met' if ok else 'NOT met'}")
    return ok


def single(parts):
    out = {}
    for key, tag in (("S", "S"), ("C", "Cp")):
        frames = [r for p in parts for r in rows(runs / f"{p}_{tag}" / "pose_eval.json")]
        valid = [r for r in frames if r["valid"]]
        out[key] = dict(n=len(frames), valid=len(valid), wrong=sum(map(wrong, valid)),
                        far=sum(r["e_R"] > FLIP_DEG for r in valid))
    ok = out["C"]["far"] == 0 and out["C"]["wrong"] <= out["S"]["wrong"] and out["C"]["valid"] >= out["S"]["valid"]
    print(f"    S {out['S']} | C {out['C']}: {'met' if ok else 'NOT met'}")
    return ok


same = all([(r["valid"], r.get("e_R"), r.get("e_t")) for r in rows(seq / f"{n}_S.json")]
           == [(r["valid"], r.get("e_R"), r.get("e_t")) for r in rows(old / "fresh_e" / f"{n}_default.json")]
           for n in E)
print(f"S re-run on e1..e10 with this session's code reproduces round 1's runs frame for frame: {same}")
verdict = True
for name, parts in (("tdrs640_val8 (train split)", ("val8a", "val8b")), ("tdrs1280_val3 (train split)", ("v1280c",))):
    print(name)
    verdict &= single(parts)
print("g1..g20 pooled (fresh, 800 frames)")
verdict &= compare(G)
print("regression: the 59 spent sequences pooled (f1..f20, e1..e10, 29 older; 2,360 frames)")
verdict &= compare(F + E + OLD)
for label, names in (("  of which f1..f20", F), ("  of which e1..e10", E), ("  of which the 29 older", OLD)):
    print(label)
    compare(names)
print("round 3:", "met: ship C" if verdict else "NOT met: nothing ships")
