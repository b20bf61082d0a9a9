"""Session 40, exploratory: would a less noisy polish make valid poses more accurate?

    python reports/polish_s40/explore.py DATASET --split train --skip 0 --limit 600 --out ROWS.json.gz
    python reports/polish_s40/explore.py DATASET ... --frames-from ROWS.json.gz --out ROWS2.json.gz  # those frames
    python reports/polish_s40/explore.py --table ROWS.json.gz...

The polish (:func:`spacepose.silhouette.polish_pose`) is one more Gauss-Newton refinement of the decided pose
against the stereo outline. Each of its 8 steps draws a fixed-seed subsample of the contour pairs (800) and of the
stereo points (300), and session 11 found that the refinement jitters rather than converges (10-16 steps moved the
winner by 0.5-1.2 deg median). Valid poses are 1.9 deg off in the median on the test split, so that jitter may be a
part of their error.

The shipped pipeline runs unchanged (use_prior off, as ``eval-pose``); every polish it makes is also recomputed
from the same inputs in these forms, with polish_pose's own caps (15 deg / 1 m from the decided pose):

* ``base``: the shipped polish (checked equal to the reported pose);
* ``seeds5``: the chordal mean of five polishes with the subsample seeds 0-4;
* ``dense``: one polish on every contour pair and up to 3,000 stereo points (no subsample);
* ``long``: 16 steps instead of 8;
* ``none``: the decided pose, unpolished;
* ``truth``: the polish started from the true pose instead of the decided one (where the outline and the stereo
  points would hold a perfect start: the error the data themselves leave);
* ``multi1``, ``multi2`` (with ``--multi``): seven polishes, from the decided pose and from it turned by 1 (2) deg
  either way about each camera axis; the one with the lowest chamfer is kept (polish caps measured from the
  decided pose). Its turn from the decided pose is recorded (``multi*_deg``), since the polish caps read it;
* ``truemask``, ``truemask_truth`` (with ``--truemask``): the polish against the rendered target mask (the
  dataset's ``mask/``, resampled into the decision's silhouette frame as the stereo outline is) instead of the
  stereo outline, from the decided pose and from the truth: what a perfect outline would give (the stereo points
  still weigh in); with it also ``erode1``: the polish against the stereo outline eroded by one pixel (3x3), and the
  stereo outline's area over the rendered mask's (``area_ratio``) and their IoU per frame; and ``lit``: the polish
  against the stereo outline with its outer 2-pixel band cut where the left image is no brighter than the sky
  around it (:func:`lit_outline`), with that outline's IoU against the rendered mask (``iou_lit``); ``lit5``: the
  same with a 5-pixel band (``iou_lit5``).

``--quick`` leaves out ``seeds5``, ``dense`` and ``long``.

Rows: per frame the truth's errors of each form, for the frames whose reported pose is valid and polished.
``--table`` prints mean / median e_t and e_R and the count within 0.10 m and 2 deg per form.
"""
from __future__ import annotations

import argparse
import dataclasses
import gzip
import json
import sys
from pathlib import Path

import cv2
import numpy as np

FORMS = ("base", "seeds5", "dense", "long", "none", "truth", "multi1", "multi2", "truemask", "truemask_truth", "erode1",
         "lit", "lit5")
MULTI = {"multi1": 1.0, "multi2": 2.0}   # start turns (deg) of the multi-start forms


