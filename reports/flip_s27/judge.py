"""Counts and verdict of reports/flip_s27/plan.txt (candidate C, the flip classifier trained on twice the frames,
against the shipped bundle S).

    python reports/flip_s27/judge.py [RUNS]

RUNS (default ``runs/s27``) holds ``single640_{S,C}/pose_eval.json``, ``single1280_{S,C}/pose_eval.json``
(``eval-pose``) and ``seq_kK_{S,C}.json`` (``sequence eval``, K = 1..10). When they are all there, their frames are
cut to the columns counted here and written to ``rows.json.gz`` / ``rows_sequences.json.gz`` beside this script;
otherwise those committed files are read, so the verdict reproduces without the runs.

After the verdict it prints, outside the rule, the same counts on the sets the plan reports but does not judge:
``extra640_{S,C}`` (a fresh set added before C existed), ``restyle_{S,C}`` (the restyled test split),
``test_{S,C}`` (the test split) and ``unseen_{S,C}`` (1280x960), rows in ``rows_reported.json.gz``.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "position_s25"))
from _rows import STATS_HEAD, compact_rows, position_stats  # noqa: E402

MAX_E_T, MAX_E_R, FAR_DEG, MAX_E_POS = 0.5, 20.0, 90.0, 2.0
SINGLE = {"single640": "tdrs640_s27f, 900 train frames", "single1280": "tdrs1280_s27f, 90 train frames"}
SEQUENCES = [f"seq_k{k}" for k in range(1, 11)]
KEYS = ("frame", "regime", "distance", "valid", "status", "e_t", "e_R", "decided_by", "flip_prob",
        "outline_chamfer_px", "position_valid", "e_pos", "depth_tolerance_m")
SEQ_KEYS = ("frame", "valid", "status", "tracked", "e_t", "e_R", "decided_by")
REPORTED = {"extra640": "tdrs640_s27x, 900 train frames (extra)", "restyle": "restyled test split, 300",
            "test": "test split, 300", "unseen": "unseen 1280x960, 90"}


def load(runs: Path) -> dict[str, list[dict]]:
    singles = compact_rows({f"{n}_{b}": [runs / f"{n}_{b}" / "pose_eval.json"] for n in SINGLE for b in "SC"},
                           HERE / "rows.json.gz", KEYS)
    seqs = compact_rows({f"{n}_{b}": [runs / f"{n}_{b}.json"] for n in SEQUENCES for b in "SC"},
                        HERE / "rows_sequences.json.gz", SEQ_KEYS)
    reported = compact_rows({f"{n}_{b}": [runs / f"{n}_{b}" / "pose_eval.json"] for n in REPORTED for b in "SC"},
                            HERE / "rows_reported.json.gz", KEYS)
    return {**singles, **seqs, **reported}


def wrong(r: dict) -> bool:
    """A valid pose off by more than 20 deg or 0.5 m (this session's scripts count with this one test)."""
    return r["e_R"] > MAX_E_R or r["e_t"] > MAX_E_T


def tally(frames: list[dict]) -> dict[str, int]:
    valid = [r for r in frames if r["valid"]]
    return dict(n=len(frames), valid=len(valid), wrong=sum(map(wrong, valid)),
                far=sum(r["e_R"] > FAR_DEG for r in valid))


def far_keys(frames: list[dict], tag: str) -> set:
    return {(tag, r["frame"]) for r in frames if r["valid"] and r["e_R"] > FAR_DEG}


def position_safety(frames: list[dict]) -> tuple[float, int]:
    """Share of positions without a valid pose within their tolerance, and the count over 2 m."""
    pos = [r for r in frames if r["position_valid"] and not r["valid"]]
    if not pos:
        return 1.0, 0
    e = np.array([r["e_pos"] for r in pos])
    return float(np.mean(e <= np.array([r["depth_tolerance_m"] for r in pos]))), int(np.sum(e > MAX_E_POS))


def judge(label: str, s_frames: list[dict], c_frames: list[dict], s_far: set, c_far: set,
          positions: bool) -> bool:
    s, c = tally(s_frames), tally(c_frames)
    new_far = len(c_far - s_far)
    ok = {"a": c["valid"] >= s["valid"], "b": c["wrong"] <= s["wrong"], "c": new_far == 0}
    text = ""
    if positions:
        (s_in, s_over), (c_in, c_over) = position_safety(s_frames), position_safety(c_frames)
        ok["d"] = (c_in >= 0.95 and c_over == 0) or (c_in >= s_in and c_over <= s_over)
        text = (f"   positions only: within tau S {100 * s_in:.1f} % C {100 * c_in:.1f} %, over 2 m S {s_over} "
                f"C {c_over}")
    failed = [k for k, v in ok.items() if not v]
    print(f"{label:34s} S {s['valid']:4d} / {s['wrong']:2d} / {s['far']}   C {c['valid']:4d} / {c['wrong']:2d} / "
          f"{c['far']}   new > 90 deg {new_far}{text}: {'met' if not failed else 'NOT met ' + ','.join(failed)}")
    return not failed


def main(runs: Path) -> int:
    rows = load(runs)
    print("valid / wrong (e_R > 20 deg or e_t > 0.5 m) / > 90 deg")
    verdict = True
    for name, label in SINGLE.items():
        s, c = rows[f"{name}_S"], rows[f"{name}_C"]
        verdict &= judge(label, s, c, far_keys(s, name), far_keys(c, name), positions=True)
    s_all, c_all, s_far, c_far = [], [], set(), set()
    for name in SEQUENCES:
        s, c = rows[f"{name}_S"], rows[f"{name}_C"]
        s_all += s
        c_all += c
        s_far |= far_keys(s, name)
        c_far |= far_keys(c, name)
    verdict &= judge("sequences k1..k10 (400 frames)", s_all, c_all, s_far, c_far, positions=False)
    print("verdict:", "met: ship C" if verdict else "NOT met: nothing ships")
    print("\nreported, not judged (the same columns)")
    for name, label in REPORTED.items():
        s, c = rows[f"{name}_S"], rows[f"{name}_C"]
        judge(label, s, c, far_keys(s, name), far_keys(c, name), positions=True)
    print("\nper regime, valid / wrong (S -> C), and positions (all frames with one)")
    for name in [*SINGLE, *REPORTED]:
        for regime in sorted({r["regime"] for r in rows[f"{name}_S"]}):
            s = tally([r for r in rows[f"{name}_S"] if r["regime"] == regime])
            c = tally([r for r in rows[f"{name}_C"] if r["regime"] == regime])
            print(f"  {name} {regime:9s} {s['n']:4d} frames: {s['valid']:4d} / {s['wrong']} -> {c['valid']:4d} / "
                  f"{c['wrong']}")
        print(f"  {'':34s}{STATS_HEAD}")
        for b in "SC":
            print(f"  {name + ' ' + b:34s}{position_stats(rows[f'{name}_{b}'])}")
        decided = {b: sum(r["valid"] and r["decided_by"] == "classifier" for r in rows[f"{name}_{b}"]) for b in "SC"}
        print(f"  valid poses the classifier decided: S {decided['S']}, C {decided['C']}")
    return 0 if verdict else 1


if __name__ == "__main__":
    raise SystemExit(main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("runs/s27")))
