"""A tumbling-target stereo sequence, and the flight pipeline run over it in order (tracking measured).

    python -m spacepose.tools.sequence render OUT --frames 60 --distance 15 --rate 2 --regime sun --seed 7
    python -m spacepose.tools.sequence eval OUT [--bundle B] [--json REPORT]

``render`` draws one scene (illumination, materials, Earth) with the dataset's samplers, then turns
the target about a fixed random axis by ``--rate`` degrees per frame at a fixed ``--distance``
(the projected centre stays where the sampler put it), with fresh image noise and degradations
per frame. It writes a CLI input folder (``left/``, ``right/``, ``rig.yaml``) plus ``labels.jsonl``.

``eval`` runs :class:`spacepose.estimator.PoseEstimator` with ``use_prior`` over the frames in
order, as a flight computer would, and reports per frame the status, whether the pose was decided by
the previous one (``tracked``) and its errors; in summary the valid share, flips, errors, the first
valid frame and the longest run of valid frames.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np

__all__ = ["tumble", "render_sequence", "evaluate_sequence", "main"]

log = logging.getLogger(__name__)


def tumble(R0: np.ndarray, axis: np.ndarray, rate_deg: float, frames: int) -> np.ndarray:
    """(frames, 3, 3): ``R_k = exp(k * rate * axis) @ R0`` (turning about a camera-frame axis)."""
    from spacepose.registration import exp_so3

    axis = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    k = np.arange(int(frames), dtype=np.float64)[:, None]
    return exp_so3(k * math.radians(rate_deg) * axis[None]) @ np.asarray(R0, dtype=np.float64)


def render_sequence(out: str | Path, frames: int = 60, distance_m: float = 15.0, rate_deg: float = 2.0,
                    regime: str = "sun", seed: int = 7, size: tuple[int, int] = (640, 480), rig=None) -> Path:
    """Render the sequence (module docstring) into ``out`` (must not exist yet), seen by ``rig`` (an ideal
    parallel :class:`~spacepose.calibration.rig.StereoRig`, scaled to ``size``; default the paper rig)."""
    from spacepose.calibration.rig import paper_rig, save_rig
    from spacepose.errors import DatasetError
    from spacepose.imageio import write_image
    from spacepose.tools.degrade import apply_degradations, sample_degradations, to_uint8
    from spacepose.tools.render import PoseSampler, StereoCamera, render_stereo, sample_scene
    from spacepose.tools.targets import load_target

    root = Path(out)
    if root.exists():
        raise DatasetError(f"{root} exists; choose a new folder")
    if rig is None:
        rig = paper_rig(*size)
    elif tuple(rig.image_size) != tuple(size):
        rig = rig.scaled(*size)
    target = load_target("tdrs")
    camera = StereoCamera.from_rig(rig)
    sampler = PoseSampler(camera, target.bounding_radius, (distance_m, distance_m + 1e-6))
    rng = np.random.default_rng(seed)
    scene = sample_scene(target, camera, rng, regime, sampler)
    t = np.asarray(scene.t, dtype=np.float64)
    t = t * (distance_m / t[2])
    rotations = tumble(scene.R, rng.normal(size=3), rate_deg, frames)
    for sub in ("left", "right"):
        (root / sub).mkdir(parents=True)
    save_rig(rig, root / "rig.yaml")
    lines = []
    for k, R in enumerate(rotations):
        clean = render_stereo(target, camera, dataclasses.replace(scene, R=R, t=t))
        frame_rng = np.random.default_rng([seed, k])
        params = sample_degradations(frame_rng, size[0])
        name = f"{k:06d}"
        write_image(root / "left" / f"{name}.png", to_uint8(apply_degradations(clean.left, params, frame_rng)))
        write_image(root / "right" / f"{name}.png", to_uint8(apply_degradations(clean.right, params, frame_rng)))
        lines.append(json.dumps({"frame": name, "index": k, "split": "test", "R": R.tolist(), "t": t.tolist(),
                                 "regime": regime, "degradations": params}))
    (root / "labels.jsonl").write_text("\n".join(lines) + "\n")
    log.info("rendered %d frames into %s", frames, root)
    return root


def _longest_run(flags: list[bool]) -> int:
    best = run = 0
    for f in flags:
        run = run + 1 if f else 0
        best = max(best, run)
    return best


def _position_errors(rec: Any, res: Any, centre: np.ndarray) -> dict[str, float]:
    """``e_pos`` (m) of the reported target centre and ``e_pos_los``, its signed part along the line of sight
    (as :func:`spacepose.tools.eval_pose.evaluate_pose` records them); NaN without a position."""
    if not res.position_valid:
        return {"e_pos": float("nan"), "e_pos_los": float("nan")}
    true = np.asarray(rec.R, dtype=np.float64) @ centre + np.asarray(rec.t, dtype=np.float64)
    miss = np.asarray(res.position, dtype=np.float64) - true
    return {"e_pos": float(np.linalg.norm(miss)), "e_pos_los": float(miss @ true / np.linalg.norm(true))}


def evaluate_sequence(folder: str | Path, bundle: str | Path | None = None, threads: int = 2,
                      prior_max_gap: int | None = None, position_window: bool = False,
                      prior_window: bool | None = None) -> dict[str, Any]:
    """Run the estimator over the sequence in order with ``use_prior`` (and ``prior_max_gap``, default
    the estimator's; ``position_window``, ``prior_window``, :class:`spacepose.estimator.PoseEstimator`); rows
    and a summary. ``prior_window`` None: the estimator's default."""
    from spacepose.calibration.rig import load_rig
    from spacepose.estimator import PoseEstimator
    from spacepose.imageio import read_image
    from spacepose.metrics import rotation_error_deg, translation_error
    from spacepose.tools.eval_pose import predicted_sigmas
    from spacepose.tools.pose_data import read_pose_labels

    root = Path(folder)
    records = read_pose_labels(root)
    extra = {} if prior_max_gap is None else {"prior_max_gap": int(prior_max_gap)}
    if position_window:
        extra["position_window"] = True
    if prior_window is not None:
        extra["prior_window"] = bool(prior_window)
    est = PoseEstimator(load_rig(root / "rig.yaml"), bundle=bundle, threads=threads, use_prior=True, **extra)
    centre = np.asarray(est.bundle.centre, dtype=np.float64)
    rows = []
    for rec in records:
        res = est.estimate(read_image(root / "left" / f"{rec.frame}.png"), read_image(root / "right" / f"{rec.frame}.png"))
        row = {"frame": rec.frame, "valid": bool(res.valid), "status": res.status, "tracked": bool(res.tracked),
               "confidence": float(res.confidence), "decision_confidence": float(res.decision_confidence),
               "flip_margin": float(res.flip_margin),
               "e_t": translation_error(rec.t, res.t) if res.valid else float("nan"),
               "e_R": rotation_error_deg(rec.R, res.R) if res.valid else float("nan"),
               "outline_chamfer_px": float(res.outline_chamfer_px), "outline_margin_px": float(res.outline_margin_px),
               "outline_image_score": float(res.outline_image_score), "decided_by": res.decided_by,
               "polish_deg": float(res.polish_deg), "polish_m": float(res.polish_m),
               "range_fit_m": float(res.range_fit_m),
               "position_valid": bool(res.position_valid), "stereo_ms": float(res.timings_ms.get("stereo", float("nan"))),
               "roi": None if res.roi is None else [int(v) for v in res.roi],
               "depth_tolerance_m": float(res.depth_tolerance_m), "position": np.asarray(res.position).tolist(),
               **_position_errors(rec, res, centre), **predicted_sigmas(res), "detail": res.detail}
        rows.append(row)
    valid = [r for r in rows if r["valid"]]
    first = next((i for i, r in enumerate(rows) if r["valid"]), None)
    summary = {"frames": len(rows), "valid": len(valid), "tracked": sum(r["tracked"] for r in rows),
               "position_valid": sum(r["position_valid"] for r in rows),
               "flips": sum(r["e_R"] > 90.0 for r in valid), "first_valid": first,
               "longest_valid_run": _longest_run([r["valid"] for r in rows]),
               "e_t_mean": float(np.mean([r["e_t"] for r in valid])) if valid else float("nan"),
               "e_R_mean": float(np.mean([r["e_R"] for r in valid])) if valid else float("nan"),
               "e_R_max": float(np.max([r["e_R"] for r in valid])) if valid else float("nan")}
    return {"folder": str(root), "bundle": str(est.bundle.path), "summary": summary, "frames": rows}


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m spacepose.tools.sequence", description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("render")
    r.add_argument("out", type=Path)
    r.add_argument("--frames", type=int, default=60)
    r.add_argument("--distance", type=float, default=15.0)
    r.add_argument("--rate", type=float, default=2.0, help="degrees per frame")
    r.add_argument("--regime", default="sun")
    r.add_argument("--seed", type=int, default=7)
    r.add_argument("--size", default=None, help="WIDTHxHEIGHT (default: the rig's size, or 640x480)")
    r.add_argument("--rig", type=Path, default=None,
                   help="ideal parallel rig file to render with (default: the paper rig scaled to --size)")
    e = sub.add_parser("eval")
    e.add_argument("folder", type=Path)
    e.add_argument("--bundle", type=Path, default=None)
    e.add_argument("--threads", type=int, default=2)
    e.add_argument("--json", type=Path, default=None)
    e.add_argument("--prior-max-gap", type=int, default=None,
                   help="frames a valid pose stays the prior without another (default: the estimator's)")
    e.add_argument("--position-window", action="store_true",
                   help="take the next frame's window from a position-only frame too (PoseEstimator position_window)")
    e.add_argument("--prior-window", action=argparse.BooleanOptionalAction, default=None,
                   help="the frame after a valid pose takes its stereo window from that pose (PoseEstimator "
                        "prior_window; default: the estimator's, off since session 30); --no-prior-window: the "
                        "coarse pass on every frame")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    if args.cmd == "render":
        from spacepose.calibration.rig import load_rig

        rig = load_rig(args.rig) if args.rig is not None else None
        size = args.size or ("x".join(map(str, rig.image_size)) if rig is not None else "640x480")
        w, h = (int(v) for v in size.lower().split("x"))
        render_sequence(args.out, args.frames, args.distance, args.rate, args.regime, args.seed, (w, h), rig)
        print(f"wrote {args.frames} frames to {args.out}")
        return 0
    report = evaluate_sequence(args.folder, args.bundle, args.threads, args.prior_max_gap, args.position_window,
                               prior_window=args.prior_window)
    print("frame   status        tracked  e_t m   e_R deg")
    for row in report["frames"]:
        print(f"{row['frame']}  {row['status']:<12}  {str(row['tracked']):<7}  "
              + (f"{row['e_t']:.3f}   {row['e_R']:.2f}" if row["valid"] else "-       -"))
    print("summary:", json.dumps(report["summary"]))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(report, indent=1) + "\n")
    return 0


if __name__ == "__main__":  # pragma: no cover
    import sys

    sys.exit(main())
