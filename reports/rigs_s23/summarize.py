"""Session 23: the shipped bundle on rigs it was never trained on. Prints the table quoted in README.md
and the model card from the compact per-frame rows beside this script (``rig_NAME.json.gz``).

    python reports/rigs_s23/summarize.py                       # the table, from the committed rows
    python reports/rigs_s23/summarize.py --collect runs/s23    # first refresh the rows from eval-pose runs

How the rows were made (each rig file is in this folder; the frames are rendered fresh, seeds 2321-2327):

    spacepose render data/rigA_s23b --target tdrs --count 300 --size 1024x768 --seed 2321 --rig reports/rigs_s23/rigA_1024_f1250_b0.5.yaml
    spacepose render data/rigB_s23b --target tdrs --count 300 --size 800x600 --seed 2322 --rig reports/rigs_s23/rigB_800_f1000_b2.0.yaml
    spacepose render data/rigC_s23b --target tdrs --count 300 --size 1280x960 --seed 2323 --depth 14 50 --rig reports/rigs_s23/rigC_1280_f2400_b1.0.yaml
    spacepose render data/rigD_s23b --target tdrs --count 300 --size 1280x720 --seed 2324 --depth 12 50 --rig reports/rigs_s23/rigD_1280x720_f1400_b0.8.yaml
    spacepose render data/rigE_s23b --target tdrs --count 300 --size 640x480 --seed 2325 --rig reports/rigs_s23/rigE_640_f500_b1.5.yaml
    spacepose render data/paper1280_s23b --target tdrs --count 300 --size 1280x960 --seed 2326
    spacepose render data/rigF_s23b --target tdrs --count 300 --size 1280x960 --seed 2327 --rig reports/rigs_s23/rigF_paper_b0.3.yaml
    python -m spacepose.tools.derectify data/rigA_s23b data/rigA_raw_s23b --seed 2331 --split train
    python -m spacepose.tools.derectify data/paper1280_s23b data/paper1280_raw_s23b --seed 2332 --split train
    spacepose eval-pose DATASET --split train --limit 200 --threads 1 --overlays 0 --out runs/s23/rig_NAME

Tracking (``seq_RIG_K.json.gz``): three tumbling sequences per rig, 40 frames each, run in order with the prior,

    python -m spacepose.tools.sequence render data/seqrig_RIG_1 --frames 40 --distance 15 --rate 2 --regime sun --seed 601 [--rig FILE]
    python -m spacepose.tools.sequence render data/seqrig_RIG_2 --frames 40 --distance 25 --rate 2 --regime albedo --seed 602 [--rig FILE]
    python -m spacepose.tools.sequence render data/seqrig_RIG_3 --frames 40 --distance 35 --rate 2 --regime penumbra --seed 603 [--rig FILE]
    python -m spacepose.tools.sequence eval data/seqrig_RIG_K --threads 1 --json runs/s23/seq/seqrig_RIG_K.json

(the paper rig with ``--size 1280x960`` and no ``--rig``; rigs A, B and F with their files).

(``--workers 2`` on the renders; the render refuses depths at which the target cannot be wholly in
both views, hence ``--depth`` for rigs C and D.) Wrong: e_R > 20 deg or e_t > 0.5 m; far: e_R > 90 deg.
"""
import argparse
import gzip
import json
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RIGS = {  # name: (what it is, the eval-pose run's folder name)
    "paper": "paper rig 1280x960, f 1600, B 1.0 m (reference)",
    "paper_raw": "the same frames through a distorted, turned rig (derectify seed 2332)",
    "A": "1024x768, f 1250, B 0.5 m",
    "A_raw": "rig A frames through a distorted, turned rig (derectify seed 2331)",
    "B": "800x600, f 1000, B 2.0 m",
    "C": "1280x960, f 2400, B 1.0 m, 14-50 m",
    "D": "1280x720, f 1400, B 0.8 m, 12-50 m",
    "E": "640x480, f 500, B 1.5 m",
    "F": "paper rig with B 0.3 m (2x2 tiled coarse pass)",
}
KEEP = ("frame", "regime", "distance", "valid", "status", "e_t", "e_R", "decided_by", "depth_tolerance_m",
        "outline_chamfer_px", "flip_prob")


