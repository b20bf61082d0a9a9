"""Tests of spacepose.calibration.chessboard on chessboard pairs rendered with a known distorted rig."""

from __future__ import annotations

import logging
import shutil

import cv2
import numpy as np
import pytest

from spacepose.calibration.chessboard import (
    MIN_PAIRS,
    board_object_points,
    calibrate_stereo,
    find_chessboard,
    list_image_pairs,
)
from spacepose.errors import CalibrationError, ShapeError

TOLERANCE = 0.005  # the bar: fx and baseline within 0.5 %
BOARD = (9, 6)  # as in conftest (checked by test_board_matches_scene)
SQUARE_M = 0.03


def rotation_angle_deg(R: np.ndarray) -> float:
    return float(np.rad2deg(np.linalg.norm(cv2.Rodrigues(R)[0])))


def copy_pairs(scene, dst, names):
    for side in ("left", "right"):
        (dst / side).mkdir(parents=True, exist_ok=True)
        for name in names:
            shutil.copy(scene.folder / side / name, dst / side / name)
    return dst


@pytest.fixture(scope="module")
def result(board_scene):
    return calibrate_stereo(board_scene.folder, board=BOARD, square_m=SQUARE_M)


class TestCalibrateStereo:
    def test_recovers_focal_length_and_baseline(self, result, board_scene):
        truth = board_scene.rig
        assert result.n_pairs_used == len(board_scene.names) and result.pairs_skipped == ()
        assert result.rig.image_size == truth.image_size
        assert result.rig.M1[0, 0] == pytest.approx(truth.M1[0, 0], rel=TOLERANCE)
        assert result.rig.M2[0, 0] == pytest.approx(truth.M2[0, 0], rel=TOLERANCE)
        assert result.rig.baseline_m == pytest.approx(truth.baseline_m, rel=TOLERANCE)

    def test_recovers_the_rest_of_the_rig(self, result, board_scene):
        truth = board_scene.rig
        assert result.rms < 0.3
        assert rotation_angle_deg(result.rig.R @ truth.R.T) < 0.3  # the true relative rotation is ~1.9 deg
        np.testing.assert_allclose(result.rig.M1[:2, 2], truth.M1[:2, 2], atol=3.0)
        assert result.rig.D1[0] == pytest.approx(truth.D1[0], abs=0.02)
        assert result.rig.T[0] < 0  # right camera to the right, in metres

    def test_skips_unreadable_and_boardless_pairs(self, board_scene, tmp_path, caplog):
        folder = copy_pairs(board_scene, tmp_path / "cal", board_scene.names[:4])
        (folder / "left" / "corrupt.png").write_bytes(b"not a png")
        (folder / "right" / "corrupt.png").write_bytes(b"not a png")
        blank = np.full((480, 640), 128, np.uint8)
        cv2.imwrite(str(folder / "left" / "blank.png"), blank)
        cv2.imwrite(str(folder / "right" / "blank.png"), blank)
        cv2.imwrite(str(folder / "left" / "lonely.png"), blank)
        with caplog.at_level(logging.WARNING):
            result = calibrate_stereo(folder, board=BOARD, square_m=SQUARE_M)
        assert result.n_pairs_used == 4
        assert set(result.pairs_skipped) == {"corrupt.png", "blank.png"}
        messages = " ".join(r.getMessage() for r in caplog.records)
        assert "corrupt.png" in messages and "blank.png" in messages and "lonely.png" in messages

    def test_too_few_pairs(self, board_scene, tmp_path):
        folder = copy_pairs(board_scene, tmp_path / "cal", board_scene.names[: MIN_PAIRS - 1])
        with pytest.raises(CalibrationError, match="need at least 3"):
            calibrate_stereo(folder, board=BOARD, square_m=SQUARE_M)

    def test_wrong_board_size_finds_nothing(self, board_scene, tmp_path):
        folder = copy_pairs(board_scene, tmp_path / "cal", board_scene.names[:1])  # a failed search is slow
        with pytest.raises(CalibrationError, match="only 0 of 1"):
            calibrate_stereo(folder, board=(7, 5), square_m=SQUARE_M)

    def test_bad_arguments(self, board_scene, tmp_path):
        with pytest.raises(CalibrationError, match="left/"):
            calibrate_stereo(tmp_path, board=BOARD, square_m=SQUARE_M)
        with pytest.raises(ValueError, match="square_m"):
            calibrate_stereo(board_scene.folder, board=BOARD, square_m=0.0)
        with pytest.raises(ValueError, match="board"):
            calibrate_stereo(board_scene.folder, board=(9,), square_m=SQUARE_M)


