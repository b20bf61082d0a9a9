"""Evaluate the full flight pipeline (images -> PoseEstimator -> pose) on a dataset's test split.

Per frame the runtime :class:`spacepose.estimator.PoseEstimator` (no pose prior between frames:
the dataset's frames are independent) sees the raw stereo pair; errors against the label use
:mod:`spacepose.metrics` (paper eqs. 32-33: e_t in m, e_R in degrees; ADD in m over model surface
points; the SPEED score ``||Δt|| / ||t|| + angle`` in rad). Reported over the valid frames, per
regime and per 10 m distance bin: mean and median e_t / e_R / ADD, mean SPEED score, the valid
fraction, and the count of valid frames with e_R > 90° ("flips", symmetric-looking targets);
``e_R_sym``: e_R to the nearer of the label and its 180° flip about the bundle's ``voting.flip_axis``
(how good the orientation is up to that near-symmetry; equal to e_R without a flip axis).
Target position without attitude (``PoseResult.position_valid``): the share of frames with a usable
position, ``e_pos`` = distance (m) of the reported centre to the labelled one (mean, median, 95th
percentile), the share of those within the frame's ``depth_tolerance_m``, and ``e_pos_los``: the signed part of the
error along the line of sight to the labelled centre (positive: too far; its mean is the range bias).
Also: an error-vs-confidence table (quantile bins of confidence, with the mean confidence and the share of poses
within the pose bar, 0.10 m and 2 degrees, that the default bundle's confidence predicts), Fig. 14-style scatter plots
(e_t and e_R against distance) and Fig. 15-style overlays (projected 3-D box; white = GT, green =
estimate). ``baseline="classical"`` adds :func:`spacepose.tools.classical_pose.estimate_classical`
(SGBM + FPFH/RANSAC + ICP; needs Open3D, the ``[baseline]`` extra) on the rectified pair.
"""

from __future__ import annotations

import json
import logging
import math
import time
from pathlib import Path
from typing import Any, Callable, Iterable

import numpy as np

from spacepose.errors import DatasetError
from spacepose.imageio import read_image, write_image

log = logging.getLogger(__name__)

__all__ = ["FLIP_DEG", "BAR_T_M", "BAR_R_DEG", "DISTANCE_BIN_M", "evaluate_pose", "predicted_sigmas", "summarise", "confidence_table", "distance_bin",
           "format_tables", "save_scatter", "draw_box_overlay", "write_report", "model_points"]

FLIP_DEG = 90.0
BAR_T_M, BAR_R_DEG = 0.10, 2.0   # the pose bar of issue 6 (mean errors); per pose, the event the confidence predicts
DISTANCE_BIN_M = 10.0


def distance_bin(z: float, width: float = DISTANCE_BIN_M) -> str:
    lo = int(math.floor(z / width) * width)
    return f"{lo}-{lo + int(width)}m"


def model_points(target: str, fallback: np.ndarray, n: int = 2000, seed: int = 0) -> np.ndarray:
    """Surface samples of the target mesh (for ADD); ``fallback`` (e.g. keypoints) without the mesh."""
    try:
        import trimesh

        from spacepose.tools.targets import load_target

        pts, _ = trimesh.sample.sample_surface(load_target(target).mesh, n, seed=seed)
        return np.asarray(pts, dtype=np.float64)
    except Exception as err:  # unknown target / no trimesh: ADD over the fallback points
        log.warning("ADD over %d fallback points (%s)", len(fallback), err)
        return np.asarray(fallback, dtype=np.float64)


def _errors(R: np.ndarray, t: np.ndarray, R_hat: np.ndarray, t_hat: np.ndarray, pts: np.ndarray) -> dict[str, float]:
    from spacepose.metrics import add, rotation_error_deg, speed_score, translation_error

    return {"e_t": translation_error(t, t_hat), "e_R": rotation_error_deg(R, R_hat), "add": add(R, t, R_hat, t_hat, pts),
            "speed": speed_score(R, t, R_hat, t_hat)}


