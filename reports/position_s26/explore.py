"""Session 26, exploration (spent sets only): alternative centre estimates on position-only frames.

For each frame the shipped estimator reports, the registration and outline objects are captured and the
target centre is computed several ways; rows written as JSON lines with the truth. ``position`` is what the default
bundle reports when the script runs: the session-26 rows (``runs/s26/exp*.jsonl``) were made with session 25's
bundle, before ``position_lateral`` shipped (since then it is ``reg_lat`` on the frames it moves, but for outlines
cut by the frame edge).

    python reports/position_s26/explore.py DATASET --skip S --limit N --out rows.jsonl
"""
from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path

import numpy as np


def _model_mask(R, t, points, observed, frame):
    """The model's outline mask at (R, t) in ``frame``; None when it or ``observed`` has under 10 pixels."""
    from spacepose.silhouette import splat_mask
    mask, _, _ = splat_mask(points, R, t, frame)
    return None if mask.sum() < 10 or observed.sum() < 10 else mask


def lateral_shift(R, t, points, observed, frame):
    """t shifted across the line of sight so the model's silhouette centroid lands on the observed one (unlike
    :func:`spacepose.silhouette.align_centroid`, with no check of outlines cut by the frame's edge)."""
    mask = _model_mask(R, t, points, observed, frame)
    if mask is None:
        return None
    ys, xs = np.nonzero(observed)
    ym, xm = np.nonzero(mask)
    du, dv = xs.mean() - xm.mean(), ys.mean() - ym.mean()   # frame px
    z = float(t[2])
    fx, fy = frame.K[0, 0], frame.K[1, 1]
    return np.asarray(t, float) + np.array([du * z / fx, dv * z / fy, 0.0])


def area_scaled(R, t, points, observed, frame):
    """The pose moved along the line of sight by the ratio of the outlines' areas (area ~ 1 / range^2)."""
    mask = _model_mask(R, t, points, observed, frame)
    return None if mask is None else np.asarray(t, float) * np.sqrt(mask.sum() / observed.sum())


def main() -> None:
    from spacepose.bundle import load_bundle
    from spacepose.calibration.rig import load_rig
    from spacepose.estimator import PoseEstimator
    from spacepose.imageio import read_image
    from spacepose.tools.pose_data import read_pose_labels

    ap = argparse.ArgumentParser()
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--skip", type=int, default=0)
    ap.add_argument("--limit", type=int, default=None)
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    logging.basicConfig(level=logging.WARNING)
    recs = read_pose_labels(args.dataset, "train")[args.skip:]
    if args.limit:
        recs = recs[: args.limit]
    model = load_bundle(None)
    est = PoseEstimator(load_rig(args.dataset / "rig.yaml"), bundle=model, threads=1, use_prior=False)
    centre = np.asarray(model.centre, float)
    cap = {}
    orig_outline = est._outline

    def outline_hook(reg, xyz, stereo, left_r=None):
        out = orig_outline(reg, xyz, stereo, left_r)
        cap.update(reg=reg, outline=out, xyz=xyz)
        return out

    est._outline = outline_hook
    with args.out.open("w") as fh:
        for i, rec in enumerate(recs):
            cap.clear()
            res = est.estimate(read_image(args.dataset / "left" / f"{rec.frame}.png"),
                               read_image(args.dataset / "right" / f"{rec.frame}.png"))
            truth = np.asarray(rec.R) @ centre + np.asarray(rec.t)
            row = {"frame": rec.frame, "regime": rec.regime, "distance": rec.distance_m, "valid": res.valid,
                   "status": res.status, "position_valid": res.position_valid, "tau": res.depth_tolerance_m,
                   "truth": truth.tolist(), "position": np.asarray(res.position).tolist()}
            if "outline" in cap and cap["outline"].frame is not None:
                reg, out = cap["reg"], cap["outline"]
                cands = {"reg": (reg.R, reg.t), "best": (out.best.R, out.best.t)}
                if np.all(np.isfinite(out.other.R)):
                    cands["other"] = (out.other.R, out.other.t)
                for name, (R, t) in list(cands.items()):
                    row[name] = (R @ centre + t).tolist()
                    ts = lateral_shift(R, t, est._outline_points, out.observed, out.frame)
                    if ts is not None:
                        row[name + "_lat"] = (R @ centre + ts).tolist()
                from spacepose.silhouette import polish_pose
                sil = model.silhouette
                for name, (R, t) in (("reg", (reg.R, reg.t)), ("best", (out.best.R, out.best.t))):
                    a = area_scaled(R, t, est._outline_points, out.observed, out.frame)
                    if a is not None:
                        row[name + "_area"] = (R @ centre + a).tolist()
                    pol = polish_pose(out, R, t, est._outline_points, sil, stereo_points=cap["xyz"],
                                      surface=est._registration, tau_m=reg.tau_m)
                    if pol is not None:
                        row[name + "_pol"] = (pol.R @ centre + pol.t).tolist()
                        row[name + "_pol_chamfer"] = float(pol.chamfer_px)
                row["chamfer"] = float(out.best.chamfer_px)
                row["xyz_mean"] = np.asarray(cap["xyz"], float).reshape(-1, 3).mean(0).tolist()
            fh.write(json.dumps(row) + "\n")
            if i % 50 == 0:
                logging.warning("%d/%d", i, len(recs))


if __name__ == "__main__":
    main()
