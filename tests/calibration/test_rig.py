"""Tests of spacepose.calibration.rig: the StereoRig model and its FileStorage files."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from spacepose.calibration.rig import PAPER_RIG_PATH, StereoRig, load_rig, paper_rig, save_rig
from spacepose.errors import CalibrationError


def distorted_rig() -> StereoRig:
    M1 = np.array([[812.5, 0.25, 318.75], [0.0, 810.0, 241.5], [0.0, 0.0, 1.0]])
    M2 = np.array([[806.0, 0.0, 322.0], [0.0, 805.5, 238.0], [0.0, 0.0, 1.0]])
    D1 = np.array([-0.1, 0.02, 0.001, -0.0005, 0.003])
    D2 = np.array([-0.09, 0.015, 0.0, 0.0, 0.001, 0.0, 0.0, 0.0])  # rational model, 8 coefficients
    R, _ = cv2.Rodrigues(np.array([0.01, -0.03, 0.008]))
    T = np.array([-0.12, 0.001, -0.002])
    return StereoRig(M1, D1, M2, D2, R, T, (640, 480))


def write_storage(path: Path, values: dict[str, object]) -> Path:
    """A FileStorage file holding ``values`` (arrays as opencv-matrix, ints as ints)."""
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for key, value in values.items():
        if isinstance(value, (int, float, str)):
            fs.write(key, value)
        else:
            fs.write(key, np.asarray(value, dtype=np.float64))
    fs.release()
    return path


def rig_values(rig: StereoRig) -> dict[str, object]:
    return {
        "M1": rig.M1, "D1": rig.D1.reshape(1, -1), "M2": rig.M2, "D2": rig.D2.reshape(1, -1),
        "R": rig.R, "T": rig.T.reshape(3, 1), "image_width": rig.width, "image_height": rig.height,
    }


class TestStereoRig:
    def test_arrays_are_float64_read_only_copies(self):
        M = np.array([[800, 0, 320], [0, 800, 240], [0, 0, 1]], dtype=np.int64)
        rig = StereoRig(M, [0, 0, 0, 0], M, np.zeros((1, 5)), np.eye(3), [[-0.1], [0], [0]], (640, 480))
        assert rig.M1.dtype == np.float64 and rig.T.shape == (3,) and rig.D2.shape == (5,)
        with pytest.raises(ValueError):
            rig.M1[0, 0] = 1.0
        M[0, 0] = 1
        assert rig.M1[0, 0] == 800.0

    def test_equality_and_baseline(self):
        assert distorted_rig() == distorted_rig()
        assert distorted_rig() != paper_rig()
        assert distorted_rig().baseline_m == pytest.approx(np.linalg.norm([0.12, 0.001, 0.002]), rel=1e-12)

    @pytest.mark.parametrize(
        "field, value, key",
        [
            ("M1", np.eye(2), "M1"),
            ("M2", np.zeros((3, 4)), "M2"),
            ("M1", np.diag([0.0, 800.0, 1.0]), "M1"),
            ("M2", np.diag([800.0, -800.0, 1.0]), "M2"),
            ("M1", np.array([[800, 0, 320], [0, 800, 240], [0, 0, 2.0]]), "M1"),
            ("M1", np.array([[np.nan, 0, 320], [0, 800, 240], [0, 0, 1.0]]), "M1"),
            ("D1", np.zeros(3), "D1"),
            ("D2", np.zeros((2, 5)), "D2"),
            ("D2", np.array([np.inf, 0, 0, 0, 0]), "D2"),
            ("R", np.eye(4), "R"),
            ("R", 2 * np.eye(3), "R"),
            ("R", np.diag([1.0, 1.0, -1.0]), "R"),
            ("T", np.zeros(3), "T"),
            ("T", np.ones(4), "T"),
            ("T", "far", "T"),
            ("image_size", (0, 480), "image_width"),
            ("image_size", (640, -1), "image_height"),
            ("image_size", (640.5, 480), "image_width"),
            ("image_size", (640,), "image_width"),
            ("image_size", (640, "480"), "image_height"),
        ],
    )
    def test_invalid_parameters_name_the_key(self, field, value, key):
        params = dict(M1=np.diag([800.0, 800.0, 1.0]), D1=np.zeros(5), M2=np.diag([800.0, 800.0, 1.0]),
                      D2=np.zeros(5), R=np.eye(3), T=np.array([-0.1, 0, 0]), image_size=(640, 480))
        params[field] = value
        with pytest.raises(CalibrationError) as info:
            StereoRig(**params)
        assert info.value.key == key

    def test_scaled_follows_pixel_centre_convention(self):
        rig = paper_rig().scaled(640, 480)
        assert rig.M1[0, 0] == 800.0 and rig.M1[1, 1] == 800.0
        assert rig.M1[0, 2] == pytest.approx((639.5 + 0.5) * 0.5 - 0.5)
        assert rig.M2[1, 2] == pytest.approx(239.5)
        assert rig.image_size == (640, 480)
        np.testing.assert_array_equal(rig.T, paper_rig().T)
        assert distorted_rig().scaled(1280, 960).scaled(640, 480).allclose(distorted_rig())

    def test_scaled_rejects_bad_size(self):
        with pytest.raises(CalibrationError, match="image_width") as info:
            paper_rig().scaled(0, 480)
        assert info.value.key == "image_width"

    def test_check_image_size(self):
        rig = paper_rig(640, 480)
        rig.check_image_size((480, 640))
        rig.check_image_size((480, 640, 3))
        with pytest.raises(CalibrationError, match="width 320") as info:
            rig.check_image_size((480, 320, 3))
        assert info.value.key == "image_width"
        with pytest.raises(CalibrationError) as info:
            rig.check_image_size((240, 640))
        assert info.value.key == "image_height"
        with pytest.raises(CalibrationError):
            rig.check_image_size((480,))
        with pytest.raises(CalibrationError):
            rig.check_image_size(None)


class TestPaperRig:
    def test_values_follow_conventions(self):
        rig = paper_rig()
        np.testing.assert_array_equal(rig.M1, [[1600, 0, 639.5], [0, 1600, 479.5], [0, 0, 1]])
        np.testing.assert_array_equal(rig.M2, rig.M1)
        np.testing.assert_array_equal(rig.R, np.eye(3))
        np.testing.assert_array_equal(rig.T, [-1.0, 0.0, 0.0])
        assert not rig.D1.any() and not rig.D2.any()
        assert rig.image_size == (1280, 960) and rig.baseline_m == 1.0
        # d = 160 px at 10 m, 32 px at 50 m
        assert rig.M1[0, 0] * rig.baseline_m / 10.0 == 160.0 and rig.M1[0, 0] * rig.baseline_m / 50.0 == 32.0

    def test_scaled_paper_rig(self):
        assert paper_rig(640, 480) == paper_rig().scaled(640, 480)
        assert paper_rig(640, 480).M1[0, 2] == 319.5

    def test_shipped_file_is_the_paper_rig(self):
        assert PAPER_RIG_PATH.is_file()
        assert load_rig(PAPER_RIG_PATH) == paper_rig()
        fs = cv2.FileStorage(str(PAPER_RIG_PATH), cv2.FILE_STORAGE_READ)
        keys = set(fs.root().keys())
        fs.release()
        assert {"M1", "D1", "M2", "D2", "R", "T", "image_width", "image_height", "R1", "R2", "P1", "P2", "Q"} <= keys

    def test_bad_size(self):
        with pytest.raises(CalibrationError):
            paper_rig(-640, 480)


class TestSaveLoad:
    @pytest.mark.parametrize("ext", [".yaml", ".yml", ".xml", ".json"])
    def test_round_trip_is_exact(self, tmp_path, ext):
        rig = distorted_rig()
        path = save_rig(rig, tmp_path / f"rig{ext}")
        assert load_rig(path) == rig
        assert sorted(p.name for p in tmp_path.iterdir()) == [f"rig{ext}"]  # no temporary file left

    @pytest.mark.parametrize("ext", [".yaml", ".xml", ".json"])
    def test_file_without_rectification_keys(self, tmp_path, ext):
        path = save_rig(distorted_rig(), tmp_path / f"rig{ext}", with_rectification=False)
        assert "Q" not in path.read_text()
        assert load_rig(path) == distorted_rig()

    def test_a_file_r1_other_than_opencvs_is_reported(self, tmp_path, caplog):
        """The pose is in cv2.stereoRectify's left rectified camera; a file whose R1 turns the left
        camera otherwise (another tool's rectification) is loaded, with a warning naming the angle."""
        rig = distorted_rig()
        with caplog.at_level("WARNING", logger="spacepose.calibration.rig"):
            load_rig(save_rig(rig, tmp_path / "own.yaml"))            # save_rig writes OpenCV's own R1
        assert not caplog.records
        from spacepose.calibration.rectify import rectify

        R1 = np.asarray(rectify(rig).R1)
        turned = cv2.Rodrigues(np.array([0.0, 0.0, np.radians(1.0)]))[0] @ R1
        path = write_storage(tmp_path / "other.yaml", {**rig_values(rig), "R1": turned})
        with caplog.at_level("WARNING", logger="spacepose.calibration.rig"):
            assert load_rig(path) == rig
        assert len(caplog.records) == 1 and "1.000 deg" in caplog.text and "ignores it" in caplog.text

    def test_refuses_to_overwrite(self, tmp_path):
        path = tmp_path / "rig.yaml"
        save_rig(paper_rig(), path)
        with pytest.raises(FileExistsError, match="overwrite=True"):
            save_rig(distorted_rig(), path)
        assert load_rig(path) == paper_rig()
        save_rig(distorted_rig(), path, overwrite=True)
        assert load_rig(path) == distorted_rig()

    def test_save_bad_input(self, tmp_path):
        with pytest.raises(CalibrationError, match="extension"):
            save_rig(paper_rig(), tmp_path / "rig.txt")
        with pytest.raises(TypeError):
            save_rig({"M1": np.eye(3)}, tmp_path / "rig.yaml")
        assert not any(tmp_path.iterdir())

    def test_save_creates_parent_folders(self, tmp_path):
        path = save_rig(paper_rig(), tmp_path / "a" / "b" / "rig.json")
        assert load_rig(path) == paper_rig()

    def test_reads_opencv4_yaml_and_plain_sequences(self, tmp_path):
        path = tmp_path / "hand.yml"
        path.write_text(
            "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\n"
            "M1: [[800, 0, 320], [0, 800, 240], [0, 0, 1]]\nD1: [0, 0, 0, 0]\n"
            "M2: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [800, 0, 320, 0, 800, 240, 0, 0, 1]\n"
            "D2: [0, 0, 0, 0, 0]\nR: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\nT: [-0.1, 0, 0]\n"
        )
        rig = load_rig(path)
        assert rig.M1[0, 0] == 800.0 and rig.D1.shape == (4,) and rig.baseline_m == pytest.approx(0.1)

    @pytest.mark.parametrize("key", ["M1", "D1", "M2", "D2", "R", "T", "image_width", "image_height"])
    @pytest.mark.parametrize("ext", [".yaml", ".json"])
    def test_missing_key_is_named(self, tmp_path, key, ext):
        values = rig_values(distorted_rig())
        del values[key]
        path = write_storage(tmp_path / f"rig{ext}", values)
        with pytest.raises(CalibrationError, match=f"missing key '{key}'") as info:
            load_rig(path)
        assert info.value.key == key

    @pytest.mark.parametrize(
        "key, value, match",
        [
            ("M1", np.eye(3)[:2], "3x3"),
            ("M2", np.diag([-800.0, 800.0, 1.0]), "positive"),
            ("D1", np.zeros((1, 3)), "coefficients"),
            ("R", np.eye(2), "3x3"),
            ("R", np.diag([1.0, 2.0, 1.0]), "rotation"),
            ("T", np.zeros((3, 1)), "baseline"),
            ("T", np.ones((2, 2)), "3-vector"),
            ("M1", np.full((3, 3), np.nan), "finite"),
            ("image_width", 0, "positive integer"),
            ("image_height", "tall", "string"),
            ("P1", np.zeros((3, 3)), r"\(3, 4\)"),
            ("Q", np.eye(3), r"\(4, 4\)"),
        ],
    )
    def test_bad_value_is_named(self, tmp_path, key, value, match):
        values = rig_values(distorted_rig())
        values[key] = value
        path = write_storage(tmp_path / "rig.xml", values)
        with pytest.raises(CalibrationError, match=match) as info:
            load_rig(path)
        assert info.value.key == key

    def test_image_size_mismatch_after_load(self, tmp_path):
        rig = load_rig(save_rig(paper_rig(640, 480), tmp_path / "rig.yaml"))
        with pytest.raises(CalibrationError) as info:
            rig.check_image_size((960, 1280, 3))
        assert info.value.key == "image_width"

    def test_malformed_matrix_is_named(self, tmp_path):
        path = tmp_path / "rig.yaml"
        save_rig(paper_rig(), path)
        text = path.read_text().replace("data: [ 1600., 0., 639.5, 0., 1600., 479.5, 0., 0., 1. ]", "data: [ 1600., 0. ]", 1)
        path.write_text(text)
        with pytest.raises(CalibrationError) as info:
            load_rig(path)
        assert info.value.key == "M1"

    @pytest.mark.parametrize(
        "name, content",
        [
            ("corrupt.yaml", "%YAML:1.0\n---\nM1: [1, 2\n"),
            ("empty.json", ""),
            ("garbage.json", "\x00\x01 not json {{"),
            ("broken.xml", "<opencv_storage><M1>"),
            ("list.yaml", "%YAML:1.0\n---\n- 1\n- 2\n"),
        ],
    )
    def test_unparseable_file(self, tmp_path, name, content):
        path = tmp_path / name
        path.write_text(content)
        with pytest.raises(CalibrationError) as info:
            load_rig(path)
        assert info.value.key is None

    def test_missing_file_and_bad_extension(self, tmp_path):
        with pytest.raises(CalibrationError, match="not found") as info:
            load_rig(tmp_path / "nope.yaml")
        assert info.value.key is None
        (tmp_path / "rig.txt").write_text("M1: 1\n")
        with pytest.raises(CalibrationError, match="extension"):
            load_rig(tmp_path / "rig.txt")
