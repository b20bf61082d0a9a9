"""Validity thresholds of the pose stage from train-split frames: ``min_confidence``, ``min_flip_margin``
(and, for a registration bundle, ``max_tau_m`` with ``--taus``; for a silhouette bundle the outline
gates ``max_chamfer_px`` / ``min_margin_px`` with ``--outline``).

    spacepose eval-pose data/tdrs640 --split train --limit 400 --bundle B --out runs/gates_train
    python -m spacepose.tools.calibrate_gates runs/gates_train/pose_eval.json --out reports/gates_train.json

The evaluation must run with both gates open (``voting.min_confidence`` 0 and ``voting.min_flip_margin``
0 in bundle B), so that every pose the other checks pass is in the report with its confidence and flip
margin. For each pair of thresholds on a grid, this counts the poses that would stay valid, the
180° flips among them (e_R > 90°) and the wrong poses (e_t or e_R over ``--max-e-t`` / ``--max-e-r``).
It proposes the pair that keeps the most poses with no flip and no wrong pose. Ties go to the stricter
pair. The thresholds come from train frames only; the test split measures them. Numbers only.

``--outline``: the evaluation ran with the silhouette gates open (``silhouette.max_chamfer_px`` large,
``min_margin_px`` 0) and the registration's margin closed (``registration.min_margin`` 0.99), so that
every frame the outline stage saw is valid in the report with its ``outline_chamfer_px`` and
``outline_margin_px``; the grid is then over those two gates.

``--image``: the same evaluation with the silhouette stage's ``image_vote`` 1, so that every row also
carries ``outline_image_score`` and ``outline_image_background``. The outline gates stay at
``--chamfer`` / ``--margin`` (the bundle's), and the grid is over the image route's
``image_min_margin_px``, ``image_min_score``, ``image_min_pixels``, ``image_veto_score``,
``image_max_chamfer_px`` and ``min_flip_pixels`` (``image_max_background`` fixed at ``--background``): a
pose is kept when a usable vote does not score ``image_veto_score`` or less, the vote counted at least
``min_flip_pixels`` differing pixels, and either its chamfer and margin pass, or the image route does
(its own chamfer gate, the larger of the two). Run the evaluation with ``image_min_pixels`` 0 and ``image_veto_score`` -1, so that every vote is
in the rows (a report made with a higher veto score tables only veto scores at or above it).

``--flip``: the same evaluation with a ``flip_classifier`` in the bundle that neither decides nor vetoes
(``decide_prob`` and ``veto_prob`` at their defaults), so that every row carries ``flip_prob``, the
classifier's probability for the outline's winner against its flip. The outline and image gates are
fixed at ``--chamfer`` / ``--margin`` and the shipped image route (``--image-margin``, ``--score``,
``--min-pixels``, ``--veto``, ``--image-chamfer``, ``--flip-min-pixels``, ``--background``); the grid is over
the classifier's ``decide_prob``, ``veto_prob`` and ``max_chamfer_px``
(:class:`spacepose.flip_classifier.FlipClassifierConfig`). A frame the outline gates decide is kept unless
the classifier gives its winner ``veto_prob`` or less; one they leave open is kept for the winner when the
classifier gives it at least ``decide_prob`` (the winner within the classifier's chamfer gate, no usable
image vote against it), or for the winner's flip when it gives the winner at most ``1 - decide_prob``
(the flip's fit is taken as the winner's chamfer plus the margin; no usable image vote for the winner).
A row's outcome for the flip is read from the winner's: a flip when the winner was right, its error up to
the flip (``e_R_sym``) when the winner was a flip. ``--flip-max-tau`` and ``--flip-max-polish`` replay the
classifier's ``max_depth_tolerance_m`` and ``max_polish_deg``: it decides no frame over either. The table also
counts the kept poses within the pose bar (0.10 m and 2 degrees).
"""

from __future__ import annotations

import argparse
import gzip
import itertools
import json
import math
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np

from spacepose.tools.eval_pose import FLIP_DEG

#: the pose bar of issue 6 (e_t and e_R of a pose "within the bar"), counted by :func:`flip_gate_table`
WITHIN_T_M = 0.10
WITHIN_R_DEG = 2.0

__all__ = ["gate_table", "outline_gate_table", "image_gate_table", "flip_gate_table", "propose", "propose_outline",
           "propose_image", "propose_flip", "main"]