def predicted_sigmas(result: Any) -> dict[str, float]:
    """The result's predicted sigmas (:mod:`spacepose.uncertainty`): along and across the line of sight to
    its position (from ``position_cov``) and of the rotation; NaN where it has none."""
    cov, pos = np.asarray(result.position_cov, dtype=np.float64), np.asarray(result.position, dtype=np.float64)
    if not (np.all(np.isfinite(cov)) and np.all(np.isfinite(pos)) and np.linalg.norm(pos) > 0):
        return {"sigma_range_m": float("nan"), "sigma_lateral_m": float("nan"), "sigma_rotation_deg": float("nan")}
    u = pos / np.linalg.norm(pos)
    along = float(u @ cov @ u)
    return {"sigma_range_m": math.sqrt(max(along, 0.0)),
            "sigma_lateral_m": math.sqrt(max((float(np.trace(cov)) - along) / 2.0, 0.0)),
            "sigma_rotation_deg": float(result.sigma_rotation_deg)}


def _nanstat(fn: Callable, values: list[float]) -> float:
    return float(fn(values)) if values else float("nan")


def summarise(rows: Iterable[dict[str, Any]]) -> dict[str, Any]:
    """Aggregate per-frame rows (keys valid, e_t, e_R, add, speed) into the report numbers."""
    rows = list(rows)
    ok = [r for r in rows if r["valid"]]
    out: dict[str, Any] = {"frames": len(rows), "valid": len(ok), "valid_fraction": len(ok) / len(rows) if rows else float("nan")}
    for key in ("e_t", "e_R", "e_R_sym", "add"):
        vals = [r[key] for r in ok if key in r]
        out[f"{key}_mean"] = _nanstat(np.mean, vals)
        out[f"{key}_median"] = _nanstat(np.median, vals)
    out["speed_score"] = _nanstat(np.mean, [r["speed"] for r in ok])
    pos = [r for r in rows if r.get("position_valid")]
    e_pos = [r["e_pos"] for r in pos]
    out["position_valid"] = len(pos)
    out["position_fraction"] = len(pos) / len(rows) if rows else float("nan")
    out["e_pos_mean"] = _nanstat(np.mean, e_pos)
    out["e_pos_median"] = _nanstat(np.median, e_pos)
    out["e_pos_p95"] = _nanstat(lambda v: np.percentile(v, 95), e_pos)
    out["e_pos_max"] = _nanstat(np.max, e_pos)
    out["e_pos_within_tolerance"] = _nanstat(np.mean, [float(r["e_pos"] <= r["depth_tolerance_m"]) for r in pos])
    out["e_pos_los_mean"] = _nanstat(np.mean, [r["e_pos_los"] for r in pos if "e_pos_los" in r])
    out["flips"] = sum(1 for r in ok if r["e_R"] > FLIP_DEG)
    statuses: dict[str, int] = {}
    for r in rows:
        statuses[r["status"]] = statuses.get(r["status"], 0) + 1
    out["statuses"] = statuses
    return out


def confidence_table(rows: Iterable[dict[str, Any]], n_bins: int = 4) -> list[dict[str, Any]]:
    """Valid frames split into ``n_bins`` confidence quantile bins (highest first): errors per bin, the mean
    confidence and the share within the pose bar (``e_t`` <= :data:`BAR_T_M`, ``e_R`` <= :data:`BAR_R_DEG`: what
    the default bundle's confidence predicts, :mod:`spacepose.confidence`)."""
    ok = sorted((r for r in rows if r["valid"]), key=lambda r: -r["confidence"])
    if not ok:
        return []
    out = []
    for chunk in np.array_split(np.arange(len(ok)), min(n_bins, len(ok))):
        sel = [ok[i] for i in chunk]
        conf = [r["confidence"] for r in sel]
        out.append({"confidence_min": float(min(conf)), "confidence_max": float(max(conf)), "frames": len(sel),
                    "e_t_median": float(np.median([r["e_t"] for r in sel])),
                    "e_R_median": float(np.median([r["e_R"] for r in sel])),
                    "e_t_mean": float(np.mean([r["e_t"] for r in sel])),
                    "e_R_mean": float(np.mean([r["e_R"] for r in sel])),
                    "flips": sum(1 for r in sel if r["e_R"] > FLIP_DEG),
                    "confidence_mean": float(np.mean(conf)),
                    "within_bar": float(np.mean([r["e_t"] <= BAR_T_M and r["e_R"] <= BAR_R_DEG for r in sel]))})
    return out


