"""Counts and verdict of reports/flip_s27/gate_rule.txt (gate R, ``flip_classifier.registration_min_prob`` 0.9,
on the shipped bundle S).

    python reports/flip_s27/gate_judge.py [RUNS]

RUNS (default ``runs/s27``) holds ``g_{S,R}_{0,675}/pose_eval.json`` (``eval-pose`` of data/tdrs640_s27g, train
frames 0-674 and 675-1349, with S and with S + R) and ``seq_kK_{S,R}.json`` (``sequence eval`` of data/seq_kK,
K = 1..10), and ``{test,unseen}_{S,R}/pose_eval.json`` (the test split and the unseen 1280x960 set
re-measured with R, reported after the verdict). When they are all there, their frames are cut to the columns
counted here and written to ``gate_rows.json.gz`` / ``gate_rows_sequences.json.gz`` beside this script; otherwise those committed files are
read.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "position_s25"))
from _rows import compact_rows  # noqa: E402
from judge import FAR_DEG, wrong  # noqa: E402  (this folder: plan.txt's judge)

MIN_PROB = 0.9
KEYS = ("frame", "regime", "distance", "valid", "status", "e_t", "e_R", "decided_by", "flip_prob")
SEQ_KEYS = ("frame", "valid", "status", "tracked", "e_t", "e_R", "decided_by")
REMEASURE_KEYS = (*KEYS, "position_valid", "e_pos")
SEQUENCES = [f"seq_k{k}" for k in range(1, 11)]


def refused_by_r(r: dict) -> bool:
    """A valid pose of S that R refuses: decided by the registration route, the classifier below 0.9 (or none)."""
    p = r.get("flip_prob")
    return r["valid"] and r["decided_by"] == "registration" and not (p is not None and p >= MIN_PROB)


def load(runs: Path) -> dict[str, list[dict]]:
    single = compact_rows({f"g_{b}": [runs / f"g_{b}_{part}" / "pose_eval.json" for part in (0, 675)] for b in "SR"},
                          HERE / "gate_rows.json.gz", KEYS)
    seqs = compact_rows({f"{n}_{b}": [runs / f"{n}_{b}.json"] for n in SEQUENCES for b in "SR"},
                        HERE / "gate_rows_sequences.json.gz", SEQ_KEYS)
    remeasure = compact_rows({f"{n}_{b}": [runs / f"{n}_{b}" / "pose_eval.json"] for n in ("test", "unseen")
                              for b in "SR"}, HERE / "gate_rows_remeasure.json.gz", REMEASURE_KEYS)
    return {**single, **seqs, **remeasure}


def main(runs: Path) -> int:
    rows = load(runs)
    s, r = rows["g_S"], rows["g_R"]
    assert [a["frame"] for a in s] == [b["frame"] for b in r]
    valid = [a for a in s if a["valid"]]
    gone = [a for a in valid if refused_by_r(a)]
    # R only refuses: S + R must equal S on every frame but those
    same = all(b["valid"] == (a["valid"] and not refused_by_r(a)) for a, b in zip(s, r))
    new_far = sum(b["valid"] and b["e_R"] > FAR_DEG and not a["valid"] for a, b in zip(s, r))
    share = len(gone) / max(len(valid), 1)
    ok1 = share <= 0.01 and new_far == 0
    print(f"tdrs640_s27g, {len(s)} train frames: S {len(valid)} valid, {sum(map(wrong, valid))} wrong, "
          f"{sum(a['e_R'] > FAR_DEG for a in valid)} > 90 deg, {sum(a['decided_by'] == 'registration' for a in valid)} "
          f"by the registration route; R refuses {len(gone)} ({100 * share:.1f} %; {sum(map(wrong, gone))} wrong, "
          f"{sum(a['e_R'] > FAR_DEG for a in gone)} > 90 deg); S + R = S elsewhere: {same}; new > 90 deg {new_far}: "
          f"{'met' if ok1 else 'NOT met'} (<= 1 %)")
    for a in gone:
        print(f"  refused: frame {a['frame']} {a['regime']} {a['distance']:.1f} m, e_R {a['e_R']:.1f} deg, "
              f"e_t {a['e_t']:.2f} m, p {a['flip_prob']}")
    tallies, far = {}, {}
    for tag in "SR":
        allr = [x for n in SEQUENCES for x in rows[f"{n}_{tag}"]]
        far[tag] = {(n, x["frame"]) for n in SEQUENCES for x in rows[f"{n}_{tag}"] if x["valid"] and x["e_R"] > FAR_DEG}
        v = [x for x in allr if x["valid"]]
        tallies[tag] = dict(valid=len(v), wrong=sum(map(wrong, v)), right=sum(not wrong(x) for x in v),
                            far=len(far[tag]), registration=sum(x["decided_by"] == "registration" for x in v))
    ts, tr = tallies["S"], tallies["R"]
    new_far_seq = len(far["R"] - far["S"])
    ok2 = tr["wrong"] <= ts["wrong"] and tr["right"] >= 0.95 * ts["right"] and new_far_seq == 0
    print(f"sequences k1..k10: S {ts['valid']} valid / {ts['wrong']} wrong / {ts['far']} > 90 deg "
          f"({ts['registration']} by registration); S + R {tr['valid']} / {tr['wrong']} / {tr['far']} "
          f"({tr['registration']}); right {tr['right']} vs 0.95 x {ts['right']}, new > 90 deg {new_far_seq}: "
          f"{'met' if ok2 else 'NOT met'}")
    verdict = ok1 and ok2 and same
    print("verdict:", "met: ship R" if verdict else "NOT met: R does not ship")
    for name in ("test", "unseen"):
        a, b = rows[f"{name}_S"], rows[f"{name}_R"]
        same_frames = json.dumps(a) == json.dumps(b)   # NaN-safe, unlike ==
        print(f"re-measured, {name}: {sum(x['valid'] for x in b)} of {len(b)} valid with R; every column the same as "
              f"without it: {same_frames}")
    return 0 if verdict else 1


if __name__ == "__main__":
    raise SystemExit(main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("runs/s27")))