def collect(runs: Path) -> None:
    for name in RIGS:
        src = runs / f"rig_{name}" / "pose_eval.json"
        if not src.is_file():
            print(f"{name}: no run at {src}")
            continue
        rows = [{k: r.get(k) for k in KEEP} for r in json.loads(src.read_text())["frames"]]
        with gzip.open(HERE / f"rig_{name}.json.gz", "wt") as fh:
            json.dump({"rig": RIGS[name], "frames": rows}, fh)


SEQ_RIGS = ("paper", "A", "B", "F")
SEQ_KEEP = ("frame", "valid", "status", "tracked", "e_t", "e_R")


def collect_sequences(runs: Path) -> None:
    for rig in SEQ_RIGS:
        for k in (1, 2, 3):
            src = runs / "seq" / f"seqrig_{rig}_{k}.json"
            if not src.is_file():
                print(f"sequence {rig} {k}: no run at {src}")
                continue
            rows = [{key: r.get(key) for key in SEQ_KEEP} for r in json.loads(src.read_text())["frames"]]
            with gzip.open(HERE / f"seq_{rig}_{k}.json.gz", "wt") as fh:
                json.dump({"rig": rig, "frames": rows}, fh)


def sequence_table() -> None:
    print("\n| rig | sequences (15 / 25 / 35 m) | valid | tracked | wrong | > 90° | valid per sequence |")
    print("|---|---|---|---|---|---|---|")
    for rig in SEQ_RIGS:
        per, rows = [], []
        for k in (1, 2, 3):
            path = HERE / f"seq_{rig}_{k}.json.gz"
            if path.is_file():
                with gzip.open(path, "rt") as fh:
                    fr = json.load(fh)["frames"]
                per.append(sum(r["valid"] for r in fr))
                rows += fr
        if not rows:
            continue
        valid = [r for r in rows if r["valid"]]
        wrong = sum(r["e_R"] > 20.0 or r["e_t"] > 0.5 for r in valid)
        far = sum(r["e_R"] > 90.0 for r in valid)
        print(f"| {rig}: {RIGS[rig]} | {len(per)} x 40 | {len(valid)} of {len(rows)} | "
              f"{sum(bool(r['tracked']) for r in valid)} | {wrong} | {far} | {' / '.join(map(str, per))} |")


def table() -> None:
    print("| rig | frames | valid | mean e_t / e_R | median e_t / e_R | wrong | > 90° | valid at 10-20 / 20-30 / 30-40 / 40-50 m "
          "| e_t <= depth_tolerance_m (its largest) |")
    print("|---|---|---|---|---|---|---|---|---|")
    within = total = 0
    for name, what in RIGS.items():
        path = HERE / f"rig_{name}.json.gz"
        if not path.is_file():
            continue
        with gzip.open(path, "rt") as fh:
            rows = json.load(fh)["frames"]
        valid = [r for r in rows if r["valid"]]
        e_t = np.array([r["e_t"] for r in valid])
        e_r = np.array([r["e_R"] for r in valid])
        wrong = int(np.sum((e_r > 20.0) | (e_t > 0.5)))
        far = int(np.sum(e_r > 90.0))
        bins = []
        for lo in (10, 20, 30, 40):
            b = [r for r in rows if lo <= r["distance"] < lo + 10]
            bins.append(f"{100 * sum(r['valid'] for r in b) / len(b):.0f}" if b else "–")
        stats = (f"{e_t.mean():.3f} m / {e_r.mean():.2f}° | {np.median(e_t):.3f} m / {np.median(e_r):.2f}°"
                 if valid else "– | –")
        tau = np.array([r["depth_tolerance_m"] for r in valid])
        inside = int(np.sum(e_t <= tau))
        within, total = within + inside, total + len(valid)
        print(f"| {name}: {what} | {len(rows)} | {len(valid)} ({100 * len(valid) / len(rows):.1f} %) | {stats} | "
              f"{wrong} | {far} | {' / '.join(bins)} % | {inside} of {len(valid)} ({tau.max() if valid else 0:.2f} m) |")
    print(f"\nvalid poses with e_t <= depth_tolerance_m, all sets: {within} of {total}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--collect", type=Path, default=None, help="runs folder holding rig_NAME/pose_eval.json")
    args = parser.parse_args()
    if args.collect is not None:
        collect(args.collect)
        collect_sequences(args.collect)
    table()
    sequence_table()
