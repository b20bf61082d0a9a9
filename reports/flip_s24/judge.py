"""Counts and verdict of reports/flip_s24/plan.txt (candidate C against the shipped bundle S, gate G in both).

    python reports/flip_s24/judge.py RUNS [--pack]

RUNS holds ``eval-pose`` outputs ``{a1,a2,b}_{S,C}/pose_eval.json`` (a1, a2: train frames 0-449 and 450-899 of
data/tdrs640_s24f; b: the 135 train frames of data/tdrs1280_s24f), ``test_C/pose_eval.json`` (the test split of
data/tdrs640 with C; S's rows are session 23's, reports/flip_s23/test640_s23.json.gz, the same bundle) and
``seq_kK_{S,C}.json`` (``sequence eval`` of data/seq_kK, K = 1..10). A missing file is read from ``NAME.json.gz``
beside this script; ``--pack`` writes those compact copies from RUNS.
"""
import gzip
import json
import sys
from pathlib import Path

MAX_E_T, MAX_E_R, FAR_DEG = 0.5, 20.0, 90.0
HERE = Path(__file__).resolve().parent
KEEP = ("frame", "regime", "distance", "valid", "status", "tracked", "e_t", "e_R", "decided_by", "flip_prob",
        "outline_chamfer_px", "depth_tolerance_m")
NAMES = [f"{p}_{t}" for p in ("a1", "a2", "b") for t in ("S", "C")] + ["test_C"]
NAMES += [f"seq_k{k}_{t}" for k in range(1, 11) for t in ("S", "C")]


def source(runs: Path, name: str) -> Path:
    return runs / name / "pose_eval.json" if not name.startswith("seq_") else runs / f"{name}.json"


def rows(runs: Path, name: str) -> list:
    path = source(runs, name)
    if not path.exists():
        path = HERE / f"{name}.json.gz"
    with (gzip.open(path, "rt") if path.suffix == ".gz" else open(path)) as fh:
        return json.load(fh)["frames"]


def pack(runs: Path) -> None:
    for name in NAMES:
        frames = [{k: r[k] for k in KEEP if k in r} for r in rows(runs, name)]
        with gzip.open(HERE / f"{name}.json.gz", "wt") as fh:
            json.dump({"frames": frames}, fh)


def wrong(r: dict) -> bool:
    return r["e_R"] > MAX_E_R or r["e_t"] > MAX_E_T


def tally(frames: list) -> dict:
    valid = [r for r in frames if r["valid"]]
    return dict(n=len(frames), valid=len(valid), wrong=sum(map(wrong, valid)),
                far=sum(r["e_R"] > FAR_DEG for r in valid))


def far_keys(frames: list, tag: str) -> set:
    return {(tag, r["frame"]) for r in frames if r["valid"] and r["e_R"] > FAR_DEG}


def main() -> None:
    runs = Path(sys.argv[1])
    if "--pack" in sys.argv[2:]:
        pack(runs)
    groups = {"A: tdrs640_s24f, 900 train frames": ["a1", "a2"], "B: tdrs1280_s24f, 135 train frames": ["b"],
              "C: sequences k1..k10, 400 frames": [f"seq_k{k}" for k in range(1, 11)]}
    print("valid / wrong (e_R > 20 deg or e_t > 0.5 m) / > 90 deg")
    pooled = {"S": dict(valid=0, wrong=0), "C": dict(valid=0, wrong=0)}
    clause2 = True
    for label, parts in groups.items():
        got, loaded = {}, {}
        for tag in ("S", "C"):
            frames, far = [], set()
            for p in parts:
                fr = loaded[p, tag] = rows(runs, f"{p}_{tag}")
                frames += fr
                far |= far_keys(fr, p)
            got[tag] = (tally(frames), far)
            pooled[tag]["valid"] += got[tag][0]["valid"]
            pooled[tag]["wrong"] += got[tag][0]["wrong"]
        (s, s_far), (c, c_far) = got["S"], got["C"]
        new_far = len(c_far - s_far)
        clause2 &= new_far == 0
        print(f"{label:38s} S {s['valid']:4d} / {s['wrong']:2d} / {s['far']}   C {c['valid']:4d} / {c['wrong']:2d} / "
              f"{c['far']}   > 90 deg from C only: {new_far}")
        for part, frame in sorted(c_far - s_far):
            c_row = next(r for r in loaded[part, "C"] if r["frame"] == frame)
            s_row = next(r for r in loaded[part, "S"] if r["frame"] == frame)
            print(f"  > 90 deg from C only: {part} frame {frame} ({c_row.get('regime', '?')}, "
                  f"{c_row.get('distance', float('nan')):.0f} m) e_R {c_row['e_R']:.1f} deg, {c_row['decided_by']} "
                  f"route, chamfer {c_row['outline_chamfer_px']:.2f} px, p {c_row.get('flip_prob', float('nan')):.3f}; "
                  f"S: {s_row['status']}, p {s_row.get('flip_prob', float('nan')):.3f}")
    s, c = pooled["S"], pooled["C"]
    clause1 = c["valid"] >= s["valid"] and c["wrong"] <= s["wrong"]
    print(f"1. pooled: S {s['valid']} valid / {s['wrong']} wrong, C {c['valid']} / {c['wrong']}: "
          f"{'met' if clause1 else 'NOT met'}")
    print(f"2. no > 90 deg pose from C alone in any group: {'met' if clause2 else 'NOT met'}")
    with gzip.open(HERE.parent / "flip_s23" / "test640_s23.json.gz", "rt") as fh:
        ts = tally(json.load(fh)["frames"])
    tc = tally(rows(runs, "test_C"))
    clause3 = tc["far"] == 0 and tc["valid"] >= ts["valid"] - 3
    print(f"3. test split of data/tdrs640 ({tc['n']} frames): S {ts['valid']} / {ts['wrong']} / {ts['far']}, "
          f"C {tc['valid']} / {tc['wrong']} / {tc['far']}: {'met' if clause3 else 'NOT met'}")
    print("verdict:", "met: ship C" if clause1 and clause2 and clause3 else "NOT met: nothing ships")


if __name__ == "__main__":
    main()
