"""Counts and verdict of reports/flip_s23/gate_rule.txt (gate G on the shipped bundle S).

    python reports/flip_s23/gate_judge.py RUNS

RUNS holds ``g640a_S/pose_eval.json`` and ``g640b_S/pose_eval.json`` (``eval-pose`` of data/tdrs640_s23g, train
frames 0-674 and 675-1349, bundle S) and ``seq_hK_{S,G}.json`` (``sequence eval`` of data/seq_hK with S and with
S + G, K = 1..10). Missing files are read from ``NAME.json.gz`` beside this script. Also prints what G would have
refused on the fresh single-frame sets of sessions 22-23 that chose it (post hoc, as gate_rule.txt says).
"""
import gzip
import json
import sys
from pathlib import Path

MAX_E_T, MAX_E_R, FAR_DEG, CHAMFER_PX, MIN_PROB = 0.5, 20.0, 90.0, 1.5, 0.99
HERE = Path(__file__).resolve().parent


def rows(path: Path) -> list:
    path = Path(path)
    if not path.exists():
        name = path.parent.name if path.name == "pose_eval.json" else path.stem
        path = HERE / f"{name}.json.gz"
    with (gzip.open(path, "rt") if str(path).endswith(".gz") else open(path)) as fh:
        return json.load(fh)["frames"]


def wrong(r: dict) -> bool:
    return r["e_R"] > MAX_E_R or r["e_t"] > MAX_E_T


def refused_by_g(r: dict) -> bool:
    """A valid single-frame pose G refuses: decided by the image route with a loose fit, the classifier unsure."""
    return (r["valid"] and r["decided_by"] == "image" and r["outline_chamfer_px"] > CHAMFER_PX
            and not r.get("flip_prob", float("nan")) >= MIN_PROB)


def main() -> None:
    runs = Path(sys.argv[1])
    single = rows(runs / "g640a_S" / "pose_eval.json") + rows(runs / "g640b_S" / "pose_eval.json")
    valid = [r for r in single if r["valid"]]
    gone = [r for r in valid if refused_by_g(r)]
    share = len(gone) / max(len(valid), 1)
    ok1 = share <= 0.02
    print(f"tdrs640_s23g, {len(single)} train frames: S {len(valid)} valid, {sum(map(wrong, valid))} wrong, "
          f"{sum(r['e_R'] > FAR_DEG for r in valid)} > 90 deg; G refuses {len(gone)} ({100 * share:.1f} %; "
          f"{sum(map(wrong, gone))} wrong, {sum(r['e_R'] > FAR_DEG for r in gone)} > 90 deg): "
          f"{'met' if ok1 else 'NOT met'} (<= 2 %)")
    tallies, far = {}, {}
    for tag in ("S", "G"):
        allr = []
        far[tag] = set()
        for k in range(1, 11):
            fr = rows(runs / f"seq_h{k}_{tag}.json")
            allr += fr
            far[tag] |= {(k, r["frame"]) for r in fr if r["valid"] and r["e_R"] > FAR_DEG}
        v = [r for r in allr if r["valid"]]
        tallies[tag] = dict(valid=len(v), wrong=sum(map(wrong, v)), right=sum(not wrong(r) for r in v),
                            far=len(far[tag]))
    s, g = tallies["S"], tallies["G"]
    new_far = len(far["G"] - far["S"])
    ok2 = g["wrong"] <= s["wrong"] and g["right"] >= 0.95 * s["right"] and new_far == 0
    print(f"sequences h1..h10: S {s['valid']} valid / {s['wrong']} wrong / {s['far']} > 90 deg; "
          f"S + G {g['valid']} / {g['wrong']} / {g['far']}; right {g['right']} vs 0.95 x {s['right']}, "
          f"new > 90 deg {new_far}: {'met' if ok2 else 'NOT met'}")
    print("verdict:", "met: ship G" if ok1 and ok2 else "NOT met: G does not ship")
    posthoc()


def posthoc() -> None:
    """What G refuses on the fresh single-frame sets it was chosen on (gate_rule.txt)."""
    s22, rigs = HERE.parent / "flip_s22", HERE.parent / "rigs_s23"
    sets = [s22 / "big2700_shipped.json.gz", s22 / "val7_cand.json.gz", s22 / "val8a_Cp.json.gz",
            s22 / "val8b_Cp.json.gz", s22 / "val9a_Cp.json.gz", s22 / "val9b_Cp.json.gz",
            HERE / "single640_S.json.gz", HERE / "single1280_S.json.gz"]
    sets += sorted(rigs.glob("rig_*.json.gz"))
    valid = [r for path in sets for r in rows(path) if r["valid"]]
    gone = [r for r in valid if refused_by_g(r)]
    print(f"post hoc, {len(sets)} fresh single-frame sets of sessions 22-23: {len(valid)} valid poses; G refuses "
          f"{len(gone)}: {sum(r['e_R'] > FAR_DEG for r in gone)} > 90 deg, "
          f"{sum(wrong(r) and r['e_R'] <= FAR_DEG for r in gone)} other wrong, {sum(not wrong(r) for r in gone)} right")


if __name__ == "__main__":
    main()
