"""Session 25: would an outline from the left image tell the flip better than the stereo outline?

    python reports/outline_s25/outline_quality.py [DATASET] [FRAMES]    (default data/tdrs640, 300 train frames)

Per frame: the shipped stereo graph's fine pass (no prior), the silhouette frame of its window, and four
outlines over it: the stereo one the runtime uses (disparity above the far end of the labelled distance plus the
stage's depth margin), the ground-truth mask, and the left image above f x its 90th percentile inside the dilated
stereo outline (f 0.2, 0.3), kept inside that dilated outline. Printed:

1. each outline's chamfer (outline px, capped as in the runtime) to the ground-truth mask;
2. against each outline, the labelled pose's splat (the bundle's outline samples) and its 180° flip's: the
   labelled pose's chamfer and the margin flip - truth, and how often the truth wins by >= 0.5 px (the outline
   route's margin) with a chamfer <= 1.5 px (its fit gate).

No refinement: the poses are the labels, so this measures the outlines, not the search.
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np

from spacepose.estimator import PoseEstimator
from spacepose.flip import flipped_pose
from spacepose.image_vote import crop_to_frame, window_grey
from spacepose.imageio import read_image
from spacepose.silhouette import (SilhouetteFrame, _outline_unit, chamfer_px, observed_mask, silhouette_frame,
                                  splat_mask)
from spacepose.tools.pose_data import read_pose_labels

K3 = np.ones((3, 3), np.uint8)


def outlines(obs: np.ndarray, gt: np.ndarray, grey: np.ndarray) -> dict[str, np.ndarray]:
    dil = cv2.dilate(obs, np.ones((5, 5), np.uint8))
    ref = grey[dil > 0]
    p90 = float(np.percentile(ref, 90)) if ref.size else 1.0
    out = {"stereo": obs, "truth mask": gt}
    for f in (0.2, 0.3):
        lit = cv2.morphologyEx((grey > f * p90).astype(np.uint8), cv2.MORPH_CLOSE, K3)
        out[f"image {f} x p90"] = lit & dil
    return out


def main() -> int:
    root = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("data/tdrs640")
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 300
    est = PoseEstimator(root / "rig.yaml", threads=1)
    bundle, cfg = est.bundle, est.bundle.silhouette
    pts = np.asarray(bundle.silhouette_points, dtype=np.float32)
    centre = np.asarray(bundle.centre)
    to_mask, vs_pose = {}, {}
    for rec in read_pose_labels(root, "train")[:n]:
        left = read_image(root / "left" / f"{rec.frame}.png")
        right = read_image(root / "right" / f"{rec.frame}.png")
        st = est.stereo.match(left, right)
        if st.window is None:
            continue
        w = st.window
        frame = silhouette_frame(est.K, w.x0, w.y0, w.side, cfg.max_side_px)
        obs = observed_mask(st.disparity, frame, float(est.K[0, 0]) * est.baseline_m / (rec.distance_m + cfg.depth_margin_m))
        gtm = read_image(root / "mask" / f"{rec.frame}.png")
        gtm = gtm if gtm.ndim == 2 else gtm[..., 0]
        gt = (crop_to_frame(gtm, frame.x0, frame.y0, frame.side, frame.size,
                            convert=lambda b: (b > 0).astype(np.float32)) > 0.5).astype(np.uint8)
        grey = window_grey(left, frame.x0, frame.y0, frame.side, frame.size)
        unit = _outline_unit(frame, cfg)
        view = SilhouetteFrame(0, 0, frame.size, 1.0, frame.K)
        R, t = np.asarray(rec.R), np.asarray(rec.t)
        m_true = splat_mask(pts, R, t, view)[0]
        m_flip = splat_mask(pts, *flipped_pose(R, t, centre, "z"), view)[0]
        for name, o in outlines(obs, gt, grey).items():
            to_mask.setdefault(name, []).append(chamfer_px(o, gt, cfg.trunc_px, unit))
            a = chamfer_px(m_true, o, cfg.trunc_px, unit)
            vs_pose.setdefault(name, []).append((a, chamfer_px(m_flip, o, cfg.trunc_px, unit) - a))
    print(f"{root}, {len(to_mask['stereo'])} train frames")
    print(f"\n{'outline':<18}{'chamfer to the truth mask: median':>36}{'mean':>7}{'<= 1 px':>9}{'<= 1.5 px':>11}")
    for name, v in to_mask.items():
        a = np.array(v)
        print(f"{name:<18}{np.median(a):>36.2f}{a.mean():>7.2f}{np.mean(a <= 1.0):>9.2f}{np.mean(a <= 1.5):>11.2f}")
    print(f"\n{'outline':<18}{'truth chamfer (median)':>24}{'flip - truth (median)':>23}{'truth wins':>12}"
          f"{'by >= 0.5':>11}{'and <= 1.5 px':>15}")
    for name, v in vs_pose.items():
        a = np.array(v)
        print(f"{name:<18}{np.median(a[:, 0]):>24.2f}{np.median(a[:, 1]):>23.2f}{np.mean(a[:, 1] > 0):>12.2f}"
              f"{np.mean(a[:, 1] >= 0.5):>11.2f}{np.mean((a[:, 1] >= 0.5) & (a[:, 0] <= 1.5)):>15.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
