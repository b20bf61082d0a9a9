"""Session 36: the stereo stage's signed disparity error on the same frames, plain and restyled.

    python reports/restyle_s36/disparity_bias_pair.py PLAIN RESTYLED [--count 60] [--bundle DIR] [--out FILE]

Takes the first ``count`` frames of RESTYLED's ``labels.jsonl`` (made by ``python -m spacepose.tools.restyle PLAIN
RESTYLED --seed S --split test``), runs ``spacepose disparity`` (the whole runtime stereo stage) on them in both
datasets, and compares each map with the rendered disparity over the target's interior and rim
(``reports/position_s32/disparity_bias.py``'s ``stereo_rows``). Prints per-frame rows with the frame's style and
pooled medians, and writes them as JSON (default ``reports/restyle_s36/disparity_bias_pair.json``).
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import sys
from pathlib import Path

import numpy as np

_spec = importlib.util.spec_from_file_location("disparity_bias_s32",
                                               Path(__file__).resolve().parents[1] / "position_s32/disparity_bias.py")
_s32 = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_s32)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("plain", type=Path)
    ap.add_argument("restyled", type=Path)
    ap.add_argument("--count", type=int, default=60)
    ap.add_argument("--bundle", type=Path, default=None)
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "disparity_bias_pair.json")
    args = ap.parse_args(argv)
    labels = [json.loads(x) for x in (args.restyled / "labels.jsonl").read_text().splitlines() if x.strip()]
    labels = labels[: args.count]
    names = [d["frame"] for d in labels]
    plain = _s32.stereo_rows(args.plain, names, args.bundle)
    rest = _s32.stereo_rows(args.restyled, names, args.bundle)
    print(f"{'frame':<8}{'gt px':>7}{'plain int':>10}{'restyled':>10}{'plain rim':>10}{'restyled':>10}  style")
    rows = []
    for d, p, q in zip(labels, plain, rest):
        s = d["restyle"]
        print(f"{d['frame']:<8}{p['gt_mean_px']:>7.1f}{p['interior_median_px']:>+10.3f}{q['interior_median_px']:>+10.3f}"
              f"{p['rim_median_px']:>+10.3f}{q['rim_median_px']:>+10.3f}  g{s['gamma']:.2f} gain{s['gain']:.2f} "
              f"tint{max(s['tint']) - min(s['tint']):.2f} blur{s['blur_px']:.2f} noise{s['noise']:.3f}")
        rows.append({"frame": d["frame"], "style": s, "plain": p, "restyled": q})
    pooled = {}
    for name, side in (("plain", plain), ("restyled", rest)):
        med = np.array([r["interior_median_px"] for r in side if r["interior_pixels"]])
        absd = np.array([abs(r["interior_median_px"]) for r in side if r["interior_pixels"]])
        pooled[name] = {"frames_with_interior": int(med.size), "median_of_interior_medians_px": float(np.median(med)),
                        "mean_abs_interior_median_px": float(absd.mean()),
                        "frames_abs_interior_median_over_0.3": int(np.sum(absd > 0.3))}
    print(json.dumps(pooled))
    args.out.write_text(json.dumps({"plain": str(args.plain), "restyled": str(args.restyled), "count": args.count,
                                    "bundle": str(args.bundle) if args.bundle else None, "pooled": pooled,
                                    "frames": rows}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
