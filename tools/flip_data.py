"""Training samples of the flip classifier (:mod:`spacepose.models.flip_net`) from a rendered dataset.

A sample is one view of :func:`spacepose.flip_views.flip_views` and its label. It mimics what the run
time asks (:mod:`spacepose.flip_classifier`): the outline stage's winner and that winner's exact flip.
The winner is the true pose, perturbed as the refinements leave it (:class:`FlipSampleConfig`), or
the true pose's flip, perturbed the same way; the other pose is the winner's exact 180° flip about
body ``axis``. Which of the two lands in slot A is drawn at random; the label is 1 when slot A holds
the pose near the truth. With probability ``neither_prob`` the winner is a wrong pose instead
(:func:`wrong_pose`: the outline stage's other mistakes, a half turn about another body axis or
about the line of sight, or a turn of 25–155°), so that neither slot holds the truth, and the label
is 0.5: the classifier must stay unsure when both poses are wrong. The window is the stereo stage's
(1.25 times the longest side of the target's box joined with its right-image copy), with its side
and centre jittered.

The views are cached once (``flip_samples.npz``: grey as float16, outlines as uint8); photometric
augmentation happens in the training loop (:func:`augment_views`), on the cached views.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from spacepose.flip import flipped_pose
from spacepose.flip_views import flip_views
from spacepose.imageio import read_image
from spacepose.registration import exp_so3, rotation_angle_deg
from spacepose.tools.labels import read_labels

log = logging.getLogger(__name__)

__all__ = ["FlipSampleConfig", "perturb_pose", "wrong_pose", "stereo_window", "make_flip_samples", "save_samples",
           "load_samples", "samples_info", "augment_views"]


@dataclass(frozen=True)
class FlipSampleConfig:
    """How candidate poses and windows are drawn.

    rot_sigma_deg: spread of the rotation error (a random axis, |N(0, sigma)|); with probability
        ``wide_prob`` it is drawn from U(0, ``rot_wide_deg``) instead. lateral_sigma_m, range_sigma_m:
        translation error across and along the line of sight. side_range: the window side's factor
        over the stereo stage's; centre_jitter: window centre shift (units of its side).
    neither_prob: share of samples whose winner is a wrong pose (:func:`wrong_pose`, label 0.5).
    """

    size: int = 128
    axis: str = "z"
    margin: float = 1.25
    rot_sigma_deg: float = 3.0
    rot_wide_deg: float = 12.0
    wide_prob: float = 0.2
    lateral_sigma_m: float = 0.05
    range_sigma_m: float = 0.3
    side_range: tuple[float, float] = (0.9, 1.35)
    centre_jitter: float = 0.06
    neither_prob: float = 0.0


def perturb_pose(R: np.ndarray, t: np.ndarray, rng: np.random.Generator, config: FlipSampleConfig
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(R, t) turned about a random axis through the target and shifted (class docstring of the config)."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    if rng.random() < config.wide_prob:
        angle = rng.uniform(0.0, config.rot_wide_deg)
    else:
        angle = abs(rng.normal(0.0, config.rot_sigma_deg))
    R2 = exp_so3(axis * math.radians(angle)) @ R
    los = t / max(float(np.linalg.norm(t)), 1e-9)
    shift = rng.normal(0.0, config.lateral_sigma_m, size=3)
    shift -= los * float(shift @ los)
    shift += los * rng.normal(0.0, config.range_sigma_m)
    return R2, t + shift


def wrong_pose(R: np.ndarray, t: np.ndarray, centre: np.ndarray, axis: str, rng: np.random.Generator
               ) -> tuple[np.ndarray, np.ndarray]:
    """(R, t) turned about the object-frame ``centre`` (3,) so that neither it nor its flip about body
    ``axis`` is within 30° of it: a half turn about one of the other two body axes or about the line of
    sight (each within 15° of it), or a turn of 25–155° about a random axis, as the outline stage gets
    a pose wrong (a mirror-like outline fits these well)."""
    c = np.asarray(centre, dtype=np.float64)
    R = np.asarray(R, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    flip = flipped_pose(R, t, c, axis)[0]
    centre_cam = R @ c + t
    while True:
        kind = rng.random()
        if kind < 0.4:
            other = [a for a in "xyz" if a != axis][int(rng.integers(2))]
            body = np.eye(3)["xyz".index(other)]
            turn = R @ exp_so3(body * math.pi) @ R.T
        elif kind < 0.7:
            turn = exp_so3(centre_cam / max(float(np.linalg.norm(centre_cam)), 1e-9) * math.pi)  # line of sight
        else:
            a = rng.normal(size=3)
            turn = exp_so3(a / np.linalg.norm(a) * math.radians(rng.uniform(25.0, 155.0)))
        if kind < 0.7:
            a = rng.normal(size=3)
            turn = exp_so3(a / np.linalg.norm(a) * math.radians(rng.uniform(0.0, 15.0))) @ turn
        R2 = turn @ R
        if min(rotation_angle_deg(R2, R), rotation_angle_deg(R2, flip)) >= 30.0:
            return R2, centre_cam - R2 @ c


def stereo_window(points: np.ndarray, R: np.ndarray, t: np.ndarray, K: np.ndarray, baseline_m: float,
                  rng: np.random.Generator | None, config: FlipSampleConfig) -> tuple[int, int, int]:
    """(x0, y0, side): the stereo stage's window over the target's ``points`` (S, 3) at (R, t), jittered
    with ``rng`` (none without it)."""
    X = points @ R.T + t
    u = K[0, 0] * X[:, 0] / X[:, 2] + K[0, 2]
    v = K[1, 1] * X[:, 1] / X[:, 2] + K[1, 2]
    d_max = K[0, 0] * baseline_m / float(X[:, 2].min())
    x0, x1, y0, y1 = float(u.min()) - d_max, float(u.max()), float(v.min()), float(v.max())
    side = max(x1 - x0, y1 - y0) * config.margin
    cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    if rng is not None:
        side *= rng.uniform(*config.side_range)
        cx += rng.uniform(-1.0, 1.0) * config.centre_jitter * side
        cy += rng.uniform(-1.0, 1.0) * config.centre_jitter * side
    side_i = max(32, int(math.ceil(side)))
    return int(round(cx - side_i / 2.0)), int(round(cy - side_i / 2.0)), side_i


def make_flip_samples(root: str | Path, silhouette_points: np.ndarray, centre: np.ndarray, *, split: str | None,
                      per_frame: int, seed: int, config: FlipSampleConfig = FlipSampleConfig(),
                      limit: int | None = None) -> dict[str, np.ndarray]:
    """Views of ``per_frame`` samples for each frame of ``root`` (of ``split``; the first ``limit``).

    Returns ``views`` (N, 3, S, S) float32, ``labels`` (N,) float32 (1: slot A near the truth, 0.5:
    neither, ``config.neither_prob``),
    ``frame`` (N,) int index into the frames read, ``regime`` (N,) str, ``distance`` (N,) float.
    """
    from spacepose.calibration.rig import load_rig

    root = Path(root)
    rig = load_rig(root / "rig.yaml")
    K, baseline = np.asarray(rig.M1, dtype=np.float64), float(rig.baseline_m)
    frames = read_labels(root, split, require=("R", "t"))[:limit]
    pts32 = np.asarray(silhouette_points, dtype=np.float32)
    views, labels, index, regimes, distances = [], [], [], [], []
    for i, rec in enumerate(frames):
        rng = np.random.default_rng([seed, i])
        image = read_image(root / "left" / f"{rec.frame}.png")
        R_true, t_true = np.asarray(rec.R, np.float64), np.asarray(rec.t, np.float64)
        for _ in range(per_frame):
            truth_first = bool(rng.random() < 0.5)
            base = (R_true, t_true) if truth_first else flipped_pose(R_true, t_true, centre, config.axis)
            neither = config.neither_prob > 0 and bool(rng.random() < config.neither_prob)
            if neither:
                base = wrong_pose(R_true, t_true, centre, config.axis, rng)
            winner = perturb_pose(*base, rng, config)
            rival = flipped_pose(*winner, centre, config.axis)
            window = stereo_window(pts32, *winner, K, baseline, rng, config)
            a_is_winner = bool(rng.random() < 0.5)
            pose_a, pose_b = (winner, rival) if a_is_winner else (rival, winner)
            views.append(flip_views(image, K, window, pts32, pose_a, pose_b, config.size))
            labels.append(0.5 if neither else float(truth_first == a_is_winner))
            index.append(i)
            regimes.append(rec.regime)
            distances.append(float(np.linalg.norm(t_true)))
        if (i + 1) % 200 == 0:
            log.info("flip samples: %d / %d frames", i + 1, len(frames))
    return {"views": np.stack(views), "labels": np.asarray(labels, np.float32), "frame": np.asarray(index),
            "regime": np.asarray(regimes), "distance": np.asarray(distances)}


def save_samples(samples: dict[str, np.ndarray], path: str | Path, info: dict[str, Any]) -> None:
    """Compact cache: grey as float16, outlines as uint8."""
    v = samples["views"]
    np.savez(path, grey=v[:, 0].astype(np.float16), outlines=(v[:, 1:] > 0.5).astype(np.uint8),
             labels=samples["labels"], frame=samples["frame"], regime=samples["regime"],
             distance=samples["distance"], info=np.asarray(repr(info)))


def load_samples(path: str | Path) -> dict[str, np.ndarray]:
    """The arrays of :func:`save_samples`, ``views`` rebuilt as (N, 3, S, S) float32."""
    with np.load(path) as z:
        grey, outlines = z["grey"].astype(np.float32), z["outlines"].astype(np.float32)
        out = {k: z[k] for k in ("labels", "frame", "regime", "distance")}
    out["views"] = np.concatenate([grey[:, None], outlines], axis=1)
    return out


def samples_info(path: str | Path) -> dict[str, Any]:
    """The settings :func:`save_samples` stored with a cache (``{}`` for a cache without them)."""
    import ast

    with np.load(path) as z:
        if "info" not in z.files:
            return {}
        info = ast.literal_eval(str(z["info"]))
    return info if isinstance(info, dict) else {}


def augment_views(views: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Photometric augmentation of the grey plane of (N, 3, S, S) views (a copy): gamma 0.5–2, a smooth
    lit background (an Earth limb or glow behind the target) on a third of them, Gaussian blur,
    additive noise, a re-normalised brightness. The outlines are untouched."""
    import cv2

    out = views.copy()
    n, _, s, _ = out.shape
    yy, xx = np.mgrid[0:s, 0:s].astype(np.float32) / s
    for k in range(n):
        g = out[k, 0]
        g = 2.0 * (np.clip(g, 0.0, 2.0) / 2.0) ** np.float32(math.exp(rng.uniform(math.log(0.5), math.log(2.0))))
        if rng.random() < 0.33:
            a, b = rng.normal(size=2)
            ramp = (a * (xx - 0.5) + b * (yy - 0.5)) / max(math.hypot(a, b), 1e-6)
            level = rng.uniform(0.05, 0.8)
            edge = rng.uniform(-0.3, 0.3)
            g = np.maximum(g, level * np.clip((ramp - edge) * rng.uniform(2.0, 20.0), 0.0, 1.0))
        sigma = rng.uniform(0.0, 1.5)
        if sigma > 0.3:
            g = cv2.GaussianBlur(g, (0, 0), sigma)
        g = g + rng.normal(0.0, rng.uniform(0.0, 0.08), size=g.shape).astype(np.float32)
        g = g * np.float32(rng.uniform(0.7, 1.3))
        out[k, 0] = np.clip(g, 0.0, 2.0)
    return out
