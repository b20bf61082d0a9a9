"""Compare two eval-pose reports frame by frame: valid poses, flips and wrong poses, and which frames one adds or
drops. A flip is a valid pose off by more than ``FLIP_DEG`` (as in ``eval-pose``); a wrong one is off by more than
20° or 0.5 m (``calibrate_gates``' default bounds). Reports may be gzipped.

    python reports/flip_s18/compare_reports.py A/pose_eval.json[.gz] B/pose_eval.json[.gz]

With ``--sequences FOLDER TAG`` it sums the ``sequence eval`` reports ``FOLDER/NAME_TAG.json`` instead (the
folder ``sequences.tar.gz`` unpacks to): valid, tracked and flips from each summary, and the wrong poses.

With ``--added A1 B1 [A2 B2 …]`` it pools the frames each B makes valid that its A does not, and prints, for the
right and the wrong ones, the run-time factors (median and 90th percentile of the right ones, every value of the
wrong ones). With ``--decided R1 [R2 …]`` it does the same for the valid rows of open evaluations that the
classifier would decide for the outline's winner (``flip_prob`` >= 0.995, chamfer <= 1.5 px, outline margin
< 0.5 px: an approximation), with the right ones kept under polish caps of 1.5, 2, 3 and 4°.
"""

import gzip
import json
import sys
from pathlib import Path

from spacepose.tools.eval_pose import FLIP_DEG

MAX_E_T, MAX_E_R = 0.5, 20.0


def load(path):
    with (gzip.open if path.endswith(".gz") else open)(path, "rt") as f:
        return {r["frame"]: r for r in json.load(f)["frames"]}


def stats(rows):
    valid = [r for r in rows if r["valid"]]
    good = [r for r in valid if r["e_R"] <= FLIP_DEG]
    n_good = max(len(good), 1)
    return dict(n=len(rows), valid=len(valid), flips=len(valid) - len(good),
                wrong=sum(1 for r in valid if r["e_R"] > MAX_E_R or r["e_t"] > MAX_E_T),
                e_t=round(sum(r["e_t"] for r in good) / n_good, 4), e_R=round(sum(r["e_R"] for r in good) / n_good, 3))


def main(path_a, path_b):
    a, b = load(path_a), load(path_b)
    common = sorted(set(a) & set(b))
    print("A", stats([a[f] for f in common]))
    print("B", stats([b[f] for f in common]))
    gained = [f for f in common if b[f]["valid"] and not a[f]["valid"]]
    lost = [f for f in common if a[f]["valid"] and not b[f]["valid"]]
    changed = [f for f in common if a[f]["valid"] and b[f]["valid"] and abs(a[f]["e_R"] - b[f]["e_R"]) > 1e-3]
    print("gained", len(gained), "lost", len(lost), "changed", len(changed))
    nan = float("nan")
    for f in gained:
        print("  +", f, b[f]["regime"], round(b[f]["e_t"], 3), round(b[f]["e_R"], 2), round(b[f].get("flip_prob", nan), 3))
    for f in lost:
        print("  -", f, a[f]["regime"], b[f]["status"], round(a[f]["e_R"], 2), round(b[f].get("flip_prob", nan), 3))


FACTORS = ("outline_chamfer_px", "outline_margin_px", "depth_tolerance_m", "confidence", "polish_deg")


def _wrong(r):
    return r["e_R"] > MAX_E_R or r["e_t"] > MAX_E_T


def factors(rows):
    import numpy as np

    right, wrong = [r for r in rows if not _wrong(r)], [r for r in rows if _wrong(r)]
    print(len(rows), "poses,", len(wrong), "wrong:", [(r["frame"], r["regime"], round(r["e_R"], 1)) for r in wrong])
    for key in FACTORS:
        values = np.array([r[key] for r in right], float)
        print(f"{key:20s} right: median {np.nanmedian(values):.2f} p90 {np.nanpercentile(values, 90):.2f} | wrong:",
              [round(r[key], 2) for r in wrong])
    return right, wrong


def added(paths):
    rows = []
    for path_a, path_b in zip(paths[::2], paths[1::2]):
        a, b = load(path_a), load(path_b)
        rows += [b[f] for f in sorted(set(a) & set(b)) if b[f]["valid"] and not a[f]["valid"]]
    factors(rows)


def decided(paths):
    rows = [r for path in paths for r in load(path).values()
            if r["valid"] and r.get("flip_prob", 0.0) >= 0.995 and r["outline_chamfer_px"] <= 1.5
            and r["outline_margin_px"] < 0.5]
    right, wrong = factors(rows)
    for cap in (1.5, 2.0, 3.0, 4.0):
        print(f"polish cap {cap}: right kept {sum(r['polish_deg'] <= cap for r in right)} of {len(right)}, "
              f"wrong kept {sum(r['polish_deg'] <= cap for r in wrong)}")


def sequences(folder, tag):
    total = dict(frames=0, valid=0, tracked=0, flips=0, wrong=0)
    for path in sorted(Path(folder).glob(f"*_{tag}.json")):
        report = json.loads(path.read_text())
        wrong = sum(1 for r in report["frames"] if r.get("valid")
                    and ((r.get("e_R") or 0) > MAX_E_R or (r.get("e_t") or 0) > MAX_E_T))
        s = report["summary"]
        print(path.name[: -len(f"_{tag}.json")], s["valid"], s["tracked"], s["flips"], wrong)
        for key in ("frames", "valid", "tracked", "flips"):
            total[key] += s[key]
        total["wrong"] += wrong
    print("TOTAL", total)


if __name__ == "__main__":
    if sys.argv[1] == "--sequences":
        sequences(*sys.argv[2:4])
    elif sys.argv[1] == "--added":
        added(sys.argv[2:])
    elif sys.argv[1] == "--decided":
        decided(sys.argv[2:])
    else:
        main(*sys.argv[1:3])
