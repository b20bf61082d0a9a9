"""Session 41, exploratory: the polish against the refined outline (``refiner.py``) instead of the stereo outline.

    python reports/outline_s41/replay.py DATASET CKPT --split train --skip 0 --limit 600 --out ROWS.json.gz
    python reports/outline_s41/replay.py --table ROWS.json.gz...

Runs the shipped pipeline without its outline refiner (session 39's; use_prior off, as ``eval-pose``); on every
frame whose reported pose is valid and polished, the polish (:func:`spacepose.silhouette.polish_pose`, its own caps) is recomputed from the decided pose
against the refined outline (``refined``) and against the rendered mask (``truemask``, the bound), next to the
shipped one (``base``). Rows: per frame the errors of each form and the outlines' IoU against the mask.
``--table`` prints mean / median e_t and e_R and the count within 0.10 m and 2 deg per form.
"""
from __future__ import annotations

import argparse
import dataclasses
import gzip
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "polish_s40"))
import refiner as rf  # noqa: E402
from explore import _iou  # noqa: E402  (session 40's)

FORMS = ("base", "refined", "refined_w0.5", "refined_w1", "hybrid", "truemask")


def run(dataset: str, ckpt: str, split: str, skip: int, limit: int, out: str) -> None:
    from spacepose import estimator as est_mod
    from spacepose.bundle import load_bundle
    from spacepose.calibration.rig import load_rig
    from spacepose.image_vote import crop_to_frame, window_grey
    from spacepose.imageio import read_image
    from spacepose.metrics import rotation_error_deg
    from spacepose.tools.pose_data import read_pose_labels

    from spacepose.outline_refiner import refined_outline, refiner_planes
    from spacepose.tools.train_outline import GROW, frame_logits

    net = rf._load_net(ckpt)
    model = dataclasses.replace(load_bundle(None), outline_refiner=None)   # the pipeline as before session 41
    root = Path(dataset)
    records = read_pose_labels(root, split)[skip: skip + limit]
    estimator = est_mod.PoseEstimator(load_rig(root / "rig.yaml"), bundle=model, threads=1, use_prior=False)
    orig_decide, orig_polish = est_mod.decide_outline, est_mod.polish_pose
    state: dict = {}

    def decide(candidates, points, disparity, K_full, baseline_m, window, config, **kw):
        decision = orig_decide(candidates, points, disparity, K_full, baseline_m, window, config, **kw)
        distance = float(np.mean([np.linalg.norm(t) for _, t in candidates]))
        min_disp = float(K_full[0, 0]) * float(baseline_m) / max(distance + config.depth_margin_m, 1e-6)
        fr = decision.frame
        state["disp"] = crop_to_frame(np.asarray(disparity, np.float32), fr.x0, fr.y0, fr.side, fr.size) / min_disp
        return decision

    def polish(decision, R, t, points, config, **kw):
        shipped = orig_polish(decision, R, t, points, config, **kw)
        fr = decision.frame
        n = fr.size
        grey = window_grey(state["left"], fr.x0, fr.y0, fr.side, n)
        logit = frame_logits(net, refiner_planes(grey, decision.observed, state["disp"]))
        refined = refined_outline(logit, decision.observed, GROW)
        truth = (crop_to_frame(state["mask"], fr.x0, fr.y0, fr.side, n,
                               convert=lambda box: (box > 127).astype(np.float32)) > 0.5).astype(np.uint8)
        forms = {"base": shipped}
        for name, obs in (("refined", refined), ("truemask", truth)):
            forms[name] = orig_polish(dataclasses.replace(decision, observed=obs), R, t, points, config, **kw)
        for w in (0.5, 1.0):
            forms[f"refined_w{w:g}"] = orig_polish(dataclasses.replace(decision, observed=refined), R, t, points,
                                                   dataclasses.replace(config, polish_range_weight=w), **kw)
        ref = forms["refined"]
        if shipped is not None and ref is not None:     # the refined rotation, the shipped polish's centre
            centre = np.asarray(model.centre, dtype=np.float64)
            c = shipped.R @ centre + shipped.t
            forms["hybrid"] = dataclasses.replace(ref, t=c - ref.R @ centre)
        else:
            forms["hybrid"] = None
        state["forms"] = forms
        state["iou"] = {"stereo": _iou(decision.observed, truth), "refined": _iou(refined, truth)}
        return shipped

    est_mod.decide_outline, est_mod.polish_pose = decide, polish
    rows = []
    for i, rec in enumerate(records):
        state.pop("forms", None)
        state["left"] = read_image(root / "left" / f"{rec.frame}.png")
        state["mask"] = read_image(root / "mask" / f"{rec.frame}.png")
        res = estimator.estimate(state["left"], read_image(root / "right" / f"{rec.frame}.png"))
        row = {"frame": rec.frame, "regime": rec.regime, "distance": rec.distance_m, "valid": bool(res.valid),
               "polished": False}
        f = state.get("forms")
        if res.valid and f and f["base"] is not None and np.allclose(f["base"].R, res.R) \
                and np.allclose(f["base"].t, res.t):
            row["polished"] = True
            row["iou"] = state["iou"]
            for name in FORMS:
                fit = f[name]
                los = np.asarray(rec.t, dtype=np.float64) / np.linalg.norm(rec.t)
                row[name] = (None if fit is None else [float(np.linalg.norm(fit.t - rec.t)),
                                                       float(rotation_error_deg(rec.R, fit.R)),
                                                       float(np.dot(fit.t - rec.t, los))])
        rows.append(row)
        if (i + 1) % 50 == 0:
            print(f"{i + 1}/{len(records)} frames, {sum(r['polished'] for r in rows)} polished valid", flush=True)
    with gzip.open(out, "wt") as fh:
        json.dump({"dataset": dataset, "ckpt": ckpt, "split": split, "skip": skip, "limit": limit, "rows": rows}, fh)


def table(paths: list[str]) -> None:
    rows = [r for p in paths for r in json.load(gzip.open(p, "rt"))["rows"] if r["polished"]]
    print(f"{len(rows)} valid polished poses ({', '.join(paths)})")
    print("| form | poses | mean e_t | mean signed range error | mean / median e_R | within 0.10 m / 2 deg | median IoU |")
    print("|---|---|---|---|---|---|---|")
    for name in FORMS:
        if any(name not in r for r in rows):
            continue
        # a form that refused (past the polish caps, not finite) leaves the shipped pose
        e = np.array([(r[name] if r[name] is not None else r["base"]) + [np.nan] * 3 for r in rows])[:, :3]
        within = int(((e[:, 0] <= 0.10) & (e[:, 1] <= 2.0)).sum())
        io = {"base": "stereo", "refined": "refined", "truemask": None}.get(name, "refined")
        med = f"{np.median([r['iou'][io] for r in rows]):.3f}" if io else "1"
        print(f"| {name} | {len(e)} | {e[:, 0].mean():.3f} m | {np.nanmean(e[:, 2]):+.3f} m | {e[:, 1].mean():.2f} / "
              f"{np.median(e[:, 1]):.2f} | {within} | {med} |")


def main(argv: list[str]) -> int:
    if argv[:1] == ["--table"]:
        table(argv[1:])
        return 0
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("dataset")
    p.add_argument("ckpt")
    p.add_argument("--split", default="train")
    p.add_argument("--skip", type=int, default=0)
    p.add_argument("--limit", type=int, default=600)
    p.add_argument("--out", required=True)
    a = p.parse_args(argv)
    import torch
    torch.set_num_threads(1)
    run(a.dataset, a.ckpt, a.split, a.skip, a.limit, a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
