"""Session 42, exploratory: is the range of a valid pose limited by a per-frame bias of the stereo disparity, and
can the images themselves measure that bias?

    python reports/range_s42/explore.py DATASET --split test --skip 0 --limit 300 --out ROWS.json.gz
    python reports/range_s42/explore.py --table ROWS.json.gz...

Runs the shipped pipeline (use_prior off, as ``eval-pose``). On every valid frame it records the pose's range error
(metres, and in disparity at the target's centre), the stereo disparity's mean and median error on the rendered
mask, and the per-frame disparity offsets that make the right image, warped by the stereo disparity plus the
offset, match the left one best over the target's pixels (pixels whose stereo point lies within the target's
radius of the pose's centre), for a few costs.
"""
from __future__ import annotations

import argparse
import gzip
import json
import sys
from pathlib import Path

import cv2
import numpy as np

OFFSETS = np.round(np.arange(-1.5, 1.5001, 0.05), 3)


def _grey(img: np.ndarray) -> np.ndarray:
    from spacepose.photometric import to_grey_float
    return to_grey_float(img)


def _highpass(g: np.ndarray, k: int) -> np.ndarray:
    return g - cv2.blur(g, (k, k))


def offset_costs(left_r, right_r, disp, pix, k: int = 9) -> dict[str, np.ndarray]:
    """Per offset in OFFSETS, costs of the right image warped by disp + offset against the left on pixels pix."""
    ys, xs = pix
    y0, y1, x0, x1 = ys.min() - 8, ys.max() + 9, xs.min() - 8, xs.max() + 9
    gl, gr = _grey(left_r), _grey(right_r)
    hl, hr = _highpass(gl, k), _highpass(gr, k)
    h, w = gl.shape
    y0, x0 = max(y0, 0), max(x0, 0)
    y1, x1 = min(y1, h), min(x1, w)
    sub = (slice(y0, y1), slice(x0, x1))
    yy, xx = np.mgrid[y0:y1, x0:x1].astype(np.float32)
    m = np.zeros((h, w), bool)
    m[ys, xs] = True
    m = m[sub]
    a = hl[sub][m]
    ga = gl[sub][m]
    out = {"ssd_hp": [], "zncc_hp": [], "sad_grad": []}
    gxl = cv2.Sobel(gl, cv2.CV_32F, 1, 0, ksize=3)[sub][m]
    gxr_full = cv2.Sobel(gr, cv2.CV_32F, 1, 0, ksize=3)
    for off in OFFSETS:
        mx = xx - disp[sub] - np.float32(off)
        b = cv2.remap(hr, mx, yy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)[m]
        out["ssd_hp"].append(float(np.mean((a - b) ** 2)))
        za, zb = a - a.mean(), b - b.mean()
        out["zncc_hp"].append(-float(np.sum(za * zb) / max(np.sqrt(np.sum(za**2) * np.sum(zb**2)), 1e-12)))
        gb = cv2.remap(gxr_full, mx, yy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)[m]
        out["sad_grad"].append(float(np.mean(np.abs(gxl - gb))))
    return {k2: np.asarray(v) for k2, v in out.items()}


def model_residual(R, t, surface, disp, K, fB, cell_px: float = 3.0, depth_tol: float = 0.25,
                   max_abs: float = 3.0) -> tuple[float | None, int]:
    """Median of observed minus model disparity over the target's visible surface samples at (R, t)."""
    from spacepose.photometric import visible_mask as _visible
    pts = surface @ R.T + t
    z = pts[:, 2]
    u = K[0, 0] * pts[:, 0] / z + K[0, 2]
    v = K[1, 1] * pts[:, 1] / z + K[1, 2]
    h, w = disp.shape
    inside = (u >= 0) & (u <= w - 1) & (v >= 0) & (v <= h - 1) & (z > 0)
    u, v, z = u[inside], v[inside], z[inside]
    vis = _visible(np.stack([u, v], 1), z, cell_px, depth_tol)
    u, v, z = u[vis], v[vis], z[vis]
    obs = cv2.remap(disp.astype(np.float32), u.astype(np.float32)[None], v.astype(np.float32)[None],
                    cv2.INTER_LINEAR)[0]
    r = obs - fB / z
    ok = (obs > 0) & (np.abs(r) < max_abs)
    if ok.sum() < 30:
        return None, int(ok.sum())
    return float(np.median(r[ok])), int(ok.sum())