def _grouped(rows: list[dict[str, Any]]) -> dict[str, Any]:
    groups: dict[str, list] = {}
    for r in rows:
        groups.setdefault(f"regime:{r['regime']}", []).append(r)
        groups.setdefault(f"distance:{distance_bin(r['distance'])}", []).append(r)
    from spacepose.tools.calibrate_uncertainty import coverage, pose_errors, position_coverage, position_errors

    return {"overall": summarise(rows), **{k: summarise(v) for k, v in sorted(groups.items())},
            "confidence": confidence_table(rows), "uncertainty": coverage(pose_errors(rows)),
            "position_uncertainty": position_coverage(position_errors(rows))}


def draw_box_overlay(image: np.ndarray, K: np.ndarray, corners: np.ndarray, poses: list[tuple[np.ndarray, np.ndarray, tuple]],
                     thickness: int = 1) -> np.ndarray:
    """Draw the 12 edges of the projected box ``corners`` (8, 3) for each (R, t, BGR-less RGB colour)."""
    import cv2

    out = np.ascontiguousarray(image if image.ndim == 3 else np.repeat(image[..., None], 3, axis=2)).copy()
    edges = [(i, j) for i in range(8) for j in range(i + 1, 8) if bin(i ^ j).count("1") == 1]
    for R, t, colour in poses:
        if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
            continue
        cam = corners @ np.asarray(R).T + np.asarray(t)
        if np.any(cam[:, 2] <= 0):
            continue
        uv = cam @ np.asarray(K).T
        uv = uv[:, :2] / uv[:, 2:3]
        for i, j in edges:
            p, q = uv[i], uv[j]
            cv2.line(out, (int(round(p[0])), int(round(p[1]))), (int(round(q[0])), int(round(q[1]))), colour, thickness,
                     cv2.LINE_AA)
    return out


