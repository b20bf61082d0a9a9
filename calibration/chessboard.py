"""Stereo calibration from chessboard image pairs (``findChessboardCorners`` + ``stereoCalibrate``).

Input: a folder with ``left/`` and ``right/`` subfolders holding images of the same chessboard with
identical file names (CONVENTIONS.md, "Image folders"). Pairs that cannot be read or in which the
board is not found in both images are skipped with a warning.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from spacepose.errors import CalibrationError, ShapeError

from .rig import StereoRig

__all__ = [
    "CalibrationResult",
    "IMAGE_EXTENSIONS",
    "MIN_PAIRS",
    "board_object_points",
    "find_chessboard",
    "list_image_pairs",
    "calibrate_stereo",
]

log = logging.getLogger(__name__)

IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
#: fewest usable pairs :func:`calibrate_stereo` accepts
MIN_PAIRS = 3

_FIND_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
_CALIB_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 200, 1e-10)


@dataclass(frozen=True)
class CalibrationResult:
    """What :func:`calibrate_stereo` found.

    Attributes:
        rig: the calibrated rig (image size of the input images).
        rms: RMS reprojection error of ``cv2.stereoCalibrate`` over both images, in pixels.
        n_pairs_used: number of pairs whose board was found in both images.
        pairs_used: their file names; pairs_skipped: the names of the pairs left out.
    """

    rig: StereoRig
    rms: float
    n_pairs_used: int
    pairs_used: tuple[str, ...] = ()
    pairs_skipped: tuple[str, ...] = ()


def _check_board(board: object) -> tuple[int, int]:
    try:
        cols, rows = board  # type: ignore[misc]
        cols, rows = int(cols), int(rows)
    except (TypeError, ValueError) as err:
        raise ValueError(f"board must be (cols, rows) inner corners, got {board!r}") from err
    if cols < 3 or rows < 3:
        raise ValueError(f"board needs at least 3x3 inner corners, got {cols}x{rows}")
    return cols, rows


def board_object_points(board: tuple[int, int], square_m: float) -> np.ndarray:
    """(cols*rows, 3) float32 inner-corner coordinates on the board plane z = 0, row by row, metres."""
    cols, rows = _check_board(board)
    square_m = float(square_m)
    if not np.isfinite(square_m) or square_m <= 0:
        raise ValueError(f"square_m must be a positive length in metres, got {square_m}")
    grid = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2)  # x fastest, as findChessboardCorners orders them
    points = np.zeros((cols * rows, 3), np.float32)
    points[:, :2] = grid * square_m
    return points


def _to_grey8(image: np.ndarray) -> np.ndarray:
    if image.ndim == 3:
        if image.shape[2] == 1:
            image = image[:, :, 0]
        else:
            code = cv2.COLOR_BGRA2GRAY if image.shape[2] == 4 else cv2.COLOR_BGR2GRAY
            image = cv2.cvtColor(image, code)
    if image.dtype != np.uint8:
        image = image.astype(np.float64)
        peak = float(np.max(image)) if image.size else 0.0
        image = cv2.convertScaleAbs(image, alpha=255.0 / peak if peak > 0 else 1.0)
    return image


def find_chessboard(image: np.ndarray, board: tuple[int, int]) -> np.ndarray | None:
    """Sub-pixel inner corners of ``board`` (cols, rows) in ``image``, or None when not found.

    Args:
        image: (H, W) or (H, W, C) image (BGR/RGB order does not matter), uint8, uint16 or float.

    Returns:
        (cols*rows, 1, 2) float32 corners in OpenCV's order, or None.
    """
    if not isinstance(image, np.ndarray) or image.ndim not in (2, 3) or image.size == 0:
        raise ShapeError(f"image must be a non-empty (H, W) or (H, W, C) array, got {getattr(image, 'shape', image)!r}")
    cols, rows = _check_board(board)
    grey = _to_grey8(image)
    found, corners = cv2.findChessboardCorners(grey, (cols, rows), flags=_FIND_FLAGS)
    if not found or corners is None:
        return None
    grid = corners.reshape(rows, cols, 2)
    spacing = min(
        float(np.min(np.linalg.norm(np.diff(grid, axis=1), axis=2))),
        float(np.min(np.linalg.norm(np.diff(grid, axis=0), axis=2))),
    )
    half = int(np.clip(0.4 * spacing, 2, 11))  # search window smaller than a square
    corners = cv2.cornerSubPix(grey, corners.reshape(-1, 1, 2).astype(np.float32), (half, half), (-1, -1), _SUBPIX_CRITERIA)
    return corners.reshape(-1, 1, 2).astype(np.float32)  # OpenCV 5 returns (N, 2), 4.x (N, 1, 2)


def list_image_pairs(folder: str | os.PathLike[str]) -> list[tuple[str, Path, Path]]:
    """``(name, left_path, right_path)`` for the file names present in both ``left/`` and ``right/``, sorted.

    Raises:
        CalibrationError: ``left/`` or ``right/`` is missing.
    """
    folder = Path(folder)
    sides = {}
    for side in ("left", "right"):
        sub = folder / side
        if not sub.is_dir():
            raise CalibrationError(f"{folder}: no {side}/ subfolder (a calibration folder holds left/ and right/)")
        sides[side] = {p.name: p for p in sub.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_EXTENSIONS}
    names = sorted(set(sides["left"]) & set(sides["right"]))
    for name in sorted(set(sides["left"]) ^ set(sides["right"])):
        log.warning("%s: %s has no partner in the other camera's folder; skipped", folder, name)
    return [(name, sides["left"][name], sides["right"][name]) for name in names]


def _order_like(reference: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Reverse ``corners`` if findChessboardCorners ordered them the other way round (180 deg)."""
    ref = reference.reshape(-1, 2)
    cur = corners.reshape(-1, 2)
    if float(np.dot(ref[-1] - ref[0], cur[-1] - cur[0])) < 0:
        return corners[::-1].copy()
    return corners


