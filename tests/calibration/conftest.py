"""Shared fixtures of the calibration tests: a known distorted rig and chessboard pairs rendered with it."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest

from spacepose.calibration.rig import StereoRig

BOARD = (9, 6)  # inner corners (cols, rows)
SQUARE_M = 0.03
N_POSES = 12


def known_rig() -> StereoRig:
    """fx ~ 800 px, 640x480, k1 ~ -0.1, ~2 deg relative rotation, 0.12 m baseline."""
    M1 = np.array([[800.0, 0.0, 321.0], [0.0, 798.0, 242.0], [0.0, 0.0, 1.0]])
    M2 = np.array([[806.0, 0.0, 316.0], [0.0, 804.0, 237.0], [0.0, 0.0, 1.0]])
    D1 = np.array([-0.10, 0.02, 0.0, 0.0, 0.0])
    D2 = np.array([-0.09, 0.015, 0.0, 0.0, 0.0])
    R, _ = cv2.Rodrigues(np.array([0.01, -0.03, 0.008]))
    T = np.array([-0.12, 0.001, -0.002])
    return StereoRig(M1, D1, M2, D2, R, T, (640, 480))


def _edge_points(x0: float, y0: float, x1: float, y1: float, n: int = 8) -> np.ndarray:
    """Closed outline of the rectangle [x0, x1] x [y0, y1] on z = 0, n samples per edge (distortion bends edges)."""
    t = np.linspace(0.0, 1.0, n, endpoint=False)
    corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]])
    pts = [a + (b - a) * t[:, None] for a, b in zip(corners[:-1], corners[1:])]
    out = np.concatenate(pts)
    return np.hstack([out, np.zeros((len(out), 1))])


def render_board(K, D, rvec, tvec, size, board=BOARD, square=SQUARE_M, rng=None, supersample=4) -> np.ndarray | None:
    """8-bit grey view of the chessboard, or None if it leaves the frame.

    Squares are filled as anti-aliased polygons (edges sampled densely, so lens distortion bends
    them) at ``supersample`` times the resolution, then area-averaged down: corners come out within
    ~0.1 px of their projections.
    """
    cols, rows = board
    w, h = size
    shift = 4
    scale = float(1 << shift) * supersample

    def project(points: np.ndarray) -> np.ndarray:
        uv, _ = cv2.projectPoints(points.astype(np.float64), rvec, tvec, K, D)
        return uv.reshape(-1, 2)

    def to_poly(uv: np.ndarray) -> np.ndarray:  # pixel centres at integers in both resolutions
        return np.round((uv + 0.5 - 0.5 / supersample) * scale).astype(np.int32)

    outline = project(_edge_points(-2 * square, -2 * square, (cols + 1) * square, (rows + 1) * square, n=16))
    if outline.min() < 5 or outline[:, 0].max() > w - 6 or outline[:, 1].max() > h - 6:
        return None
    image = np.full((h * supersample, w * supersample), 90, np.uint8)
    cv2.fillPoly(image, [to_poly(outline)], 235, cv2.LINE_AA, shift)
    polys = []
    for a in range(-1, cols):
        for b in range(-1, rows):
            if (a + b) % 2 == 0:
                square_outline = _edge_points(a * square, b * square, (a + 1) * square, (b + 1) * square)
                polys.append(to_poly(project(square_outline)))
    cv2.fillPoly(image, polys, 20, cv2.LINE_AA, shift)
    image = cv2.resize(image, (w, h), interpolation=cv2.INTER_AREA)
    if rng is not None:
        image = np.clip(image + rng.normal(0.0, 1.5, image.shape), 0, 255).astype(np.uint8)
    return image


@dataclass(frozen=True)
class BoardScene:
    folder: Path
    rig: StereoRig
    names: tuple[str, ...]


def synthesise_pairs(folder: Path, rig: StereoRig, n_poses: int = N_POSES, seed: int = 0) -> BoardScene:
    """Write ``n_poses`` chessboard pairs seen by ``rig`` into folder/left and folder/right (PNG)."""
    rng = np.random.default_rng(seed)
    (folder / "left").mkdir(parents=True, exist_ok=True)
    (folder / "right").mkdir(parents=True, exist_ok=True)
    cols, rows = BOARD
    centre = np.array([(cols - 1) * SQUARE_M / 2, (rows - 1) * SQUARE_M / 2, 0.0])
    names = []
    attempts = 0
    while len(names) < n_poses:
        attempts += 1
        if attempts > 50 * n_poses:
            raise RuntimeError("could not place the chessboard in both views")
        tilt = np.deg2rad(rng.uniform([-35, -35, -20], [35, 35, 20]))
        R_board, _ = cv2.Rodrigues(tilt)
        position = np.array([-rig.T[0] / 2 + rng.uniform(-0.08, 0.08), rng.uniform(-0.06, 0.06), rng.uniform(0.55, 0.85)])
        t_left = position - R_board @ centre
        R_right = rig.R @ R_board
        t_right = rig.R @ t_left + rig.T
        left = render_board(rig.M1, rig.D1, cv2.Rodrigues(R_board)[0], t_left, rig.image_size, rng=rng)
        right = render_board(rig.M2, rig.D2, cv2.Rodrigues(R_right)[0], t_right, rig.image_size, rng=rng)
        if left is None or right is None:
            continue
        name = f"pair_{len(names):02d}.png"
        cv2.imwrite(str(folder / "left" / name), left)
        cv2.imwrite(str(folder / "right" / name), right)
        names.append(name)
    return BoardScene(folder, rig, tuple(names))


@pytest.fixture(scope="session")
def board_scene(tmp_path_factory: pytest.TempPathFactory) -> BoardScene:
    """12 chessboard pairs of :func:`known_rig`, rendered once per test session (read-only for tests)."""
    return synthesise_pairs(tmp_path_factory.mktemp("chessboard"), known_rig())


@pytest.fixture(scope="session")
def kit():
    """This module (board constants, known_rig, render_board, synthesise_pairs).

    Test modules cannot ``import conftest`` under ``--import-mode=importlib``.
    """
    return sys.modules[__name__]