def _finite(value: Any) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        return float("nan")
    return v if math.isfinite(v) else float("nan")


def _outcomes(ok: list[dict[str, Any]], max_e_t: float, max_e_r: float
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """e_t, e_R of the valid rows ``ok``, and which are flips (e_R > FLIP_DEG) and wrong (over either bound)."""
    e_t = np.array([_finite(r.get("e_t")) for r in ok])
    e_r = np.array([_finite(r.get("e_R")) for r in ok])
    return e_t, e_r, e_r > FLIP_DEG, (e_t > max_e_t) | (e_r > max_e_r)


def gate_table(rows: Iterable[dict[str, Any]], confidences: Sequence[float], margins: Sequence[float],
               max_e_t: float, max_e_r: float, taus: Sequence[float] = (math.inf,)) -> list[dict[str, float]]:
    """One row per (min_confidence, min_flip_margin, max_tau_m): kept poses, flips, wrong poses among them.

    ``max_tau_m`` gates on the rows' ``depth_tolerance_m`` (the registration's; a row without one
    passes every value). The confidence is the rows' ``decision_confidence`` (``confidence`` in reports
    without it)."""
    ok = [r for r in rows if r.get("valid")]
    tau = np.nan_to_num(np.array([_finite(r.get("depth_tolerance_m")) for r in ok]), nan=0.0)
    # the gate judges the decision's own confidence (reports since session 30 also carry the pose's accuracy
    # confidence, spacepose.confidence, under "confidence"; earlier ones only the decision's)
    conf = np.array([_finite(r.get("decision_confidence", r.get("confidence"))) for r in ok])
    margin = np.nan_to_num(np.array([_finite(r.get("flip_margin")) for r in ok]), nan=np.inf)  # no flip stage
    e_t, e_r, flip, wrong = _outcomes(ok, max_e_t, max_e_r)
    table = []
    for c, m, tmax in itertools.product(confidences, margins, taus):
        keep = (conf >= c) & (margin >= m) & (tau <= tmax)
        table.append({"min_confidence": float(c), "min_flip_margin": float(m), "max_tau_m": float(tmax),
                      "kept": int(keep.sum()), "flips": int((keep & flip).sum()), "wrong": int((keep & wrong).sum()),
                      "e_t_median": float(np.median(e_t[keep])) if keep.any() else float("nan"),
                      "e_R_median": float(np.median(e_r[keep])) if keep.any() else float("nan")})
    return table


def outline_gate_table(rows: Iterable[dict[str, Any]], chamfers: Sequence[float], margins: Sequence[float],
                       max_e_t: float, max_e_r: float) -> list[dict[str, float]]:
    """One row per (max_chamfer_px, min_margin_px): kept poses, flips, wrong poses among them, and the
    mean errors of the kept poses that are not flips."""
    ok = [r for r in rows if r.get("valid")]
    chamfer = np.nan_to_num(np.array([_finite(r.get("outline_chamfer_px")) for r in ok]), nan=np.inf)
    margin = np.nan_to_num(np.array([_finite(r.get("outline_margin_px")) for r in ok]), nan=-np.inf)
    e_t, e_r, flip, wrong = _outcomes(ok, max_e_t, max_e_r)
    table = []
    for c, m in itertools.product(chamfers, margins):
        keep = (chamfer <= c) & (margin >= m)
        good = keep & ~flip
        table.append({"max_chamfer_px": float(c), "min_margin_px": float(m), "kept": int(keep.sum()),
                      "flips": int((keep & flip).sum()), "wrong": int((keep & wrong).sum()),
                      "e_t_mean": float(np.mean(e_t[good])) if good.any() else float("nan"),
                      "e_R_mean": float(np.mean(e_r[good])) if good.any() else float("nan")})
    return table


def image_gate_table(rows: Iterable[dict[str, Any]], max_chamfer_px: float, min_margin_px: float,
                     image_margins: Sequence[float], scores: Sequence[float], max_background: float,
                     max_e_t: float, max_e_r: float, pixels: Sequence[int] = (0,),
                     vetoes: Sequence[float] = (-0.1,), chamfers: Sequence[float] = (0.0,),
                     flip_pixels: Sequence[int] = (0,)) -> list[dict[str, float]]:
    """One row per (image_min_margin_px, image_min_score, image_min_pixels, image_veto_score,
    image_max_chamfer_px, min_flip_pixels) of the image route (module docstring; :class:`spacepose.silhouette.SilhouetteConfig`; a veto score not
    below the min score is skipped): kept poses, how many of them the image route alone keeps and how
    many margin decisions its veto refuses, flips and wrong poses among the kept, and the mean errors
    of the kept poses that are not flips. A row without an image vote (NaN score) passes only by its
    margin."""
    ok = [r for r in rows if r.get("valid")]
    chamfer = np.nan_to_num(np.array([_finite(r.get("outline_chamfer_px")) for r in ok]), nan=np.inf)
    margin = np.nan_to_num(np.array([_finite(r.get("outline_margin_px")) for r in ok]), nan=-np.inf)
    score = np.array([_finite(r.get("outline_image_score")) for r in ok])
    background = np.nan_to_num(np.array([_finite(r.get("outline_image_background")) for r in ok]), nan=np.inf)
    n_pixels = np.nan_to_num(np.array([_finite(r.get("outline_image_pixels")) for r in ok]), nan=0.0)
    e_t, e_r, flip, wrong = _outcomes(ok, max_e_t, max_e_r)
    fits = chamfer <= max_chamfer_px
    table = []
    for m, s, p, v, c, f in itertools.product(image_margins, scores, pixels, vetoes, chamfers, flip_pixels):
        if v >= s:
            continue
        fits_image = chamfer <= max(max_chamfer_px, c)
        apart = ~np.isfinite(score) | (n_pixels >= f)   # no vote taken: nothing counted
        usable = np.isfinite(score) & (background <= max_background) & (n_pixels >= max(p, 1))
        veto = usable & (np.nan_to_num(score, nan=0.0) <= v)
        by_margin = fits & (margin >= min_margin_px) & ~veto & apart
        by_image = fits_image & usable & ~veto & apart & (margin >= m) & (np.nan_to_num(score, nan=-np.inf) >= s) & ~by_margin
        keep = by_margin | by_image
        good = keep & ~flip
        table.append({"image_min_margin_px": float(m), "image_min_score": float(s), "image_min_pixels": int(p),
                      "image_veto_score": float(v), "image_max_chamfer_px": float(c), "min_flip_pixels": int(f),
                      "kept": int(keep.sum()), "by_image": int(by_image.sum()),
                      "vetoed": int((fits & (margin >= min_margin_px) & veto).sum()),
                      "flips": int((keep & flip).sum()), "wrong": int((keep & wrong).sum()),
                      "e_t_mean": float(np.mean(e_t[good])) if good.any() else float("nan"),
                      "e_R_mean": float(np.mean(e_r[good])) if good.any() else float("nan")})
    return table


def flip_gate_table(rows: Iterable[dict[str, Any]], decides: Sequence[float], vetoes: Sequence[float],
                    chamfers: Sequence[float], *, max_chamfer_px: float, min_margin_px: float, image_margin: float,
                    image_score: float, image_pixels: int, image_veto: float, image_chamfer: float, flip_pixels: int,
                    max_background: float, max_e_t: float, max_e_r: float, max_depth_tolerance_m: float = 0.0,
                    max_polish_deg: float = 0.0) -> list[dict[str, float]]:
    """One row per (decide_prob, veto_prob, max_chamfer_px) of the flip classifier (module docstring): kept
    poses, how many the classifier decides and vetoes, flips and wrong poses among the kept, how many kept poses
    are within the pose bar (``WITHIN_T_M``, ``WITHIN_R_DEG``), mean errors of the kept poses that are not flips.
    ``max_depth_tolerance_m`` and ``max_polish_deg`` (0: off) are the classifier's own limits
    (:class:`spacepose.flip_classifier.FlipClassifierConfig`): it decides no frame whose ``depth_tolerance_m`` is above
    the first (or missing) nor one whose ``polish_deg`` is above the second (or missing; the winner's polish stands in
    for its flip's)."""
    ok = [r for r in rows if r.get("valid") and math.isfinite(_finite(r.get("flip_prob")))]
    prob = np.array([_finite(r.get("flip_prob")) for r in ok])
    chamfer = np.nan_to_num(np.array([_finite(r.get("outline_chamfer_px")) for r in ok]), nan=np.inf)
    margin = np.nan_to_num(np.array([_finite(r.get("outline_margin_px")) for r in ok]), nan=-np.inf)
    score = np.array([_finite(r.get("outline_image_score")) for r in ok])
    background = np.nan_to_num(np.array([_finite(r.get("outline_image_background")) for r in ok]), nan=np.inf)
    n_pixels = np.nan_to_num(np.array([_finite(r.get("outline_image_pixels")) for r in ok]), nan=0.0)
    e_t, e_r, flip, wrong = _outcomes(ok, max_e_t, max_e_r)
    e_sym = np.array([_finite(r.get("e_R_sym")) for r in ok])
    # the winner's flip: a flip when the winner was right, right (up to e_R_sym) when the winner was a flip
    flip_of_other = ~flip
    wrong_other = ~flip | (e_t > max_e_t) | (np.nan_to_num(e_sym, nan=np.inf) > max_e_r)
    usable = np.isfinite(score) & (background <= max_background) & (n_pixels >= max(image_pixels, 1))
    s = np.nan_to_num(score, nan=0.0)
    apart = ~np.isfinite(score) | (n_pixels >= flip_pixels)
    veto_image = usable & (s <= image_veto)
    by_margin = (chamfer <= max_chamfer_px) & (margin >= min_margin_px) & ~veto_image & apart
    by_image = ((chamfer <= max(max_chamfer_px, image_chamfer)) & usable & ~veto_image & apart
                & (margin >= image_margin) & (s >= image_score))
    decided = by_margin | by_image
    may_decide = np.ones(len(ok), dtype=bool)
    if max_depth_tolerance_m > 0.0:
        may_decide &= np.nan_to_num(np.array([_finite(r.get("depth_tolerance_m")) for r in ok]), nan=np.inf
                                    ) <= max_depth_tolerance_m
    if max_polish_deg > 0.0:
        may_decide &= np.nan_to_num(np.array([_finite(r.get("polish_deg")) for r in ok]), nan=np.inf) <= max_polish_deg
    table = []
    for d, v, c in itertools.product(decides, vetoes, chamfers):
        vetoed = decided & (prob <= v)
        for_best = ~decided & may_decide & apart & (chamfer <= c) & (prob >= d) & ~veto_image
        for_other = (~decided & may_decide & apart & (chamfer + margin <= c) & (prob <= 1.0 - d)
                     & ~(usable & (s >= -image_veto)))
        kept_best = (decided & ~vetoed) | for_best
        kept = kept_best | for_other
        flips = (kept_best & flip) | (for_other & flip_of_other)
        bad = (kept_best & wrong) | (for_other & wrong_other)
        good = kept & ~flips
        err_t = np.where(good, e_t, np.nan)
        err_r = np.where(kept_best & good, e_r, np.where(for_other & good, e_sym, np.nan))
        within = good & (np.nan_to_num(err_t, nan=np.inf) <= WITHIN_T_M) & (np.nan_to_num(err_r, nan=np.inf) <= WITHIN_R_DEG)
        table.append({"decide_prob": float(d), "veto_prob": float(v), "max_chamfer_px": float(c),
                      "kept": int(kept.sum()), "decided": int((for_best | for_other).sum()),
                      "for_flip": int(for_other.sum()), "vetoed": int(vetoed.sum()), "flips": int(flips.sum()),
                      "wrong": int(bad.sum()), "within": int(within.sum()),
                      "e_t_mean": float(np.nanmean(err_t)) if good.any() else float("nan"),
                      "e_R_mean": float(np.nanmean(err_r)) if good.any() else float("nan")})
    return table


def propose_flip(table: list[dict[str, float]]) -> dict[str, float] | None:
    """The classifier gates keeping the most poses with no flip (stricter on ties); None if none keeps any."""
    safe = [r for r in table if r["flips"] == 0 and r["kept"] > 0]
    if not safe:
        return None
    return max(safe, key=lambda r: (r["kept"], -r["wrong"], r["decide_prob"], r["veto_prob"], -r["max_chamfer_px"]))


def propose_image(table: list[dict[str, float]]) -> dict[str, float] | None:
    """The image-route gates keeping the most poses with no flip (stricter on ties); None if none keeps any."""
    safe = [r for r in table if r["flips"] == 0 and r["kept"] > 0]
    if not safe:
        return None
    return max(safe, key=lambda r: (r["kept"], r["image_min_margin_px"], r["image_min_score"], r["image_min_pixels"],
                                    r["image_veto_score"], -r["image_max_chamfer_px"], r["min_flip_pixels"]))


def propose_outline(table: list[dict[str, float]]) -> dict[str, float] | None:
    """The outline gates keeping the most poses with no flip (stricter on ties); None if none keeps any."""
    safe = [r for r in table if r["flips"] == 0 and r["kept"] > 0]
    if not safe:
        return None
    return max(safe, key=lambda r: (r["kept"], -r["max_chamfer_px"], r["min_margin_px"]))


def propose(table: list[dict[str, float]]) -> dict[str, float] | None:
    """The row keeping the most poses with no flip and no wrong pose (stricter on ties); None if none keeps any."""
    safe = [r for r in table if r["flips"] == 0 and r["wrong"] == 0 and r["kept"] > 0]
    if not safe:
        return None
    return max(safe, key=lambda r: (r["kept"], r["min_confidence"], r["min_flip_margin"], -r.get("max_tau_m", math.inf)))


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m spacepose.tools.calibrate_gates", description=__doc__.split("\n")[0])
    p.add_argument("report", type=Path, nargs="+",
                   help="pose_eval.json of eval-pose on train frames with both gates open (several: frames pooled)")
    p.add_argument("--max-e-t", type=float, default=0.5, help="a pose farther off than this (m) is wrong")
    p.add_argument("--max-e-r", type=float, default=20.0, help="a pose turned more than this (deg) is wrong")
    p.add_argument("--out", type=Path, default=None, help="also write the table and proposal as JSON")
    p.add_argument("--taus", type=float, nargs="*", default=None,
                   help="also try these max depth tolerances (m; registration bundles: max_tau_m)")
    p.add_argument("--margins", type=float, nargs="*", default=None, help="min_flip_margin grid")
    p.add_argument("--outline", action="store_true", help="the silhouette gates instead (module docstring)")
    p.add_argument("--image", action="store_true", help="the silhouette stage's image-vote gates (module docstring)")
    p.add_argument("--chamfer", type=float, default=1.5, help="--image: the bundle's max_chamfer_px")
    p.add_argument("--margin", type=float, default=0.5, help="--image: the bundle's min_margin_px")
    p.add_argument("--background", type=float, default=0.02, help="--image: image_max_background")
    p.add_argument("--scores", type=float, nargs="*", default=None, help="--image: image_min_score grid")
    p.add_argument("--pixels", type=int, nargs="*", default=None, help="--image: image_min_pixels grid")
    p.add_argument("--vetoes", type=float, nargs="*", default=None, help="--image: image_veto_score grid")
    p.add_argument("--image-chamfers", type=float, nargs="*", default=None,
                   help="--image: image_max_chamfer_px grid (0: the margin route's --chamfer)")
    p.add_argument("--flip-pixels", type=int, nargs="*", default=None, help="--image: min_flip_pixels grid")
    p.add_argument("--flip", action="store_true", help="the flip classifier's gates (module docstring)")
    p.add_argument("--decides", type=float, nargs="*", default=None, help="--flip: decide_prob grid")
    p.add_argument("--flip-vetoes", type=float, nargs="*", default=None, help="--flip: veto_prob grid")
    p.add_argument("--flip-chamfers", type=float, nargs="*", default=None, help="--flip: max_chamfer_px grid")
    p.add_argument("--image-margin", type=float, default=0.2, help="--flip: the bundle's image_min_margin_px")
    p.add_argument("--score", type=float, default=0.1, help="--flip: the bundle's image_min_score")
    p.add_argument("--min-pixels", type=int, default=16, help="--flip: the bundle's image_min_pixels")
    p.add_argument("--veto", type=float, default=0.0, help="--flip: the bundle's image_veto_score")
    p.add_argument("--image-chamfer", type=float, default=2.0, help="--flip: the bundle's image_max_chamfer_px")
    p.add_argument("--flip-min-pixels", type=int, default=16, help="--flip: the bundle's min_flip_pixels")
    p.add_argument("--flip-max-tau", type=float, default=0.0,
                   help="--flip: the classifier's max_depth_tolerance_m (0: no limit)")
    p.add_argument("--flip-max-polish", type=float, default=0.0,
                   help="--flip: the classifier's max_polish_deg (0: no limit)")
    args = p.parse_args(argv)
    reports = [json.loads(gzip.decompress(path.read_bytes()) if path.suffix == ".gz" else path.read_text())
               for path in args.report]
    if any(r.get("split") == "test" for r in reports):
        raise SystemExit("calibrate on train frames, not the test split")
    report = {"split": "+".join(sorted({str(r.get("split")) for r in reports}))}
    rows = [row for r in reports for row in r["frames"]]
    if args.flip:
        return _main_flip(args, report, rows)
    if args.image:
        return _main_image(args, report, rows)
    if args.outline:
        return _main_outline(args, report, rows)
    confidences = [0.0, 0.3, 0.5, 0.6, 0.7, 0.8, 0.9]
    margins = args.margins or [0.0, 0.005, 0.01, 0.02, 0.03, 0.05, 0.08]
    taus = args.taus or [math.inf]
    table = gate_table(rows, confidences, margins, args.max_e_t, args.max_e_r, taus)
    best = propose(table)
    print(f"{sum(1 for r in rows if r.get('valid'))} of {len(rows)} {report.get('split')} frames valid with the gates open")
    print("| min_confidence | min_flip_margin | max_tau_m | kept | flips | wrong | e_t median m | e_R median ° |\n"
          "|---|---|---|---|---|---|---|---|")
    for r in table:
        print(f"| {r['min_confidence']:.2f} | {r['min_flip_margin']:.3f} | {r['max_tau_m']:g} | {r['kept']} | {r['flips']} "
              f"| {r['wrong']} | {r['e_t_median']:.3f} | {r['e_R_median']:.2f} |")
    print("proposed:", "none (no set keeps a pose without a flip or a wrong pose)" if best is None else
          f"min_confidence {best['min_confidence']}, min_flip_margin {best['min_flip_margin']}, "
          f"max_tau_m {best['max_tau_m']:g} ({best['kept']} poses kept)")
    _write_out(args, {}, table, best)
    return 0


def _write_out(args: argparse.Namespace, settings: dict[str, Any], table: list[dict[str, float]],
               best: dict[str, float] | None) -> None:
    """With ``--out``: the reports, the error bounds, the mode's fixed ``settings``, the table and the proposal."""
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps({"report": [str(path) for path in args.report], "max_e_t": args.max_e_t,
                                        "max_e_r": args.max_e_r, **settings, "table": table, "proposed": best},
                                       indent=2))