def calibrate_stereo(
    folder: str | os.PathLike[str],
    board: tuple[int, int] = (9, 6),
    square_m: float = 0.025,
    fix_k3: bool = True,
) -> CalibrationResult:
    """Calibrate a stereo rig from chessboard pairs in ``folder/left`` and ``folder/right``.

    Each camera is first calibrated alone (``cv2.calibrateCamera``), then both are refined together
    with ``cv2.stereoCalibrate`` (``CALIB_USE_INTRINSIC_GUESS``); ``T`` comes out in the unit of
    ``square_m`` (metres).

    Args:
        folder: folder with ``left/`` and ``right/`` image subfolders (identical file names).
        board: inner corners per row and per column, as in OpenCV's ``patternSize`` (e.g. (9, 6)).
        square_m: side of one board square in metres.
        fix_k3: keep k3 = 0 (recommended unless the views cover the image corners well).

    Raises:
        CalibrationError: missing subfolders, images of different sizes only, or fewer than
            :data:`MIN_PAIRS` usable pairs.
        ValueError: a bad ``board`` or ``square_m``.
    """
    board = _check_board(board)
    object_points = board_object_points(board, square_m)
    pairs = list_image_pairs(folder)
    image_size: tuple[int, int] | None = None  # set by the first usable pair
    used: list[str] = []
    skipped: list[str] = []
    left_points: list[np.ndarray] = []
    right_points: list[np.ndarray] = []
    for name, left_path, right_path in pairs:
        images = [cv2.imread(str(p), cv2.IMREAD_UNCHANGED) for p in (left_path, right_path)]
        if any(img is None for img in images):
            log.warning("%s: cannot read the image pair; skipped", name)
            skipped.append(name)
            continue
        sizes = {(img.shape[1], img.shape[0]) for img in images}
        if len(sizes) != 1 or (image_size is not None and sizes != {image_size}):
            log.warning("%s: image size %s differs from %s; skipped", name, sorted(sizes), image_size)
            skipped.append(name)
            continue
        corners = [find_chessboard(img, board) for img in images]
        if corners[0] is None or corners[1] is None:
            log.warning("%s: chessboard %dx%d not found in both images; skipped", name, *board)
            skipped.append(name)
            continue
        image_size = sizes.pop()
        left_points.append(corners[0])
        right_points.append(_order_like(corners[0], corners[1]))
        used.append(name)
    if len(used) < MIN_PAIRS:
        raise CalibrationError(
            f"{folder}: only {len(used)} of {len(pairs)} image pairs show the {board[0]}x{board[1]} chessboard in both "
            f"images; need at least {MIN_PAIRS}"
        )
    objects = [object_points] * len(used)
    flags = cv2.CALIB_FIX_K3 if fix_k3 else 0
    _, M1, D1, _, _ = cv2.calibrateCamera(objects, left_points, image_size, None, None, flags=flags)
    _, M2, D2, _, _ = cv2.calibrateCamera(objects, right_points, image_size, None, None, flags=flags)
    rms, M1, D1, M2, D2, R, T, *_ = cv2.stereoCalibrate(
        objects, left_points, right_points, M1, D1, M2, D2, image_size,
        flags=cv2.CALIB_USE_INTRINSIC_GUESS | flags, criteria=_CALIB_CRITERIA,
    )
    rig = StereoRig(M1, D1, M2, D2, R, T, image_size)
    log.info("calibrated %d pairs: RMS %.4f px, fx %.2f px, baseline %.5f m", len(used), rms, rig.M1[0, 0], rig.baseline_m)
    return CalibrationResult(rig, float(rms), len(used), tuple(used), tuple(skipped))