def range_corrected(R, t, surface, disp, K, fB, centre, steps: int = 2):
    """t moved along its line of sight until the median model residual is zero (steps times)."""
    t = np.asarray(t, np.float64).copy()
    for _ in range(steps):
        delta, n = model_residual(R, t, surface, disp, K, fB)
        if delta is None:
            return None, n
        zc = float((R @ centre + t)[2])
        t = t * (fB / zc) / (fB / zc + delta)
    return t, n


def best_offset(costs: np.ndarray) -> float:
    i = int(np.argmin(costs))
    if 0 < i < len(costs) - 1:
        c0, c1, c2 = costs[i - 1], costs[i], costs[i + 1]
        den = c0 - 2 * c1 + c2
        frac = 0.5 * (c0 - c2) / den if den > 0 else 0.0
        return float(OFFSETS[i] + frac * (OFFSETS[1] - OFFSETS[0]))
    return float(OFFSETS[i])


def run(dataset: str, split: str, skip: int, limit: int, out: str, dump: str | None = None) -> None:
    from spacepose import estimator as est_mod
    from spacepose.calibration.rig import load_rig
    from spacepose.imageio import read_image, read_pfm
    from spacepose.metrics import rotation_error_deg
    from spacepose.tools.pose_data import read_pose_labels

    root = Path(dataset)
    records = read_pose_labels(root, split)[skip: skip + limit]
    est = est_mod.PoseEstimator(load_rig(root / "rig.yaml"), bundle=None, threads=1, use_prior=False)
    state: dict = {}
    orig_match, orig_pair = est.stereo.match, est._pose_from_pair

    def match(left_r, right_r, roi_hint=None):
        res = orig_match(left_r, right_r, roi_hint=roi_hint)
        state["disp"] = res.disparity
        return res

    def pair(left_r, right_r, hint, timer):
        state["left_r"], state["right_r"] = left_r, right_r
        return orig_pair(left_r, right_r, hint, timer)

    est.stereo.match, est._pose_from_pair = match, pair
    fB = est.focal_px * est.baseline_m
    K = est.K
    centre = np.asarray(est.bundle.centre, np.float64)
    radius = float(est.bundle.radius)
    rows = []
    for i, rec in enumerate(records):
        left = read_image(root / "left" / f"{rec.frame}.png")
        res = est.estimate(left, read_image(root / "right" / f"{rec.frame}.png"))
        row = {"frame": rec.frame, "regime": rec.regime, "distance": rec.distance_m, "valid": bool(res.valid)}
        if res.valid:
            gt_disp = read_pfm(root / "disparity" / f"{rec.frame}.pfm")
            disp = state["disp"]
            on = gt_disp > 0
            err = disp[on] - gt_disp[on]
            c = res.R @ centre + res.t
            c_gt = np.asarray(rec.R) @ centre + np.asarray(rec.t)
            los = np.asarray(rec.t) / np.linalg.norm(rec.t)
            row.update(e_t=float(np.linalg.norm(res.t - rec.t)), range_err=float(np.dot(res.t - rec.t, los)),
                       dd_pose=float(fB / c[2] - fB / c_gt[2]), z=float(c[2]), z_gt=float(c_gt[2]),
                       net_bias_mean=float(err.mean()), net_bias_median=float(np.median(err)),
                       e_R=float(rotation_error_deg(rec.R, res.R)))
            if dump:
                Path(dump).mkdir(parents=True, exist_ok=True)
                np.savez_compressed(Path(dump) / f"{rec.frame}.npz", disp=disp, gt_disp=gt_disp, R=res.R, t=res.t,
                                    R_gt=np.asarray(rec.R), t_gt=np.asarray(rec.t),
                                    left=_grey(state["left_r"]).astype(np.float16),
                                    right=_grey(state["right_r"]).astype(np.float16))
            surface = np.asarray(est.bundle.surface_points, np.float64)
            for name, dmap in (("model", disp), ("model_gt", gt_disp)):
                delta, n = model_residual(res.R, res.t, surface, dmap, K, fB)
                row[f"delta_{name}"], row[f"n_{name}"] = delta, n
                tc, _ = range_corrected(res.R, res.t, surface, dmap, K, fB, centre)
                row[f"e_t_{name}"] = None if tc is None else float(np.linalg.norm(tc - rec.t))
                row[f"range_err_{name}"] = None if tc is None else float(np.dot(tc - rec.t, los))
            # the target's pixels by the pose: stereo points within the radius of its centre
            h, w = disp.shape
            ys, xs = np.nonzero(disp > 0.5)
            Z = fB / disp[ys, xs]
            X = np.stack([(xs - K[0, 2]) * Z / K[0, 0], (ys - K[1, 2]) * Z / K[1, 1], Z], 1)
            near = np.linalg.norm(X - c, axis=1) <= radius
            ys, xs = ys[near], xs[near]
            row["pixels"] = int(len(ys))
            row["pix_in_mask"] = float(on[ys, xs].mean()) if len(ys) else 0.0
            if len(ys) >= 50:
                costs = offset_costs(state["left_r"], state["right_r"], disp, (ys, xs))
                row["offsets"] = {k: best_offset(v) for k, v in costs.items()}
                # the bias on the same pixels (those in the mask)
                inm = on[ys, xs]
                row["net_bias_pix"] = float(np.mean(disp[ys, xs][inm] - gt_disp[ys, xs][inm])) if inm.any() else None
                # the oracle: the same cost with the exact disparity
                gcosts = offset_costs(state["left_r"], state["right_r"], gt_disp, (ys, xs))
                row["offsets_gt"] = {k: best_offset(v) for k, v in gcosts.items()}
        rows.append(row)
        if (i + 1) % 25 == 0:
            print(f"{i + 1}/{len(records)}, {sum(r['valid'] for r in rows)} valid", flush=True)
    with gzip.open(out, "wt") as fh:
        json.dump({"dataset": dataset, "split": split, "skip": skip, "limit": limit, "rows": rows}, fh)


