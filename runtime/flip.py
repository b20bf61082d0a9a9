"""Which of a pose and its 180° flip about a body axis the stereo points support (numpy).

A near-symmetric target (the shipped ``tdrs``) looks almost the same after a half turn about one body
axis. A pose network trained with ``train-pose --symmetric-flip AXIS`` learns the orientation up to
that flip, and the keypoint votes cannot tell the two apart. The geometry can, a little. The target's
surface at the true pose holds more of the stereo points than at the flipped pose. On 300 train
frames with ground-truth points, the true pose scored higher on 96 % of frames, and the flip never
scored higher by more than 0.02. These counts come from the per-frame ``fitness`` rows of
``reports/photo_calibration_train640/photo_calibration.json``. With the stereo points of session 4's
graphs at 10–50 m the gap did not tell the flip (model card), so the shipped bundle leaves this off.

:func:`resolve_flip` scores both poses with :func:`spacepose.pose_stage.surface_fitness` and keeps
the better one. The gap between the two scores is the evidence. The estimator reports the frame
``weak_votes`` when that gap is below the bundle's ``voting.min_flip_margin``.

The flipped pose turns the target about ``axis`` through its centre ``c``:
``X_cam = R (c + S (X - c)) + t``, so ``R_f = R S`` and ``t_f = t + R (c - S c)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .pose_stage import surface_fitness

__all__ = ["FLIP_AXES", "flip_matrix", "flipped_pose", "FlipDecision", "resolve_flip"]

FLIP_AXES = ("x", "y", "z")
_SIGNS = {"x": (1.0, -1.0, -1.0), "y": (-1.0, 1.0, -1.0), "z": (-1.0, -1.0, 1.0)}


def flip_matrix(axis: str) -> np.ndarray:
    """(3, 3) rotation by 180° about body axis ``"x"``, ``"y"`` or ``"z"``."""
    if axis not in _SIGNS:
        raise ValueError(f"flip axis must be one of {FLIP_AXES}, got {axis!r}")
    return np.diag(_SIGNS[axis])


def flipped_pose(R: np.ndarray, t: np.ndarray, centre: np.ndarray, axis: str) -> tuple[np.ndarray, np.ndarray]:
    """The pose (R, t) turned 180° about body ``axis`` through the object-frame ``centre`` (3,)."""
    S = flip_matrix(axis)
    R = np.asarray(R, dtype=np.float64)
    c = np.asarray(centre, dtype=np.float64)
    return R @ S, np.asarray(t, dtype=np.float64) + R @ (c - S @ c)


@dataclass(frozen=True, eq=False)
class FlipDecision:
    """The better-supported of a pose and its flip.

    ``R``/``t`` are the kept pose. ``fitness`` is its surface fitness and ``fitness_other`` that of
    the pose not kept. ``flipped`` says whether the kept pose is the flip of the input pose.
    """

    R: np.ndarray
    t: np.ndarray
    fitness: float
    fitness_other: float
    flipped: bool

    @property
    def margin(self) -> float:
        """``fitness - fitness_other`` (>= 0): how clearly the points prefer the kept pose."""
        return self.fitness - self.fitness_other


def resolve_flip(R: np.ndarray, t: np.ndarray, points: np.ndarray, surface: np.ndarray, centre: np.ndarray,
                 axis: str, tolerance: float,
                 refine: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None
                 ) -> FlipDecision:
    """Keep whichever of (R, t) and its ``axis`` flip puts more of ``points`` (N, 3, camera frame) on
    the ``surface`` samples (S, 3, object frame) within ``tolerance`` metres. A tie keeps the input pose.

    ``refine(R, t) -> (R, t)`` (e.g. ICP against the points), when given, is applied to both poses
    before they are scored, so neither is favoured by having been refined alone.
    """
    R_f, t_f = flipped_pose(R, t, centre, axis)
    if refine is not None:
        R, t = refine(R, t)
        R_f, t_f = refine(R_f, t_f)
    f_in = surface_fitness(R, t, points, surface, tolerance)
    f_flip = surface_fitness(R_f, t_f, points, surface, tolerance)
    if f_flip > f_in:
        return FlipDecision(R_f, t_f, f_flip, f_in, True)
    return FlipDecision(np.asarray(R, dtype=np.float64), np.asarray(t, dtype=np.float64), f_in, f_flip, False)
