"""``spacepose estimate FOLDER --calib RIG --out poses.jsonl``: poses of an image sequence.

FOLDER holds ``left/`` and ``right/`` with identical file names (PNG/JPEG, 8/16-bit, grey or
colour). One JSON line per frame (CONVENTIONS.md), invalid frames included; a missing or corrupt
image gives a ``bad_input`` line and the run goes on. Existing outputs are never overwritten
without ``--force``.
"""

from __future__ import annotations

import argparse
import csv
import json
import logging
import sys
import time
from pathlib import Path
from typing import Iterator, TextIO

import numpy as np

from .cli_args import non_negative_int
from .errors import DatasetError, ImageReadError

HELP = "estimate the target pose for every stereo pair of a folder (left/, right/) -> JSON lines"

IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".pgm", ".ppm")

logger = logging.getLogger(__name__)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("folder", type=Path, help="sequence folder with left/ and right/ subfolders")
    parser.add_argument("--calib", type=Path, required=True, help="stereo calibration (OpenCV FileStorage YAML/XML/JSON)")
    parser.add_argument("--out", type=Path, required=True, help="output JSON lines file (one line per frame)")
    parser.add_argument("--csv", type=Path, default=None, help="also write a CSV summary")
    parser.add_argument("--overlay", type=Path, default=None, help="folder for left images with the projected target box")
    parser.add_argument("--bundle", type=Path, default=None, help="model bundle folder (default: the shipped one)")
    parser.add_argument("--threads", type=int, default=2, help="onnxruntime threads per graph (default 2)")
    parser.add_argument("--no-prior", action="store_true",
                        help="no prior between frames: no tracking")
    parser.add_argument("--prior-window", action="store_true",
                        help="the frame after a valid pose takes its stereo window from that pose, skipping the coarse "
                             "pass (off by default since session 30: poses on it were worse, see the model card)")
    parser.add_argument("--prior-max-gap", type=non_negative_int, default=None, metavar="N",
                        help="frames a valid pose stays the prior while none is valid (default 2 since session 30; 0: the "
                             "next frame only; see the model card)")
    parser.add_argument("--force", action="store_true", help="overwrite existing outputs")


def list_frames(folder: Path) -> list[str]:
    """Sorted file names of ``folder/left`` that are images (their right partners may be missing).

    Raises:
        DatasetError: ``folder/left`` or ``folder/right`` is not a directory.
    """
    for side in ("left", "right"):
        if not (folder / side).is_dir():
            raise DatasetError(f"{folder} has no {side}/ subfolder (a sequence needs left/ and right/)")
    names = sorted(p.name for p in (folder / "left").iterdir()
                   if p.is_file() and p.suffix.lower() in IMAGE_EXTENSIONS)
    extra = sorted(p.name for p in (folder / "right").iterdir()
                   if p.is_file() and p.suffix.lower() in IMAGE_EXTENSIONS and not (folder / "left" / p.name).exists())
    if extra:
        logger.warning("%d right image(s) without a left partner are ignored (e.g. %s)", len(extra), extra[0])
    return names


