"""Session 37: would the outline's own range catch the range errors another look causes? Measured: no.

    python reports/look_s37/range_check.py run DATASET OUT.json.gz SKIP LIMIT     # eval-pose rows + the check
    python reports/look_s37/range_check.py table ROWS.json.gz...                  # the comparison

The three wrong poses of the restyled test split (model card, "Another look") are range errors at a good outline fit
(chamfer 1.0-1.2 px). The decision refines the outline with ``range_weight`` 0 (the range from the stereo points
only), so the outline's apparent size could be an independent check. ``run`` evaluates like ``spacepose eval-pose``
(test split, the shipped bundle) and, for every frame with an outline decision, refines the reported pose once more
against the outline alone (``range_weight`` 1, no stereo points) and records how far that moves the target's centre
along the line of sight (``d_los_outline``, m). The session-37 runs (two halves per set):

    python reports/look_s37/range_check.py run data/tdrs640_restyle /tmp/s37/diag_rest_0.json.gz 0 150   (and 150;
        and data/tdrs640 -> /tmp/s37/diag_plain_{0,150}.json.gz)
    python reports/look_s37/range_check.py table /tmp/s37/diag_{rest,plain}_{0,150}.json.gz
"""
from __future__ import annotations

import dataclasses
import gzip
import json
import sys

import numpy as np

KEEP = ("frame", "regime", "distance", "valid", "status", "confidence", "e_t", "e_R", "e_pos_los", "sigma_range_m",
        "outline_chamfer_px", "decided_by")


def run(dataset: str, out: str, skip: int, limit: int) -> None:
    from spacepose.estimator import PoseEstimator
    from spacepose.silhouette import refine_outline
    from spacepose.tools.eval_pose import evaluate_pose

    extra: list[dict] = []
    polish, estimate = PoseEstimator._polish, PoseEstimator.estimate

    def checked_polish(self, outline, R, t, xyz, reg, factors, timer):
        decided, R2, t2 = polish(self, outline, R, t, xyz, reg, factors, timer)
        if outline is not None and outline.observed is not None and outline.frame is not None:
            fit = refine_outline(R2, t2, self._outline_points, outline.observed, outline.frame,
                                 dataclasses.replace(self.bundle.silhouette, range_weight=1.0))
            c = np.asarray(self.bundle.centre, float)
            c_rep, c_out = R2 @ c + t2, fit.R @ c + fit.t
            extra[-1].update(d_los_outline=float((c_out - c_rep) @ (c_rep / np.linalg.norm(c_rep))),
                             outline_only_chamfer=float(fit.chamfer_px))
        return decided, R2, t2

    def counted_estimate(self, *args, **kwargs):
        extra.append({})
        return estimate(self, *args, **kwargs)

    PoseEstimator._polish, PoseEstimator.estimate = checked_polish, counted_estimate
    rows = evaluate_pose(dataset, None, skip=skip, limit=limit, threads=1, split="test", overlays=0)["frames"]
    with gzip.open(out, "wt") as fh:
        json.dump([{**{k: r[k] for k in KEEP}, **x} for r, x in zip(rows, extra)], fh)


def table(paths: list[str]) -> None:
    rows = [r for p in paths for r in json.load(gzip.open(p, "rt"))]
    valid = [r for r in rows if r["valid"] and "d_los_outline" in r]
    wrong = [r for r in valid if r["e_t"] > 0.5 or r["e_R"] > 20.0]
    right = [r for r in valid if not (r["e_t"] > 0.5 or r["e_R"] > 20.0)]
    rep = np.array([r["e_pos_los"] for r in valid])
    out = rep + np.array([r["d_los_outline"] for r in valid])
    print(f"{len(rows)} frames, {len(valid)} valid poses with an outline decision, {len(wrong)} wrong")
    print(f"mean |range error| of the reported poses {np.abs(rep).mean():.3f} m; of the outline-only refits "
          f"{np.abs(out).mean():.3f} m (mean signed {out.mean():+.3f} m)")
    z = np.array([abs(r["d_los_outline"]) / r["sigma_range_m"] for r in right])
    print(f"right poses: |outline - reported| in range sigmas, median {np.median(z):.2f}, "
          f"over 3: {int((z > 3).sum())} of {len(z)}, over 4: {int((z > 4).sum())}")
    for r in wrong:
        print(f"wrong {r['frame']}: range error {r['e_pos_los']:+.2f} m, outline-only {r['e_pos_los'] + r['d_los_outline']:+.2f}"
              f" m, |outline - reported| {abs(r['d_los_outline']) / r['sigma_range_m']:.2f} range sigmas")


if __name__ == "__main__":
    if sys.argv[1] == "run":
        run(sys.argv[2], sys.argv[3], int(sys.argv[4]), int(sys.argv[5]))
    else:
        table(sys.argv[2:])
