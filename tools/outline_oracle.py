"""Where the outline stage fails: its search or its objective (train frames, numbers only).

    python -m spacepose.tools.outline_oracle data/tdrs640 --bundle B --skip 0 --limit 400 \\
        --out reports/outline_oracle_train400.json

Runs the estimator (no tracking) on the labelled frames of ``--split`` (train by default) with bundle
``B`` and records every fit the outline stage's decision refines (:func:`spacepose.silhouette.decide_outline`;
the polish is not counted): its chamfer, the stereo points' mean point-to-plane residual at it in units
of the noise (capped at 3, as :class:`spacepose.silhouette.OutlineFit` ``points_res``) and its error to
the label. It then refines the labelled pose and its flip against the same observed outline with the
same settings. Run it with the outline gates open (a copy of the bundle with ``silhouette.max_chamfer_px``
large and ``min_margin_px`` 0) so that every frame's decision is seen.

The summary counts, among the frames the stage decided on, how the lowest-chamfer fit came out (right:
within ``--max-e-r`` and ``--max-e-t``; flip: more than 90° off; wrong: the rest), how often any fit was
right, how often the refined label beat the chosen fit's chamfer (the objective prefers the truth: a
search problem) and what ranking by ``chamfer + w * points_res`` would choose for a few ``w``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np

from spacepose.tools.eval_pose import FLIP_DEG

__all__ = ["summarise", "collect", "main"]

logger = logging.getLogger(__name__)
WEIGHTS = (0.0, 1.0, 2.0, 4.0)


def _outcome(e_r: float, e_t: float, max_e_r: float, max_e_t: float) -> str:
    if e_r > FLIP_DEG:
        return "flip"
    return "right" if e_r <= max_e_r and e_t <= max_e_t else "wrong"


def summarise(frames: list[dict[str, Any]], max_e_r: float = 10.0, max_e_t: float = 0.5) -> dict[str, Any]:
    """Counts over ``frames`` (rows of :func:`collect`: ``fits`` list of dicts with ``chamfer_px``,
    ``points_res``, ``e_R``, ``e_t``; ``truth_chamfer_px``, ``truth_flip_chamfer_px``)."""
    out: dict[str, Any] = {"frames": len(frames), "any_right": 0}
    by_chamfer = {"right": 0, "flip": 0, "wrong": 0}
    truth_better = {"right": 0, "flip": 0, "wrong": 0}
    ranked = {str(w): {"right": 0, "flip": 0, "wrong": 0} for w in WEIGHTS}
    decided = 0
    for f in frames:
        fits = f["fits"]
        if not fits:
            continue
        decided += 1
        kind = lambda x: _outcome(x["e_R"], x["e_t"], max_e_r, max_e_t)   # noqa: E731
        out["any_right"] += any(kind(x) == "right" for x in fits)
        best = min(fits, key=lambda x: x["chamfer_px"])
        by_chamfer[kind(best)] += 1
        truth_better[kind(best)] += f["truth_chamfer_px"] < best["chamfer_px"]
        for w in WEIGHTS:
            ranked[str(w)][kind(min(fits, key=lambda x: x["chamfer_px"] + w * x["points_res"]))] += 1
    out.update(with_outline=decided, best_by_chamfer=by_chamfer, truth_fits_better=truth_better,
               ranked_by_chamfer_plus_w_points=ranked, max_e_r=max_e_r, max_e_t=max_e_t)
    return out


@contextlib.contextmanager
def _recording(store: list[tuple[Any, ...]]) -> Iterator[list[dict[str, Any]]]:
    """Record the fits refined inside the estimator's :func:`decide_outline` calls into ``store``
    (the polish, refined outside it, is not recorded); ``decisions`` gets each call's result."""
    import spacepose.estimator as est
    import spacepose.silhouette as sil

    decide, refine = est.decide_outline, sil.refine_outline
    inside = [False]
    decisions: list[dict[str, Any]] = []

    def refine_rec(R, t, *args, **kwargs):
        fit = refine(R, t, *args, **kwargs)
        if inside[0]:
            store.append((fit, kwargs.get("stereo_points"), kwargs.get("surface"), kwargs.get("tau_m", 0.5)))
        return fit

    def decide_rec(*args, **kwargs):
        inside[0] = True
        try:
            result = decide(*args, **kwargs)
        finally:
            inside[0] = False
        decisions.append({"args": args, "kwargs": kwargs, "result": result})
        return result

    est.decide_outline, sil.refine_outline = decide_rec, refine_rec
    try:
        yield decisions
    finally:
        est.decide_outline, sil.refine_outline = decide, refine


