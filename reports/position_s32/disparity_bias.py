"""The stereo graph's signed disparity error over the target (session 32): is it biased?

    python reports/position_s32/disparity_bias.py [DATASET] [--first 2700] [--count 40] [--out FILE] [--bundle DIR]

Runs ``spacepose disparity`` (the shipped bundle unless ``--bundle``; the whole runtime stereo stage: coarse pass, window, fine pass) on
frames ``first .. first+count-1`` of DATASET (default ``data/tdrs640``, made by ``spacepose render data/tdrs640
--target tdrs --count 3000 --size 640x480 --seed 1``; frames 2700-2999 are its test split) and compares the maps
with the rendered disparity over the target's mask: its interior (the mask eroded by a 7x7 square) and its rim
(the rest). Prints per-frame and pooled statistics of predicted minus true disparity (negative: the graph reads
the target too far) and writes them as JSON (default ``reports/position_s32/disparity_bias.json``).
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np

from spacepose.cli import main as cli_main
from spacepose.imageio import read_image, read_pfm


def frame_stats(pred: np.ndarray, gt: np.ndarray, mask: np.ndarray) -> dict[str, float]:
    inner = cv2.erode(mask.astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
    ok = np.isfinite(pred) & np.isfinite(gt) & (gt > 0)
    err = pred - gt
    out = {"gt_mean_px": float(gt[mask & ok].mean()) if (mask & ok).any() else float("nan")}
    for name, sel in (("interior", inner & ok), ("rim", mask & ~inner & ok)):
        e = err[sel]
        out[f"{name}_pixels"] = int(sel.sum())
        out[f"{name}_mean_px"] = float(e.mean()) if e.size else float("nan")
        out[f"{name}_median_px"] = float(np.median(e)) if e.size else float("nan")
    return out


def stereo_rows(dataset: Path, names: list[str], bundle: Path | None) -> list[dict]:
    """Run ``spacepose disparity`` (one thread; the shipped bundle unless ``bundle``) on frames ``names`` of
    ``dataset`` and return one row per frame: ``frame`` and :func:`frame_stats` against the rendered disparity."""
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for side in ("left", "right"):
            (work / side).mkdir()
            for n in names:
                (work / side / f"{n}.png").symlink_to((dataset / side / f"{n}.png").resolve())
        if cli_main(["disparity", str(work), "--calib", str(dataset / "rig.yaml"), "--out", str(work / "pred"),
                     "--threads", "1", *(["--bundle", str(bundle)] if bundle else [])]) != 0:
            raise SystemExit("spacepose disparity failed")
        rows = []
        for n in names:
            mask = read_image(dataset / "mask" / f"{n}.png")
            mask = (mask[..., 0] if mask.ndim == 3 else mask) > 0
            rows.append({"frame": n, **frame_stats(read_pfm(work / "pred" / f"{n}.pfm"),
                                                     read_pfm(dataset / "disparity" / f"{n}.pfm"), mask)})
    return rows


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset", nargs="?", type=Path, default=Path("data/tdrs640"))
    ap.add_argument("--first", type=int, default=2700)
    ap.add_argument("--count", type=int, default=40)
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "disparity_bias.json")
    ap.add_argument("--bundle", type=Path, default=None, help="model bundle folder (default: the shipped one)")
    args = ap.parse_args(argv)
    names = [f"{i:06d}" for i in range(args.first, args.first + args.count)]
    rows = stereo_rows(args.dataset, names, args.bundle)
    print(f"{'frame':<8}{'gt px':>7}{'interior mean':>15}{'median':>9}{'rim mean':>10}{'median':>9}")
    for r in rows:
        print(f"{r['frame']:<8}{r['gt_mean_px']:>7.1f}{r['interior_mean_px']:>+15.3f}{r['interior_median_px']:>+9.3f}"
              f"{r['rim_mean_px']:>+10.3f}{r['rim_median_px']:>+9.3f}")
    med = np.array([r["interior_median_px"] for r in rows if r["interior_pixels"]])
    pooled = {"frames": len(rows), "frames_with_interior": int(med.size),
              "median_of_interior_medians_px": float(np.median(med)),
              "frames_interior_median_below_zero": int(np.sum(med < 0)),
              "frames_interior_median_below_minus_0.1": int(np.sum(med < -0.1))}
    print(json.dumps(pooled))
    args.out.write_text(json.dumps({"dataset": str(args.dataset), "first": args.first, "count": args.count,
                                    "pooled": pooled, "frames": rows}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