def _chordal_mean(Rs: list[np.ndarray]) -> np.ndarray:
    U, _, Vt = np.linalg.svd(np.sum(Rs, axis=0))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two (n, n) masks (nonzero: inside)."""
    a, b = a > 0, b > 0
    return float((a & b).sum() / max((a | b).sum(), 1))


def lit_outline(stereo: np.ndarray, grey: np.ndarray, band_px: int = 2, margin: float = 0.02,
                min_lit: float = 0.3) -> np.ndarray:
    """(n, n) uint8: the stereo outline ``stereo`` with the pixels of its outer ``band_px`` band removed where the
    left image's ``grey`` (n, n, [0, 1]) is within ``margin`` of the sky ring just outside it (95th percentile) and
    no lit pixel is next to them; unchanged when under ``min_lit`` of the outline is lit (shadow, the Earth behind)."""
    k = np.ones((3, 3), np.uint8)
    st = stereo > 0
    ring = (cv2.dilate(stereo, k, iterations=4) > 0) & ~(cv2.dilate(stereo, k, iterations=1) > 0)
    if not ring.any() or not st.any():
        return stereo
    lit = grey > float(np.percentile(grey[ring], 95)) + margin
    if (lit & st).sum() < min_lit * st.sum():
        return stereo
    band = st & ~(cv2.erode(stereo, k, iterations=band_px, borderType=cv2.BORDER_CONSTANT, borderValue=0) > 0)
    cut = band & ~(cv2.dilate(lit.astype(np.uint8), k) > 0)
    return (st & ~cut).astype(np.uint8)


def run(dataset: str, split: str, skip: int, limit: int, out: str, frames_from: str | None = None,
        quick: bool = False, multi: bool = False, truemask: bool = False) -> None:
    from spacepose import estimator as est_mod
    from spacepose import silhouette as sil_mod
    from spacepose.bundle import load_bundle
    from spacepose.calibration.rig import load_rig
    from spacepose.imageio import read_image
    from spacepose.metrics import rotation_error_deg
    from spacepose.registration import rotation_angle_deg
    from spacepose.tools.pose_data import read_pose_labels

    root = Path(dataset)
    records = read_pose_labels(root, split)[skip: skip + limit]
    if frames_from:   # only the frames another run of this script found valid and polished
        keep = {r["frame"] for r in json.load(gzip.open(frames_from, "rt"))["rows"] if r["polished"]}
        records = [r for r in records if r.frame in keep]
    truth: dict = {}
    model = dataclasses.replace(load_bundle(None), outline_refiner=None)   # the pipeline of session 40 (39's bundle)
    estimator = est_mod.PoseEstimator(load_rig(root / "rig.yaml"), bundle=model, threads=1, use_prior=False)
    calls: list[dict] = []
    original = sil_mod.polish_pose

    def within_caps(fit, R, t, config) -> bool:
        """polish_pose's own caps, measured from (R, t) instead of the start the polish was given."""
        return (float(rotation_angle_deg(R, fit.R)) <= config.polish_max_deg
                and float(np.linalg.norm(fit.t - np.asarray(t))) <= config.polish_max_m)

    def wrapped(decision, R, t, points, config, **kw):
        def polish(dec, R0, t0, cfg=config):
            """(R, t) of polish_pose from (R0, t0), None where it refuses (not finite, or past its caps from there)."""
            fit = original(dec, R0, t0, points, cfg, **kw)
            return None if fit is None else (fit.R, fit.t)

        shipped = original(decision, R, t, points, config, **kw)
        forms = {"base": None if shipped is None else (shipped.R, shipped.t), "none": (np.asarray(R), np.asarray(t))}
        if not quick:
            ok = [f for f in (polish(decision, R, t, dataclasses.replace(config, seed=s)) for s in range(5))
                  if f is not None]
            forms["seeds5"] = ((_chordal_mean([f[0] for f in ok]), np.mean([f[1] for f in ok], axis=0)) if ok
                               else None)
            forms["dense"] = polish(decision, R, t, dataclasses.replace(config, contour_points=1_000_000,
                                                                        stereo_points=3000))
            forms["long"] = polish(decision, R, t, dataclasses.replace(config, iterations=16))
        forms["_base_deg"] = None if forms["base"] is None else float(rotation_angle_deg(R, forms["base"][0]))
        if multi:
            from spacepose.registration import exp_so3
            for name, deg in MULTI.items():
                best = shipped if shipped is not None and np.all(np.isfinite(shipped.R)) else None
                for axis in range(3):
                    for sign in (1.0, -1.0):
                        w = np.zeros(3)
                        w[axis] = sign * np.radians(deg)
                        dR = exp_so3(w)
                        fit = original(decision, dR @ R, dR @ np.asarray(t), points, config, **kw)
                        if (fit is not None and within_caps(fit, R, t, config)
                                and (best is None or fit.chamfer_px < best.chamfer_px)):
                            best = fit
                forms[name] = None if best is None else (best.R, best.t)
                forms[f"_{name}_deg"] = None if best is None else float(rotation_angle_deg(R, best.R))
        if truemask:
            from spacepose.image_vote import crop_to_frame, window_grey
            fr = decision.frame
            obs = (crop_to_frame(truth["mask"], fr.x0, fr.y0, fr.side, fr.size,
                                 convert=lambda box: (box > 127).astype(np.float32)) > 0.5).astype(np.uint8)
            exact = dataclasses.replace(decision, observed=obs)
            forms["truemask"] = polish(exact, R, t)
            forms["truemask_truth"] = polish(exact, truth["R"], truth["t"])
            eroded = cv2.erode(decision.observed, np.ones((3, 3), np.uint8), borderType=cv2.BORDER_CONSTANT,
                               borderValue=0)
            forms["erode1"] = polish(dataclasses.replace(decision, observed=eroded), R, t)
            grey = window_grey(truth["left"], fr.x0, fr.y0, fr.side, fr.size)
            lit = lit_outline(decision.observed, grey)
            forms["lit"] = polish(dataclasses.replace(decision, observed=lit), R, t)
            lit5 = lit_outline(decision.observed, grey, band_px=5)
            forms["lit5"] = polish(dataclasses.replace(decision, observed=lit5), R, t)
            forms["_mask"] = {"iou_lit5": _iou(lit5, obs), "area_ratio": float((decision.observed > 0).sum()
                                                                               / max((obs > 0).sum(), 1)),
                              "iou": _iou(decision.observed, obs), "iou_lit": _iou(lit, obs)}
        from_truth = original(decision, truth["R"], truth["t"], points, config, **kw)
        forms["truth"] = None if from_truth is None else (from_truth.R, from_truth.t)
        forms["_chamfer"] = {k: (None if f is None else float(f.chamfer_px)) for k, f in
                             (("base", shipped), ("truth", from_truth))}
        calls.append(forms)
        return shipped

    est_mod.polish_pose = wrapped
    rows = []
    for i, rec in enumerate(records):
        calls.clear()
        truth.update(R=np.asarray(rec.R, dtype=np.float64), t=np.asarray(rec.t, dtype=np.float64))
        if truemask:
            truth["mask"] = read_image(root / "mask" / f"{rec.frame}.png")
        left = read_image(root / "left" / f"{rec.frame}.png")
        right = read_image(root / "right" / f"{rec.frame}.png")
        truth["left"] = left
        res = estimator.estimate(left, right)
        row = {"frame": rec.frame, "regime": rec.regime, "distance": rec.distance_m, "valid": bool(res.valid),
               "decided_by": res.decided_by, "polished": False}
        if res.valid and calls and calls[-1]["base"] is not None and np.allclose(calls[-1]["base"][0], res.R) \
                and np.allclose(calls[-1]["base"][1], res.t):
            row["polished"] = True
            row["chamfer"] = calls[-1]["_chamfer"]
            if "_mask" in calls[-1]:
                row["mask"] = calls[-1]["_mask"]
            for name in ("base", *MULTI):
                if f"_{name}_deg" in calls[-1]:
                    row[f"{name}_deg"] = calls[-1][f"_{name}_deg"]
            for name in FORMS:
                if name not in calls[-1]:
                    continue
                f = calls[-1][name]
                row[name] = (None if f is None else
                             [float(np.linalg.norm(np.asarray(f[1]) - rec.t)), float(rotation_error_deg(rec.R, f[0]))])
        rows.append(row)
        if (i + 1) % 50 == 0:
            print(f"{i + 1}/{len(records)} frames, {sum(r['polished'] for r in rows)} polished valid", flush=True)
    with gzip.open(out, "wt") as fh:
        json.dump({"dataset": dataset, "split": split, "skip": skip, "limit": limit, "rows": rows}, fh)