def table(paths: list[str]) -> None:
    rows = [r for p in paths for r in json.load(gzip.open(p, "rt"))["rows"] if r["valid"] and "offsets" in r]
    dd = np.array([r["dd_pose"] for r in rows])
    nb = np.array([r["net_bias_pix"] if r["net_bias_pix"] is not None else np.nan for r in rows])
    print(f"{len(rows)} valid poses with pixels; pose range error in disparity: std {dd.std():.3f}")
    e_t = np.array([r["e_t"] for r in rows])
    rng = np.abs([r["range_err"] for r in rows])
    print(f"their mean e_t {e_t.mean():.3f} m, of which along the line of sight: mean |range error| {rng.mean():.3f} m; "
          f"mean disparity error on the target's pixels: spread over the frames {np.nanstd(nb):.3f} px")
    print(f"corr(dd_pose, net bias on target pixels) {np.corrcoef(dd[np.isfinite(nb)], nb[np.isfinite(nb)])[0, 1]:.3f}")
    for k in rows[0]["offsets"]:
        off = np.array([r["offsets"][k] for r in rows])
        offg = np.array([r["offsets_gt"][k] for r in rows])
        f = np.isfinite(nb)
        print(f"{k}: corr(offset, -net bias) {np.corrcoef(off[f], -nb[f])[0, 1]:.3f}; "
              f"resid std(nb+off) {np.std(nb[f] + off[f]):.3f} vs std(nb) {np.std(nb[f]):.3f}; "
              f"gt-disp offset mean {offg.mean():+.3f} std {offg.std():.3f}; "
              f"dd_pose+off std {np.std(dd + off):.3f} (dd {dd.std():.3f})")


def table2(paths: list[str]) -> None:
    rows = [r for p in paths for r in json.load(gzip.open(p, "rt"))["rows"] if r["valid"]]
    print(f"{len(rows)} valid poses")
    print("| form | poses | mean e_t | median e_t | range err std | e_t <= 0.10 m | within 0.10 m / 2 deg |")
    print("|---|---|---|---|---|---|---|")
    for form in ("", "_model", "_model_gt"):
        e = np.array([r["e_t" + form] if r.get("e_t" + form) is not None else r["e_t"] for r in rows])
        rr = np.array([r["range_err" + form] if r.get("range_err" + form) is not None else r["range_err"] for r in rows])
        eR = np.array([r["e_R"] for r in rows])
        print(f"| {form or 'shipped'} | {len(e)} | {e.mean():.3f} | {np.median(e):.3f} | {rr.std():.3f} | "
              f"{(e <= 0.1).sum()} | {((e <= 0.1) & (eR <= 2)).sum()} |")


def main(argv: list[str]) -> int:
    if argv[:1] == ["--table"]:
        table(argv[1:])
        table2(argv[1:])
        return 0
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("dataset")
    p.add_argument("--split", default="test")
    p.add_argument("--skip", type=int, default=0)
    p.add_argument("--limit", type=int, default=300)
    p.add_argument("--out", required=True)
    p.add_argument("--dump", help="a folder for each valid frame's disparity, images and poses (npz)")
    a = p.parse_args(argv)
    run(a.dataset, a.split, a.skip, a.limit, a.out, a.dump)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