def read_pair(folder: Path, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Read ``left/name`` and ``right/name``; ImageReadError when either is missing or corrupt."""
    from .imageio import read_image

    return read_image(folder / "left" / name), read_image(folder / "right" / name)


def iter_pairs(folder: Path, names: list[str]) -> Iterator[tuple[str, tuple[np.ndarray, np.ndarray] | None, str]]:
    """``(name, (left, right) or None, error message)`` for each frame."""
    for name in names:
        try:
            yield name, read_pair(folder, name), ""
        except ImageReadError as err:
            yield name, None, str(err)


def frame_stem(name: str) -> str:
    return Path(name).stem


class Progress:
    """A one-line progress bar on a stream (no dependency); silent when ``total`` is 0."""

    def __init__(self, total: int, stream: TextIO | None = None, width: int = 30) -> None:
        self.total, self.width = total, width
        self.stream = sys.stderr if stream is None else stream
        self.start = time.perf_counter()

    def update(self, done: int, note: str = "") -> None:
        if self.total <= 0:
            return
        filled = int(self.width * done / self.total)
        rate = done / max(time.perf_counter() - self.start, 1e-9)
        self.stream.write(f"\r[{'#' * filled}{'.' * (self.width - filled)}] {done}/{self.total} "
                          f"{rate:.2f} frames/s {note[:30]:<30}")
        self.stream.flush()

    def close(self) -> None:
        if self.total > 0:
            self.stream.write("\n")
            self.stream.flush()


def check_outputs(paths: list[Path | None], overlay: Path | None, force: bool) -> None:
    """Refuse to overwrite existing outputs without ``force`` (DatasetError naming the first)."""
    if force:
        return
    for path in paths:
        if path is not None and path.exists():
            raise DatasetError(f"{path} exists; pass --force to overwrite it")
    if overlay is not None and overlay.exists() and any(overlay.iterdir()):
        raise DatasetError(f"overlay folder {overlay} is not empty; pass --force to overwrite it")


def draw_overlay(image: np.ndarray, result, bundle, K: np.ndarray) -> np.ndarray:
    """RGB uint8 copy of ``image`` with the target's projected 3-D bounding box (valid poses)."""
    import cv2

    from .pose_preprocess import to_rgb_uint8

    out = to_rgb_uint8(image).copy()
    if result.valid:
        corners = bundle.bbox_corners @ np.asarray(result.R).T + np.asarray(result.t)
        if np.all(corners[:, 2] > 0):
            uvw = corners @ np.asarray(K).T
            uv = uvw[:, :2] / uvw[:, 2:3]
            for a in range(8):
                for b in range(a + 1, 8):
                    if bin(a ^ b).count("1") == 1:  # corners differing in one axis share an edge
                        pa = tuple(int(round(v)) for v in uv[a])
                        pb = tuple(int(round(v)) for v in uv[b])
                        cv2.line(out, pa, pb, (0, 255, 0), 2, cv2.LINE_AA)
    label = f"{result.status} conf={result.confidence:.2f}"
    colour = (0, 255, 0) if result.valid else (255, 64, 64)
    cv2.putText(out, label, (10, 28), cv2.FONT_HERSHEY_SIMPLEX, 0.8, colour, 2, cv2.LINE_AA)
    return out


CSV_FIELDS = ["frame", "valid", "status", "confidence", "tx", "ty", "tz", "qw", "qx", "qy", "qz", "total_ms",
              "position_valid", "px", "py", "pz"]


def csv_row(record: dict) -> list:
    t = record.get("t") or [None] * 3
    q = record.get("q_wxyz") or [None] * 4
    p = record.get("position") or [None] * 3
    total = sum(record.get("timings_ms", {}).values())
    return [record["frame"], record["valid"], record["status"], f"{record['confidence']:.4f}", *t, *q, f"{total:.1f}",
            bool(record.get("position_valid", False)), *p]


def bad_input_record(name: str, message: str) -> dict:
    """The JSON line of a frame that could not be read."""
    nan3 = [None] * 3
    return {"frame": name, "valid": False, "status": "bad_input", "R": [nan3, nan3, nan3], "t": nan3,
            "q_wxyz": [None] * 4, "confidence": 0.0, "timings_ms": {}, "n_points": 0, "roi": None,
            "tracked": False, "depth_tolerance_m": None, "position": nan3, "position_valid": False, "detail": message}


def run(args: argparse.Namespace) -> int:
    from .estimator import PoseEstimator
    from .imageio import write_image

    folder: Path = args.folder
    names = list_frames(folder)
    check_outputs([args.out, args.csv], args.overlay, args.force)
    extra = {} if args.prior_max_gap is None else {"prior_max_gap": args.prior_max_gap}
    if args.prior_window:
        extra["prior_window"] = True
    estimator = PoseEstimator(args.calib, bundle=args.bundle, threads=args.threads, use_prior=not args.no_prior,
                              **extra)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    if args.overlay is not None:
        args.overlay.mkdir(parents=True, exist_ok=True)
    csv_file = None
    n_valid = n_position = 0
    progress = Progress(len(names))
    try:
        with open(args.out, "w", encoding="utf-8") as out:
            writer = None
            if args.csv is not None:
                csv_file = open(args.csv, "w", encoding="utf-8", newline="")
                writer = csv.writer(csv_file)
                writer.writerow(CSV_FIELDS)
            for i, (name, pair, error) in enumerate(iter_pairs(folder, names)):
                if pair is None:
                    logger.warning("frame %s: %s", name, error)
                    record = bad_input_record(name, error)
                    result = None
                else:
                    result = estimator.estimate(*pair)
                    record = result.to_dict(name)
                n_valid += int(record["valid"])
                n_position += int(record["position_valid"])
                out.write(json.dumps(record) + "\n")
                out.flush()
                if writer is not None:
                    writer.writerow(csv_row(record))
                if args.overlay is not None and pair is not None and result is not None:
                    left_rect = estimator.rectification.rectify_image(pair[0], "left")
                    write_image(args.overlay / (frame_stem(name) + ".png"),
                                draw_overlay(left_rect, result, estimator.bundle, estimator.K))
                progress.update(i + 1, f"{name} {record['status']}")
    finally:
        progress.close()
        if csv_file is not None:
            csv_file.close()
    print(f"{len(names)} frames, {n_valid} valid poses, {n_position} target positions (with or without a pose) "
          f"-> {args.out}")
    return 0