def table(paths: list[str]) -> None:
    rows = [r for p in paths for r in json.load(gzip.open(p, "rt"))["rows"] if r["polished"]]
    forms = [f for f in FORMS if all(f in r for r in rows)]
    rows = [r for r in rows if all(r[f] is not None for f in forms)]
    print(f"{len(rows)} valid polished poses with every form")
    print("| form | mean e_t (m) | median e_t | mean e_R (deg) | median e_R | within 0.10 m / 2 deg | e_R > 20 |")
    print("|---|---|---|---|---|---|---|")
    for f in forms:
        e = np.array([r[f] for r in rows])
        within = int(np.sum((e[:, 0] <= 0.10) & (e[:, 1] <= 2.0)))
        print(f"| {f} | {e[:, 0].mean():.4f} | {np.median(e[:, 0]):.4f} | {e[:, 1].mean():.3f} | "
              f"{np.median(e[:, 1]):.3f} | {within} | {int(np.sum(e[:, 1] > 20))} |")
    for name in ("base", *MULTI):
        d = np.array([r[f"{name}_deg"] for r in rows if r.get(f"{name}_deg") is not None])
        if len(d):
            print(f"{name}: its turn from the decided pose: median {np.median(d):.2f} deg, over 2 deg on "
                  f"{int(np.sum(d > 2))}, over 3 deg on {int(np.sum(d > 3))} of {len(d)}")
    m = np.array([(r["mask"]["area_ratio"], r["mask"]["iou"]) for r in rows if r.get("mask")])
    if len(m):
        print(f"stereo outline against the rendered mask: area ratio median {np.median(m[:, 0]):.3f} "
              f"(p10 {np.percentile(m[:, 0], 10):.3f}, p90 {np.percentile(m[:, 0], 90):.3f}), IoU median "
              f"{np.median(m[:, 1]):.3f}")
    for key in ("iou_lit", "iou_lit5"):
        lm = np.array([(r["mask"]["iou"], r["mask"][key]) for r in rows if r.get("mask") and key in r["mask"]])
        if len(lm):
            print(f"IoU against the rendered mask: stereo outline mean {lm[:, 0].mean():.3f}, {key[4:]} outline "
                  f"{lm[:, 1].mean():.3f}; closer on {int(np.sum(lm[:, 1] > lm[:, 0]))} and farther on "
                  f"{int(np.sum(lm[:, 1] < lm[:, 0]))} of {len(lm)} frames")
    ch = [(r["chamfer"]["base"], r["chamfer"]["truth"], r["base"][1], r["truth"][1]) for r in rows
          if r.get("chamfer") and None not in (r["chamfer"]["base"], r["chamfer"]["truth"])]
    if ch:
        c = np.array(ch)
        lower = c[:, 1] < c[:, 0]
        print(f"chamfer (outline px) after the polish: from the decided pose mean {c[:, 0].mean():.3f}, from the truth "
              f"{c[:, 1].mean():.3f}; the truth's start ends with the lower chamfer on {int(lower.sum())} of {len(c)} "
              f"frames (there e_R {c[lower, 2].mean():.2f} -> {c[lower, 3].mean():.2f} deg; elsewhere "
              f"{c[~lower, 2].mean():.2f} -> {c[~lower, 3].mean():.2f})")


if __name__ == "__main__":
    if sys.argv[1] == "--table":
        table(sys.argv[2:])
        sys.exit(0)
    ap = argparse.ArgumentParser()
    ap.add_argument("dataset")
    ap.add_argument("--split", default="train")
    ap.add_argument("--skip", type=int, default=0)
    ap.add_argument("--limit", type=int, default=600)
    ap.add_argument("--out", required=True)
    ap.add_argument("--frames-from", default=None, help="rows of an earlier run: only its valid polished frames")
    ap.add_argument("--quick", action="store_true", help="only base, none and truth (and --multi)")
    ap.add_argument("--multi", action="store_true", help="the multi-start forms too")
    ap.add_argument("--truemask", action="store_true", help="the polish against the rendered mask too")
    a = ap.parse_args()
    run(a.dataset, a.split, a.skip, a.limit, a.out, a.frames_from, a.quick, a.multi, a.truemask)