def test_board_matches_scene(kit):
    assert (kit.BOARD, kit.SQUARE_M) == (BOARD, SQUARE_M)


class TestFindChessboard:
    @pytest.fixture
    def view(self, kit):
        rig = kit.known_rig()
        rvec = np.array([0.2, -0.3, 0.1])
        centre = np.array([(BOARD[0] - 1) * SQUARE_M / 2, (BOARD[1] - 1) * SQUARE_M / 2, 0.0])
        tvec = np.array([0.0, 0.0, 0.7]) - cv2.Rodrigues(rvec)[0] @ centre
        image = kit.render_board(rig.M1, rig.D1, rvec, tvec, rig.image_size)
        truth, _ = cv2.projectPoints(board_object_points(BOARD, SQUARE_M).astype(np.float64), rvec, tvec, rig.M1, rig.D1)
        return image, truth.reshape(-1, 2)

    @pytest.mark.parametrize("kind", ["grey", "colour", "uint16"])
    def test_corners_match_projection(self, kind, view):
        image, truth = view
        if kind == "colour":
            image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
        elif kind == "uint16":
            image = image.astype(np.uint16) * 257
        corners = find_chessboard(image, BOARD)
        assert corners.shape == (BOARD[0] * BOARD[1], 1, 2) and corners.dtype == np.float32
        corners = corners.reshape(-1, 2)
        if np.dot(corners[-1] - corners[0], truth[-1] - truth[0]) < 0:
            corners = corners[::-1]
        error = np.linalg.norm(corners - truth, axis=1)
        assert np.sqrt(np.mean(error**2)) < 0.2 and error.max() < 0.5

    def test_no_board(self):
        assert find_chessboard(np.full((480, 640), 128, np.uint8), BOARD) is None

    def test_bad_input(self):
        with pytest.raises(ShapeError):
            find_chessboard(np.zeros(10, np.uint8), BOARD)
        with pytest.raises(ShapeError):
            find_chessboard("image.png", BOARD)
        with pytest.raises(ValueError, match="3x3"):
            find_chessboard(np.zeros((480, 640), np.uint8), (2, 6))


class TestHelpers:
    def test_board_object_points(self):
        points = board_object_points((4, 3), 0.5)
        assert points.shape == (12, 3) and points.dtype == np.float32
        np.testing.assert_array_equal(points[:5], [[0, 0, 0], [0.5, 0, 0], [1.0, 0, 0], [1.5, 0, 0], [0, 0.5, 0]])
        for bad in (0.0, -1.0, float("nan")):
            with pytest.raises(ValueError):
                board_object_points((4, 3), bad)
        with pytest.raises(ValueError):
            board_object_points("9x6", 0.025)

    def test_list_image_pairs(self, tmp_path, caplog):
        for side in ("left", "right"):
            (tmp_path / side).mkdir()
            (tmp_path / side / "a.png").write_bytes(b"")
            (tmp_path / side / "b.JPG").write_bytes(b"")
            (tmp_path / side / "notes.txt").write_text("")
        (tmp_path / "right" / "c.png").write_bytes(b"")
        with caplog.at_level(logging.WARNING):
            pairs = list_image_pairs(tmp_path)
        assert [name for name, _, _ in pairs] == ["a.png", "b.JPG"]
        assert pairs[0][1] == tmp_path / "left" / "a.png" and pairs[0][2] == tmp_path / "right" / "a.png"
        assert "c.png" in caplog.text

    def test_list_image_pairs_missing_folder(self, tmp_path):
        (tmp_path / "left").mkdir()
        with pytest.raises(CalibrationError, match="right/"):
            list_image_pairs(tmp_path)
