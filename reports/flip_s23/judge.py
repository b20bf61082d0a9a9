"""Counts and verdict of reports/flip_s23/plan.txt (candidate C against the shipped bundle S).

    python reports/flip_s23/judge.py RUNS

RUNS holds ``single640_{S,C}/pose_eval.json``, ``single1280_{S,C}/pose_eval.json`` (``eval-pose``) and
``seq_hK_{S,C}.json`` (``sequence eval``, K = 1..10). Missing files are read from ``NAME.json.gz`` beside this script.
"""
import gzip
import json
import sys
from pathlib import Path

MAX_E_T, MAX_E_R, FAR_DEG = 0.5, 20.0, 90.0
HERE = Path(__file__).resolve().parent


def rows(path: Path) -> list:
    if not path.exists():
        name = path.parent.name if path.name == "pose_eval.json" else path.stem
        path = HERE / f"{name}.json.gz"
    with (gzip.open(path, "rt") if path.suffix == ".gz" else open(path)) as fh:
        return json.load(fh)["frames"]


def tally(frames: list) -> dict:
    valid = [r for r in frames if r["valid"]]
    wrong = sum(r["e_R"] > MAX_E_R or r["e_t"] > MAX_E_T for r in valid)
    return dict(n=len(frames), valid=len(valid), wrong=wrong, far=sum(r["e_R"] > FAR_DEG for r in valid))


def far_keys(frames: list, tag: str) -> set:
    return {(tag, r["frame"]) for r in frames if r["valid"] and r["e_R"] > FAR_DEG}


def judge(label: str, s_frames: list, c_frames: list, s_far: set, c_far: set) -> bool:
    s, c = tally(s_frames), tally(c_frames)
    new_far = len(c_far - s_far)
    ok = c["valid"] >= s["valid"] and c["wrong"] <= s["wrong"] and new_far == 0
    print(f"{label:34s} S {s['valid']:4d} / {s['wrong']:2d} / {s['far']}   C {c['valid']:4d} / {c['wrong']:2d} / {c['far']}"
          f"   new > 90 deg {new_far}: {'met' if ok else 'NOT met'}")
    return ok


def main() -> None:
    runs = Path(sys.argv[1])
    print("valid / wrong (e_R > 20 deg or e_t > 0.5 m) / > 90 deg")
    verdict = True
    for name, label in (("single640", "tdrs640_s23f, 450 train frames"), ("single1280", "tdrs1280_s23f, 90 frames")):
        s, c = rows(runs / f"{name}_S" / "pose_eval.json"), rows(runs / f"{name}_C" / "pose_eval.json")
        verdict &= judge(label, s, c, far_keys(s, name), far_keys(c, name))
    s_all, c_all, s_far, c_far = [], [], set(), set()
    for k in range(1, 11):
        s, c = rows(runs / f"seq_h{k}_S.json"), rows(runs / f"seq_h{k}_C.json")
        s_all += s
        c_all += c
        s_far |= far_keys(s, f"h{k}")
        c_far |= far_keys(c, f"h{k}")
    verdict &= judge("sequences h1..h10 (400 frames)", s_all, c_all, s_far, c_far)
    print("verdict:", "met: ship C" if verdict else "NOT met: nothing ships")


if __name__ == "__main__":
    main()
