"""Session 42, exploratory: the product's range fit (:func:`spacepose.range_fit.fit_range`) replayed on the valid
frames dumped by ``explore.py --dump`` (the shipped pipeline's pose, disparity and rectified grey images).

    python reports/range_s42/replay.py DUMP_DIR [DUMP_DIR...]

Prints, per dump folder, the mean / median e_t of the valid poses and the counts within 0.10 m and within
0.10 m / 2 deg: as shipped, after the fit with RangeFitConfig's defaults, and after the same fit started from the
rendered disparity instead of the stereo graph's (what the matching leaves when the graph is exact).
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np


def main(folders: list[str]) -> None:
    from spacepose.bundle import load_bundle
    from spacepose.metrics import rotation_error_deg
    from spacepose.range_fit import RangeFitConfig, fit_range

    bundle = load_bundle(None, verify_graphs=False)
    surface, centre = np.asarray(bundle.surface_points, np.float64), np.asarray(bundle.centre, np.float64)
    f = bundle.rig.focal_px
    K = np.array([[f, 0.0, 319.5], [0.0, f, 239.5], [0.0, 0.0, 1.0]])
    config = RangeFitConfig()
    print("| set | form | poses | mean e_t | median e_t | e_t <= 0.10 m | within 0.10 m / 2 deg | fit not applied |")
    print("|---|---|---|---|---|---|---|---|")
    for folder in folders:
        errs: dict[str, list] = {"shipped": [], "fit": [], "fit from rendered disparity": []}
        missed = {k: 0 for k in errs}
        for path in sorted(Path(folder).glob("*.npz")):
            z = np.load(path)
            R, t, t_gt = z["R"], z["t"], z["t_gt"]
            e_r = float(rotation_error_deg(z["R_gt"], R))
            left, right = z["left"].astype(np.float32), z["right"].astype(np.float32)
            errs["shipped"].append((float(np.linalg.norm(t - t_gt)), e_r))
            for name, disp in (("fit", z["disp"]), ("fit from rendered disparity", z["gt_disp"])):
                fit = fit_range(R, t, centre, surface, left, right, disp, K, bundle.rig.baseline_m, config)
                missed[name] += fit.t is None
                errs[name].append((float(np.linalg.norm((t if fit.t is None else fit.t) - t_gt)), e_r))
        for name, rows in errs.items():
            e = np.array(rows)
            print(f"| {Path(folder).name} | {name} | {len(e)} | {e[:, 0].mean():.3f} m | {np.median(e[:, 0]):.3f} m | "
                  f"{int((e[:, 0] <= 0.1).sum())} | {int(((e[:, 0] <= 0.1) & (e[:, 1] <= 2.0)).sum())} | "
                  f"{missed[name]} |")


if __name__ == "__main__":
    main(sys.argv[1:])
