"""Session 41, exploratory: samples for an outline refiner (the stereo outline, the image and the disparity over the
silhouette frame, against the rendered mask).

    python reports/outline_s41/samples.py DATASET --split train --skip S --limit N --out OUT.npz

Runs the shipped pipeline (use_prior off, as ``eval-pose``) on frames ``skip .. skip + limit`` of the split and, on
every frame that reaches the outline decision (:func:`spacepose.silhouette.decide_outline`), keeps in the decision's
silhouette frame (n <= 192 pixels a side, zero-padded to 192):

* ``grey``: the left image (:func:`spacepose.image_vote.window_grey`), float16;
* ``disp``: the disparity over the outline's own threshold (the observed outline is ``disp > 1``), float16;
* ``observed``: the stereo outline the decision used, uint8;
* ``truth``: the rendered mask (``mask/``) resampled the same way (> 0.5), uint8;
* ``size`` (n), ``frame``, ``regime``, ``distance``, ``valid`` (the frame's reported pose) and ``window`` (x0, y0,
  side, full-frame pixels).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

PAD = 192


def run(dataset: str, split: str, skip: int, limit: int, out: str) -> None:
    from spacepose import estimator as est_mod
    from spacepose.bundle import load_bundle
    from spacepose.calibration.rig import load_rig
    from spacepose.image_vote import crop_to_frame, window_grey
    from spacepose.imageio import read_image
    from spacepose.tools.pose_data import read_pose_labels

    root = Path(dataset)
    records = read_pose_labels(root, split)[skip: skip + limit]
    estimator = est_mod.PoseEstimator(load_rig(root / "rig.yaml"), bundle=load_bundle(None), threads=1,
                                      use_prior=False)
    original = est_mod.decide_outline
    seen: list = []

    def wrapped(candidates, points, disparity, K_full, baseline_m, window, config, **kw):
        decision = original(candidates, points, disparity, K_full, baseline_m, window, config, **kw)
        distance = float(np.mean([np.linalg.norm(t) for _, t in candidates]))
        min_disp = float(K_full[0, 0]) * float(baseline_m) / max(distance + config.depth_margin_m, 1e-6)
        fr = decision.frame
        disp = crop_to_frame(np.asarray(disparity, np.float32), fr.x0, fr.y0, fr.side, fr.size) / min_disp
        seen.append((fr, decision.observed.copy(), disp))
        return decision

    est_mod.decide_outline = wrapped
    keep: dict[str, list] = {k: [] for k in ("grey", "disp", "observed", "truth", "size", "frame", "regime",
                                             "distance", "valid", "window")}
    for i, rec in enumerate(records):
        seen.clear()
        left = read_image(root / "left" / f"{rec.frame}.png")
        res = estimator.estimate(left, read_image(root / "right" / f"{rec.frame}.png"))
        if seen:
            fr, observed, disp = seen[-1]
            n = fr.size
            truth = crop_to_frame(read_image(root / "mask" / f"{rec.frame}.png"), fr.x0, fr.y0, fr.side, n,
                                  convert=lambda box: (box > 127).astype(np.float32)) > 0.5
            for name, a, dtype in (("grey", window_grey(left, fr.x0, fr.y0, fr.side, n), np.float16),
                                   ("disp", np.clip(disp, 0.0, 60000.0), np.float16),
                                   ("observed", observed, np.uint8), ("truth", truth, np.uint8)):
                pad = np.zeros((PAD, PAD), dtype)
                pad[:n, :n] = a
                keep[name].append(pad)
            keep["size"].append(n)
            keep["frame"].append(rec.frame)
            keep["regime"].append(rec.regime)
            keep["distance"].append(rec.distance_m)
            keep["valid"].append(bool(res.valid))
            keep["window"].append((fr.x0, fr.y0, fr.side))
        if (i + 1) % 100 == 0:
            print(f"{i + 1}/{len(records)} frames, {len(keep['size'])} samples", flush=True)
    np.savez_compressed(out, **{k: np.asarray(v) for k, v in keep.items()}, dataset=dataset, split=split)


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("dataset")
    p.add_argument("--split", default="train")
    p.add_argument("--skip", type=int, default=0)
    p.add_argument("--limit", type=int, default=100)
    p.add_argument("--out", required=True)
    a = p.parse_args(argv)
    run(a.dataset, a.split, a.skip, a.limit, a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
