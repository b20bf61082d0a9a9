"""Counts and verdict of reports/flip_s22/ship_rule_round4.txt (candidate C against the shipped bundle S).

    python reports/flip_s22/round4_judge.py RUNS OLD_S [X]

From a fresh clone: ``mkdir -p /tmp/r4/r2 /tmp/old && tar xzf reports/flip_s22/sequences_rounds2to4.tar.gz -C /tmp/r4/r2
&& tar xzf reports/flip_s21/sequences.tar.gz -C /tmp/old && tar xzf reports/flip_s22/sequences_e_round1.tar.gz -C
/tmp/old && python reports/flip_s22/round4_judge.py /tmp/r4/r2 /tmp/old``: the single-frame reports missing under
RUNS are read from their gzipped copies beside this script.

RUNS: the run folder of rounds 2-4 (``seq/NAME_{S,C}.json`` from ``sequence eval``; ``{val8a,val8b,v1280c,val9a,
val9b,v1280d}_{S,Cp}/pose_eval.json`` from ``eval-pose``: on independent frames C = C'). ROUND1: round 1's runs
(``val7_{default,cand}.json``, ``v1280b_{default,cand}/pose_eval.json``) are read from RUNS/.. . OLD_S: as in
round3_judge.py (S on the 29 older sequences and round 1's S on e1..e10). X: the depth gate (0.70).
"""
import gzip
import json
import sys
from pathlib import Path

MAX_E_T, MAX_E_R, FLIP_DEG = 0.5, 20.0, 90.0
runs, old = Path(sys.argv[1]), Path(sys.argv[2])
X = float(sys.argv[3]) if len(sys.argv) > 3 else 0.70
seq = runs / "seq"
OLD = ["sun14", "penumbra20", "albedo12", "sun18", "mixed12", "sun16b", "albedo24b", "mixed30b", "penumbra15b"]
OLD += [f"c{i}" for i in range(1, 11)] + [f"d{i}" for i in range(1, 11)]
E, F, G = ([f"{p}{i}" for i in range(1, n + 1)] for p, n in (("e", 10), ("f", 20), ("g", 20)))


REPORTS = Path(__file__).resolve().parent


def rows(path):
    path = Path(path)
    if not path.exists():   # a fresh clone: the committed copy (reports/flip_s22/NAME.json.gz)
        name = path.parent.name if path.name == "pose_eval.json" else path.stem
        path = REPORTS / f"{name}.json.gz"
    path = str(path)
    with (gzip.open(path, "rt") if path.endswith(".gz") else open(path)) as fh:
        return json.load(fh)["frames"]


def wrong(r):
    return r["e_R"] > MAX_E_R or r["e_t"] > MAX_E_T


def tally(frames):
    valid = [r for r in frames if r["valid"]]
    return dict(n=len(frames), valid=len(valid), wrong=sum(map(wrong, valid)), right=sum(not wrong(r) for r in valid),
                far=sum(r["e_R"] > FLIP_DEG for r in valid), tracked=sum(bool(r.get("tracked")) for r in valid))


def new_far(s_frames, c_frames):
    s_far = {r["frame"] for r in s_frames if r["valid"] and r["e_R"] > FLIP_DEG}
    return sum(1 for r in c_frames if r["valid"] and r["e_R"] > FLIP_DEG and r["frame"] not in s_far)


def judge_single(name, s_frames, c_frames):
    s, c, nf = tally(s_frames), tally(c_frames), new_far(s_frames, c_frames)
    ok = nf == 0 and c["wrong"] <= s["wrong"] and c["valid"] >= s["valid"]
    print(f"  {name:28s} S {s['valid']:3d} / {s['wrong']:2d} / {s['far']}   C {c['valid']:3d} / {c['wrong']:2d} / {c['far']}"
          f"   new > 90 deg {nf}: {'met' if ok else 'NOT met'}")
    return ok


def s_path(name):
    if name in OLD:
        return old / ("fresh" if name.startswith("d") else "old") / f"{name}_default.json"
    return seq / f"{name}_S.json"


def judge_sequences(label, names):
    s_all, c_all, nf = [], [], 0
    for name in names:
        s_frames, c_frames = rows(s_path(name)), rows(seq / f"{name}_C.json")
        nf += new_far(s_frames, c_frames)
        s_all += s_frames
        c_all += c_frames
    s, c = tally(s_all), tally(c_all)
    ok = nf == 0 and c["wrong"] <= s["wrong"] and c["right"] >= 0.9 * s["right"]
    print(f"  {label:28s} S {s['valid']:4d} ({s['tracked']} tracked) / {s['wrong']:2d} / {s['far']}   "
          f"C {c['valid']:4d} ({c['tracked']} tracked) / {c['wrong']:2d} / {c['far']}   right {c['right']} vs "
          f"0.9 x {s['right']}, new > 90 deg {nf}: {'met' if ok else 'NOT met'}")
    return ok


def pair(parts, tag):
    return [r for p in parts for r in rows(runs / f"{p}_{tag}" / "pose_eval.json")]


print("valid / wrong (> 20 deg or > 0.5 m) / > 90 deg")
verdict = True
print("fresh, single frames")
verdict &= judge_single("tdrs640_val9 (450)", pair(("val9a", "val9b"), "S"), pair(("val9a", "val9b"), "Cp"))
verdict &= judge_single("tdrs1280_val4 (90)", pair(("v1280d",), "S"), pair(("v1280d",), "Cp"))
print("fresh, sequences")
verdict &= judge_sequences("g1..g20 (800 frames)", G)
print("regression, single frames")
for name in ("val6", "v1280", "test", "unseen", "restyle", "val3_400", "val4_400"):
    s_frames = rows(f"reports/flip_s21/{name}_default.json.gz")
    c_frames = [dict(r, valid=False) if r["valid"] and r["decided_by"] == "classifier"
                and not r["depth_tolerance_m"] <= X else r for r in rows(f"reports/flip_s21/{name}_cand.json.gz")]
    verdict &= judge_single(f"{name} (s21, gated post hoc)", s_frames, c_frames)
r1 = runs.parent
verdict &= judge_single("tdrs640_val7 (round 1)", rows(r1 / "val7_default.json"), rows(r1 / "val7_cand.json"))
verdict &= judge_single("tdrs1280_val2 (round 1)", rows(r1 / "v1280b_default" / "pose_eval.json"),
                        rows(r1 / "v1280b_cand" / "pose_eval.json"))
verdict &= judge_single("tdrs640_val8 (round 2)", pair(("val8a", "val8b"), "S"), pair(("val8a", "val8b"), "Cp"))
verdict &= judge_single("tdrs1280_val3 (round 2)", pair(("v1280c",), "S"), pair(("v1280c",), "Cp"))
print("regression, sequences")
verdict &= judge_sequences("59 spent, pooled", F + E + OLD)
for label, names in (("  f1..f20", F), ("  e1..e10", E), ("  the 29 older", OLD)):
    judge_sequences(label, names)
same = all([(r["valid"], r.get("e_R"), r.get("e_t")) for r in rows(seq / f"{n}_S.json")]
           == [(r["valid"], r.get("e_R"), r.get("e_t")) for r in rows(old / "fresh_e" / f"{n}_default.json")]
           for n in E)
print(f"S re-run on e1..e10 with this session's code = round 1's runs, frame for frame: {same}")
print("round 4:", "met: ship C" if verdict else "NOT met: nothing ships")