def save_scatter(rows: list[dict[str, Any]], path: str | Path, title: str = "") -> None:
    """Fig. 14-style: e_t and e_R of the valid frames against target distance."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = [r for r in rows if r["valid"]]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    z = [r["distance"] for r in ok]
    axes[0].scatter(z, [r["e_t"] for r in ok], s=8)
    axes[0].set_xlabel("target distance Z (m)")
    axes[0].set_ylabel("e_t (m)")
    axes[1].scatter(z, [r["e_R"] for r in ok], s=8, color="tab:orange")
    axes[1].set_xlabel("target distance Z (m)")
    axes[1].set_ylabel("e_R (deg)")
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.suptitle(title or f"{len(ok)} valid of {len(rows)} test frames")
    fig.tight_layout()
    fig.savefig(str(path), dpi=120)
    plt.close(fig)


def evaluate_pose(dataset: str | Path, bundle: str | Path | None = None, *, limit: int | None = None,
                  skip: int = 0, baseline: str | None = None, threads: int = 2, split: str = "test", overlays: int = 6,
                  out_dir: str | Path | None = None, seed: int = 0, refine: bool = False,
                  progress: Callable[[int, int], None] | None = None) -> dict[str, Any]:
    """Run the flight pipeline (and optionally a baseline) on ``split`` frames; returns the report.

    ``refine`` turns on the estimator's point-to-plane ICP after the validity checks. ``skip`` leaves out
    the first frames of the split (then ``limit`` counts from there): frames a calibration used stay out.

    Report: ``{"frames": [...per-frame rows...], "ours": {overall, regime:*, distance:*, confidence},
    "baseline": {...} | None, "bundle", "dataset"}``; with ``out_dir`` the overlay images are written
    under ``out_dir/overlays``.
    """
    from spacepose.bundle import load_bundle
    from spacepose.calibration.rectify import rectify
    from spacepose.calibration.rig import load_rig
    from spacepose.estimator import PoseEstimator
    from spacepose.tools.pose_data import read_pose_labels

    root = Path(dataset)
    records = read_pose_labels(root, split)
    if skip < 0:
        raise ValueError(f"skip must be >= 0, got {skip}")
    records = records[int(skip):]
    if limit is not None:
        records = records[: int(limit)]
    if not records:
        raise DatasetError(f"{root}: no frames in split {split!r}")
    rig = load_rig(root / "rig.yaml")
    model = load_bundle(bundle)
    estimator = PoseEstimator(rig, bundle=model, threads=threads, use_prior=False, seed=seed, refine=refine)
    pts = model_points(model.target_name, np.vstack([model.keypoints, model.bbox_corners]))
    from spacepose.flip import flip_matrix
    from spacepose.metrics import rotation_error_deg

    flip_S = flip_matrix(model.voting.flip_axis) if model.voting.flip_axis else np.eye(3)
    centre = np.asarray(model.centre, dtype=np.float64)
    classical: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, bool]] | None = None
    rect = rectify(rig)
    K = rect.K
    if baseline == "classical":
        from spacepose.tools.classical_pose import estimate_classical, model_cloud
        from spacepose.tools.targets import load_target

        model_pts, model_normals = model_cloud(load_target(model.target_name), seed=seed)

        def classical(left_img: np.ndarray, right_img: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
            lr, rr = (left_img, right_img) if rect.is_identity else rect.rectify_pair(left_img, right_img)
            res = estimate_classical(lr, rr, rect.K, rect.baseline_m, model_pts, model_normals)
            return np.asarray(res.R, dtype=np.float64), np.asarray(res.t, dtype=np.float64), bool(res.valid)
    elif baseline is not None:
        raise ValueError(f"unknown baseline {baseline!r} (choices: classical)")
    overlay_dir = Path(out_dir) / "overlays" if out_dir is not None and overlays > 0 else None
    if overlay_dir is not None:
        overlay_dir.mkdir(parents=True, exist_ok=True)
    rows: list[dict[str, Any]] = []
    base_rows: list[dict[str, Any]] = []
    nan_err = {"e_t": float("nan"), "e_R": float("nan"), "add": float("nan"), "speed": float("nan"),
               "e_R_sym": float("nan")}
    for i, rec in enumerate(records):
        left = read_image(root / "left" / f"{rec.frame}.png")
        right = read_image(root / "right" / f"{rec.frame}.png")
        t0 = time.perf_counter()
        result = estimator.estimate(left, right)
        wall = (time.perf_counter() - t0) * 1e3
        err = _errors(rec.R, rec.t, result.R, result.t, pts) if result.valid else dict(nan_err)
        # up to the target's declared near-symmetry: the nearer of the label and its 180° flip
        err["e_R_sym"] = (min(err["e_R"], rotation_error_deg(rec.R @ flip_S, result.R)) if result.valid
                          else float("nan"))
        centre_true = np.asarray(rec.R, dtype=np.float64) @ centre + np.asarray(rec.t, dtype=np.float64)
        miss = np.asarray(result.position) - centre_true if result.position_valid else np.full(3, np.nan)
        e_pos = float(np.linalg.norm(miss))
        e_pos_los = float(miss @ centre_true / np.linalg.norm(centre_true))   # signed, along the line of sight
        row = {"frame": rec.frame, "regime": rec.regime, "distance": rec.distance_m, "valid": bool(result.valid),
               "status": result.status, "confidence": float(result.confidence),
               "decision_confidence": float(result.decision_confidence), "wall_ms": wall, **err,
               "flip_margin": float(result.flip_margin), "depth_tolerance_m": float(result.depth_tolerance_m),
               "outline_chamfer_px": float(result.outline_chamfer_px),
               "outline_margin_px": float(result.outline_margin_px),
               "outline_image_score": float(result.outline_image_score),
               "outline_image_background": float(result.outline_image_background),
               "outline_image_pixels": float(result.outline_image_pixels),
               "polish_deg": float(result.polish_deg), "polish_m": float(result.polish_m),
               "range_fit_m": float(result.range_fit_m),
               "flip_prob": float(result.flip_prob), "decided_by": result.decided_by,
               "position_valid": bool(result.position_valid), "e_pos": e_pos, "e_pos_los": e_pos_los,
               "position": np.asarray(result.position).tolist(),
               **predicted_sigmas(result), "R": np.asarray(result.R).tolist(), "t": np.asarray(result.t).tolist()}
        rows.append(row)
        if classical is not None:
            R_c, t_c, valid_c = classical(left, right)
            valid_c = bool(valid_c) and bool(np.all(np.isfinite(R_c))) and bool(np.all(np.isfinite(t_c)))
            err_c = _errors(rec.R, rec.t, np.asarray(R_c), np.asarray(t_c), pts) if valid_c else dict(nan_err)
            base_rows.append({"frame": rec.frame, "regime": rec.regime, "distance": rec.distance_m, "valid": valid_c,
                              "status": "ok" if valid_c else "failed", "confidence": 1.0 if valid_c else 0.0, **err_c})
        if overlay_dir is not None and i < overlays:
            img = draw_box_overlay(left, K, model.bbox_corners,
                                   [(rec.R, rec.t, (255, 255, 255)), (result.R, result.t, (0, 255, 0))])
            # JPEG: a 1280x960 overlay is ~1.3 MB as PNG, ~0.2 MB as JPEG; reports are committed, and the
            # working tree must stay under the device machine's transfer limit
            write_image(overlay_dir / f"{rec.frame}.jpg", img, jpeg_quality=90)
        if progress:
            progress(i + 1, len(records))
    return {"dataset": str(root), "bundle": str(model.path), "split": split, "refine": bool(refine),
            "focal_px": float(rect.focal_px), "frames": rows,
            "ours": _grouped(rows),
            "baseline": _grouped(base_rows) if base_rows else None, "baseline_name": baseline,
            "baseline_frames": base_rows}


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return "nan" if not math.isfinite(v) else f"{v:.4g}"
    return str(v)


def format_tables(report: dict[str, Any]) -> str:
    """Markdown tables: per group (overall, regimes, distance bins) and error vs confidence."""
    cols = ["frames", "valid_fraction", "e_t_mean", "e_t_median", "e_R_mean", "e_R_median", "e_R_sym_median", "add_mean",
            "speed_score", "flips", "position_fraction", "e_pos_mean", "e_pos_median", "e_pos_p95"]
    lines = []
    for name in ("ours", "baseline"):
        block = report.get(name)
        if not block:
            continue
        label = name if name == "ours" else f"baseline ({report.get('baseline_name')})"
        lines += [f"### {label}", "", "| group | " + " | ".join(cols) + " |", "|---" * (len(cols) + 1) + "|"]
        for group, stats in block.items():
            if group in ("confidence", "uncertainty", "position_uncertainty"):
                continue
            lines.append(f"| {group} | " + " | ".join(_fmt(stats.get(c, float("nan"))) for c in cols) + " |")
        lines.append("")
        if block.get("confidence"):
            ccols = ["confidence_min", "confidence_max", "confidence_mean", "within_bar", "frames", "e_t_median",
                     "e_R_median", "flips"]
            lines += ["error vs confidence (quantile bins, highest first)", "", "| " + " | ".join(ccols) + " |",
                      "|---" * len(ccols) + "|"]
            lines += ["| " + " | ".join(_fmt(b[c]) for c in ccols) + " |" for b in block["confidence"]]
            lines.append("")
        if (block.get("uncertainty") or {}).get("poses"):
            from spacepose.tools.calibrate_uncertainty import format_coverage

            lines += ["predicted uncertainty (share within, normal's in brackets; spearman: errors vs sigmas)", "",
                      format_coverage("valid poses", block["uncertainty"]), ""]
        if (block.get("position_uncertainty") or {}).get("positions"):
            from spacepose.tools.calibrate_uncertainty import format_position_coverage

            lines += [format_position_coverage("positions without a pose", block["position_uncertainty"]), ""]
    return "\n".join(lines)


def write_report(report: dict[str, Any], out_dir: str | Path) -> Path:
    """``out_dir/pose_eval.json``, ``pose_eval.md``, ``fig14_errors_vs_distance.png`` (+ baseline plot)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "pose_eval.json"
    path.write_text(json.dumps(report, indent=1, default=float, allow_nan=True))
    (out / "pose_eval.md").write_text(format_tables(report) + "\n")
    save_scatter(report["frames"], out / "fig14_errors_vs_distance.png")
    if report.get("baseline_frames"):
        save_scatter(report["baseline_frames"], out / "fig14_baseline.png", title=f"baseline {report.get('baseline_name')}")
    return path