def _points_res(fit: Any, P: np.ndarray | None, surface: Any, tau: float) -> float:
    """:func:`spacepose.silhouette.points_residual` of ``fit``; NaN without stereo points or a surface."""
    from spacepose.silhouette import points_residual

    if P is None or surface is None:
        return float("nan")
    return points_residual(fit.R, fit.t, P, surface, tau)


def collect(dataset: str | Path, bundle: str | Path, *, split: str = "train", skip: int = 0,
            limit: int | None = None, threads: int = 1) -> list[dict[str, Any]]:
    """One row per labelled frame of ``split`` (after ``skip``, at most ``limit``): module docstring."""
    from spacepose.cli_estimate import read_pair
    from spacepose.estimator import PoseEstimator
    from spacepose.flip import flipped_pose
    from spacepose.registration import rotation_angle_deg
    from spacepose.silhouette import refine_outline
    from spacepose.tools.labels import read_labels

    root = Path(dataset)
    labels = read_labels(root, split, require=("R", "t"))[skip:]
    labels = labels[:limit] if limit is not None else labels
    est = PoseEstimator(root / "rig.yaml", bundle=bundle, threads=threads, use_prior=False)
    if est.bundle.silhouette is None:
        raise SystemExit(f"bundle {bundle} has no silhouette stage")
    centre, axis = np.asarray(est.bundle.centre), est.bundle.voting.flip_axis
    rows = []
    for i, lab in enumerate(labels):
        store: list[tuple[Any, ...]] = []
        with _recording(store) as decisions:
            left, right = read_pair(root, f"{lab.frame}.png")
            est.estimate(left, right)
        row: dict[str, Any] = {"frame": lab.frame, "regime": lab.regime, "distance": lab.distance_m, "fits": []}
        if decisions:
            call = decisions[-1]
            dec, args, kw = call["result"], call["args"], call["kwargs"]
            points, config = args[1], args[6] if len(args) > 6 else kw["config"]
            extra = {k: kw.get(k) for k in ("stereo_points", "surface", "tau_m")}
            for fit, P, surface, tau in store:
                row["fits"].append({"chamfer_px": fit.chamfer_px, "points_res": _points_res(fit, P, surface, tau),
                                    "e_R": float(rotation_angle_deg(lab.R, fit.R)),
                                    "e_t": float(np.linalg.norm(fit.t - lab.t))})
            if dec.frame is not None and dec.observed is not None:
                truth = refine_outline(lab.R, lab.t, points, dec.observed, dec.frame, config, **extra)
                R_f, t_f = flipped_pose(lab.R, lab.t, centre, axis or "z")
                flip = refine_outline(R_f, t_f, points, dec.observed, dec.frame, config, **extra)
                row.update(truth_chamfer_px=truth.chamfer_px, truth_flip_chamfer_px=flip.chamfer_px,
                           truth_moved_deg=float(rotation_angle_deg(lab.R, truth.R)))
            else:
                row["fits"] = []
        rows.append(row)
        if (i + 1) % 50 == 0:
            logger.info("%d / %d frames", i + 1, len(labels))
    return rows


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m spacepose.tools.outline_oracle", description=__doc__.split("\n")[0])
    p.add_argument("dataset", type=Path)
    p.add_argument("--bundle", type=Path, required=True, help="bundle with the outline gates open")
    p.add_argument("--split", default="train")
    p.add_argument("--skip", type=int, default=0)
    p.add_argument("--limit", type=int, default=None)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--max-e-r", type=float, default=10.0, help="a fit within this (deg) and --max-e-t is right")
    p.add_argument("--max-e-t", type=float, default=0.5)
    p.add_argument("--out", type=Path, required=True, help="JSON with the rows and the summary")
    args = p.parse_args(argv)
    if args.split == "test":
        raise SystemExit("diagnose on train frames, not the test split")
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    if args.out.exists():
        raise SystemExit(f"{args.out} exists; remove it first")
    rows = collect(args.dataset, args.bundle, split=args.split, skip=args.skip, limit=args.limit,
                   threads=args.threads)
    summary = summarise(rows, args.max_e_r, args.max_e_t)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"summary": summary, "frames": rows}, indent=1))
    logger.info("%s", json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
