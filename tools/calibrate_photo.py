"""Choose the photometric-consistency threshold (``voting.min_photo_consistency``) from data.

On training frames, score the left-right patch consistency
(:func:`spacepose.photometric.photometric_consistency`) at the true pose and at wrong poses that
the stereo stage produces when it fails: depth off by ±5 / ±10 / ±20 % (the target's disparity
scaled), laterally shifted by a quarter and a half of the target's diameter, and a 180° flip about
the body z axis (reported, not expected to be caught). The threshold is the ``--quantile`` of the
true-pose scores (so about that share of right poses is given up); the table says how many wrong
poses each candidate threshold rejects. The table also gives the surface fitness
(:func:`spacepose.pose_stage.surface_fitness`, the other geometric check) of every pose against 1,024
target points from the ground-truth depth with 1 % noise, including 180° flips about each body axis:
how well the geometry alone can tell a flip from the truth. Prints markdown and writes JSON.

    python -m spacepose.tools.calibrate_photo data/tdrs640 --split train --limit 200 --out reports/photo_calibration
"""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path
from typing import Any

import numpy as np

log = logging.getLogger(__name__)

__all__ = ["perturbations", "score_frames", "summarise", "main"]


def perturbations(R: np.ndarray, t: np.ndarray, diameter: float) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Named wrong poses around the true ``(R, t)`` (the first entry, ``true``, is the true pose)."""
    out = {"true": (R, t)}
    for s in (0.05, 0.10, 0.20):
        out[f"depth+{int(s * 100)}%"] = (R, t * (1 + s))
        out[f"depth-{int(s * 100)}%"] = (R, t * (1 - s))
    for frac in (0.25, 0.5):
        out[f"shift {frac:g}D"] = (R, t + np.array([frac * diameter, 0.0, 0.0]))
    for axis, diag in (("x", [1.0, -1.0, -1.0]), ("y", [-1.0, 1.0, -1.0]), ("z", [-1.0, -1.0, 1.0])):
        out[f"flip180 {axis}"] = (R @ np.diag(diag), t)  # about the body axis through the body origin
    return out


def score_frames(dataset: str | Path, bundle: str | Path | None, split: str, limit: int | None) -> list[dict[str, Any]]:
    """Per frame and perturbation: the consistency score, scored patches and regime."""
    from spacepose.bundle import load_bundle
    from spacepose.calibration.rectify import rectify
    from spacepose.calibration.rig import load_rig
    from spacepose.geometry import backproject
    from spacepose.imageio import read_image, read_pfm
    from spacepose.photometric import photometric_consistency
    from spacepose.pose_stage import surface_fitness
    from spacepose.tools.pose_data import read_pose_labels

    from spacepose.tools.dataset import require_depth

    root = Path(dataset)
    require_depth(root)
    recs = read_pose_labels(root, split)[: limit]
    model = load_bundle(bundle)
    surface = np.asarray(model.surface_points)
    rect = rectify(load_rig(root / "rig.yaml"))
    rng = np.random.default_rng(0)
    tolerance = 0.05 * model.diameter  # the voting bandwidth rule's floor
    rows = []
    for rec in recs:
        left = read_image(root / "left" / f"{rec.frame}.png")
        right = read_image(root / "right" / f"{rec.frame}.png")
        if not rect.is_identity:
            left, right = rect.rectify_pair(left, right)
        row: dict[str, Any] = {"frame": rec.frame, "regime": rec.regime, "distance": rec.distance_m}
        depth = read_pfm(root / "depth" / f"{rec.frame}.pfm")
        mask = read_image(root / "mask" / f"{rec.frame}.png")
        cloud = backproject(depth, rect.K, (mask if mask.ndim == 2 else mask[..., 0]) > 0).points
        if len(cloud):
            cloud = cloud[rng.choice(len(cloud), min(1024, len(cloud)), replace=False)]
            cloud = cloud * (1.0 + 0.01 * rng.standard_normal((len(cloud), 1)))  # stereo-like range noise
        fitness = {}
        for name, (R, t) in perturbations(rec.R, rec.t, model.diameter).items():
            res = photometric_consistency(R, t, surface, left, right, rect.K, rect.baseline_m)
            row[name] = res.score
            fitness[name] = surface_fitness(R, t, cloud, surface, tolerance) if len(cloud) else None
            if name == "true":
                row["patches"] = res.patches
        row["fitness"] = fitness
        rows.append(row)
    return rows


def summarise(rows: list[dict[str, Any]], quantile: float) -> dict[str, Any]:
    """Threshold = ``quantile`` of the true-pose scores; rejection share of every perturbation at it."""
    names = [k for k in rows[0] if k not in ("frame", "regime", "distance", "patches", "fitness")] if rows else []
    true = np.array([r["true"] for r in rows if r["true"] is not None], dtype=float)
    threshold = float(np.quantile(true, quantile)) if len(true) else float("nan")
    table = []
    for name in names:
        vals = [r[name] for r in rows]
        scored = np.array([v for v in vals if v is not None], dtype=float)
        fit = np.array([r["fitness"][name] for r in rows if r.get("fitness", {}).get(name) is not None], dtype=float)
        fit_true = np.array([r["fitness"]["true"] for r in rows if r.get("fitness", {}).get(name) is not None],
                            dtype=float)
        table.append({"pose": name, "frames": len(vals), "unverifiable": len(vals) - len(scored),
                      "median": float(np.median(scored)) if len(scored) else float("nan"),
                      "p05": float(np.quantile(scored, 0.05)) if len(scored) else float("nan"),
                      "rejected": float(np.mean(scored < threshold)) if len(scored) else float("nan"),
                      "fitness_median": float(np.median(fit)) if len(fit) else float("nan"),
                      "fitness_within_005_of_true": float(np.mean(fit >= fit_true - 0.05)) if len(fit) else float("nan")})
    per_regime = {}
    for regime in sorted({r["regime"] for r in rows}):
        vals = np.array([r["true"] for r in rows if r["regime"] == regime and r["true"] is not None], dtype=float)
        per_regime[regime] = {"frames": int(len(vals)), "true_median": float(np.median(vals)) if len(vals) else float("nan"),
                              "true_rejected": float(np.mean(vals < threshold)) if len(vals) else float("nan")}
    return {"threshold": threshold, "quantile": quantile, "table": table, "per_regime_true": per_regime}


def _markdown(summary: dict[str, Any]) -> str:
    lines = [f"threshold (q={summary['quantile']:g} of true-pose scores): **{summary['threshold']:.3f}**", "",
             "| pose | frames | unverifiable | median ZNCC | 5th pct | rejected at threshold | surface fitness median "
             "| fitness within 0.05 of the true pose's |", "|---|---|---|---|---|---|---|---|"]
    for r in summary["table"]:
        lines.append(f"| {r['pose']} | {r['frames']} | {r['unverifiable']} | {r['median']:.3f} | {r['p05']:.3f} | "
                     f"{100 * r['rejected']:.1f} % | {r.get('fitness_median', float('nan')):.3f} | "
                     f"{100 * r.get('fitness_within_005_of_true', float('nan')):.0f} % |")
    lines += ["", "| regime | frames | true median | true rejected |", "|---|---|---|---|"]
    for k, r in summary["per_regime_true"].items():
        lines.append(f"| {k} | {r['frames']} | {r['true_median']:.3f} | {100 * r['true_rejected']:.1f} % |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m spacepose.tools.calibrate_photo", description=__doc__.split("\n")[0])
    parser.add_argument("dataset")
    parser.add_argument("--bundle", default=None, help="bundle folder (default: shipped) for the surface samples")
    parser.add_argument("--split", default="train")
    parser.add_argument("--limit", type=int, default=200)
    parser.add_argument("--quantile", type=float, default=0.02)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    rows = score_frames(args.dataset, args.bundle, args.split, args.limit)
    summary = summarise(rows, args.quantile)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "photo_calibration.json").write_text(json.dumps({"args": {k: str(v) for k, v in vars(args).items()},
                                                                  **summary, "frames": rows}, indent=1))
    text = _markdown(summary)
    (args.out / "photo_calibration.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