def _main_outline(args: argparse.Namespace, report: dict[str, Any], rows: list[dict[str, Any]]) -> int:
    chamfers = [0.6, 0.8, 1.0, 1.2, 1.5, 2.0]
    margins = args.margins or [0.1, 0.2, 0.3, 0.4, 0.5, 0.7, 1.0]
    table = outline_gate_table(rows, chamfers, margins, args.max_e_t, args.max_e_r)
    best = propose_outline(table)
    print(f"{sum(1 for r in rows if r.get('valid'))} of {len(rows)} {report.get('split')} frames valid with the gates open")
    print("| max_chamfer_px | min_margin_px | kept | flips | wrong | e_t mean m | e_R mean ° |\n|---|---|---|---|---|---|---|")
    for r in table:
        print(f"| {r['max_chamfer_px']:.1f} | {r['min_margin_px']:.2f} | {r['kept']} | {r['flips']} | {r['wrong']} "
              f"| {r['e_t_mean']:.3f} | {r['e_R_mean']:.2f} |")
    print("proposed:", "none (no pair keeps a pose without a flip)" if best is None else
          f"max_chamfer_px {best['max_chamfer_px']}, min_margin_px {best['min_margin_px']} ({best['kept']} poses kept)")
    _write_out(args, {"outline": True}, table, best)
    return 0


