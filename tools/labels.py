"""The one reader of a dataset's ``labels.jsonl`` (layout of CONVENTIONS.md).

Used by the stereo samples (:mod:`~spacepose.tools.stereo_data`), the pose samples
(:mod:`~spacepose.tools.pose_data`) and the dataset card (:mod:`~spacepose.tools.dataset_card`);
each asks for the keys it cannot do without (``require``).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable

import numpy as np

from spacepose.errors import DatasetError

__all__ = ["FrameLabel", "read_labels"]


@dataclass(frozen=True)
class FrameLabel:
    """One line of ``labels.jsonl``: frame name, split, regime, pose (``X_cam = R X_obj + t``), degradations."""

    frame: str
    split: str
    regime: str
    R: np.ndarray | None = None  # (3, 3) object -> camera; None when the line has no "R"
    t: np.ndarray | None = None  # (3,) metres; None when the line has no "t"
    degradations: dict = field(default_factory=dict)

    @property
    def distance_m(self) -> float:
        """Target distance along the optical axis, ``t[2]`` (NaN without a pose)."""
        return float(self.t[2]) if self.t is not None else float("nan")

    @property
    def camera_in_body(self) -> np.ndarray:
        """Camera centre in the target body frame, (3,): ``-R^T t``."""
        return -self.R.T @ self.t


def read_labels(root: str | Path, split: str | None = None, *, require: Iterable[str] = ()) -> list[FrameLabel]:
    """Frames of ``root/labels.jsonl`` (optionally of one split), in file order.

    ``frame`` is always required, and so is every key in ``require`` (e.g. ``"R"``, ``"t"``,
    ``"split"``); without them ``split`` reads as ``"train"``, ``regime`` as ``"unknown"``, and
    ``R`` / ``t`` as None.

    Raises:
        DatasetError: no labels.jsonl, or a line that is not JSON, lacks a required key or holds a
            malformed pose.
    """
    path = Path(root) / "labels.jsonl"
    if not path.is_file():
        raise DatasetError(f"{path} not found: not a spacepose dataset folder")
    required = ("frame", *require)
    out = []
    with open(path, encoding="utf-8") as fh:
        for lineno, line in enumerate(fh, 1):
            if not line.strip():
                continue
            try:
                obj = json.loads(line)
                for key in required:
                    obj[key]
                rec = FrameLabel(
                    frame=str(obj["frame"]),
                    split=str(obj.get("split", "train")),
                    regime=str(obj.get("regime", "unknown")),
                    R=np.asarray(obj["R"], dtype=np.float64).reshape(3, 3) if "R" in obj else None,
                    t=np.asarray(obj["t"], dtype=np.float64).reshape(3) if "t" in obj else None,
                    degradations=dict(obj.get("degradations", {})),
                )
            except (KeyError, TypeError, ValueError, IndexError) as err:
                raise DatasetError(f"{path}:{lineno}: malformed label line ({err!r})") from err
            if split is None or rec.split == split:
                out.append(rec)
    return out