def _main_image(args: argparse.Namespace, report: dict[str, Any], rows: list[dict[str, Any]]) -> int:
    margins = args.margins or [0.0, 0.1, 0.2, 0.3, 0.4]
    scores = args.scores or [0.0, 0.05, 0.1, 0.15, 0.2, 0.3]
    table = image_gate_table(rows, args.chamfer, args.margin, margins, scores, args.background, args.max_e_t,
                             args.max_e_r, args.pixels or [0, 8, 16, 32], args.vetoes or [-0.1],
                             args.image_chamfers or [0.0], args.flip_pixels or [0])
    best = propose_image(table)
    voted = sum(1 for r in rows if r.get("valid") and math.isfinite(_finite(r.get("outline_image_score"))))
    print(f"{sum(1 for r in rows if r.get('valid'))} of {len(rows)} {report.get('split')} frames valid with the gates "
          f"open, {voted} with an image vote; outline gates {args.chamfer} / {args.margin}, "
          f"image_max_background {args.background}")
    print("| image_min_margin_px | image_min_score | image_min_pixels | image_veto_score | image_max_chamfer_px "
          "| min_flip_pixels | kept | by image | vetoed | flips | wrong | e_t mean m | e_R mean ° |\n"
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in table:
        print(f"| {r['image_min_margin_px']:.2f} | {r['image_min_score']:.2f} | {r['image_min_pixels']} "
              f"| {r['image_veto_score']:.2f} | {r['image_max_chamfer_px']:.2f} | {r['min_flip_pixels']} | {r['kept']} "
              f"| {r['by_image']} | {r['vetoed']} | {r['flips']} | {r['wrong']} | {r['e_t_mean']:.3f} "
              f"| {r['e_R_mean']:.2f} |")
    print("proposed:", "none (no setting keeps a pose without a flip)" if best is None else
          f"image_min_margin_px {best['image_min_margin_px']}, image_min_score {best['image_min_score']}, "
          f"image_min_pixels {best['image_min_pixels']}, image_veto_score {best['image_veto_score']}, "
          f"image_max_chamfer_px {best['image_max_chamfer_px']}, min_flip_pixels {best['min_flip_pixels']} "
          f"({best['kept']} poses kept, {best['by_image']} by the image)")
    _write_out(args, {"image": True, "max_chamfer_px": args.chamfer, "min_margin_px": args.margin,
                      "image_max_background": args.background}, table, best)
    return 0


def _main_flip(args: argparse.Namespace, report: dict[str, Any], rows: list[dict[str, Any]]) -> int:
    fixed = {"max_chamfer_px": args.chamfer, "min_margin_px": args.margin, "image_margin": args.image_margin,
             "image_score": args.score, "image_pixels": args.min_pixels, "image_veto": args.veto,
             "image_chamfer": args.image_chamfer, "flip_pixels": args.flip_min_pixels,
             "max_background": args.background}
    table = flip_gate_table(rows, args.decides or [0.9, 0.95, 0.97, 0.99, 0.995],
                            args.flip_vetoes or [-1.0, 0.01, 0.05, 0.1, 0.2], args.flip_chamfers or [1.5, 2.0, 2.5, 3.0],
                            max_e_t=args.max_e_t, max_e_r=args.max_e_r, **fixed,
                            max_depth_tolerance_m=args.flip_max_tau, max_polish_deg=args.flip_max_polish)
    best = propose_flip(table)
    scored = sum(1 for r in rows if r.get("valid") and math.isfinite(_finite(r.get("flip_prob"))))
    print(f"{scored} of {len(rows)} {report.get('split')} frames with a pose and a classifier score (gates open)")
    print("| decide_prob | veto_prob | max_chamfer_px | kept | decided by it | for the flip | vetoed | flips | wrong "
          "| within | e_t mean m | e_R mean ° |\n|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in table:
        print(f"| {r['decide_prob']:.3f} | {r['veto_prob']:.2f} | {r['max_chamfer_px']:.1f} | {r['kept']} | {r['decided']} "
              f"| {r['for_flip']} | {r['vetoed']} | {r['flips']} | {r['wrong']} | {r['within']} | {r['e_t_mean']:.3f} "
              f"| {r['e_R_mean']:.2f} |")
    print("proposed:", "none (no setting keeps a pose without a flip)" if best is None else
          f"decide_prob {best['decide_prob']}, veto_prob {best['veto_prob']}, max_chamfer_px {best['max_chamfer_px']} "
          f"({best['kept']} poses kept, {best['decided']} decided by the classifier)")
    _write_out(args, {"flip": True, **fixed, "max_depth_tolerance_m": args.flip_max_tau,
                      "max_polish_deg": args.flip_max_polish}, table, best)
    return 0


if __name__ == "__main__":  # pragma: no cover
    import sys

    sys.exit(main())
