"""Tests of spacepose.imageio: PNG/JPEG round trips (RGB order, 8/16-bit, alpha), PFM, errors."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from spacepose.errors import ImageReadError, ShapeError
from spacepose.imageio import read_image, read_pfm, write_image, write_pfm


def _rgb(dtype=np.uint8, shape=(6, 8)) -> np.ndarray:
    rng = np.random.default_rng(0)
    high = np.iinfo(dtype).max
    return rng.integers(0, high, size=(*shape, 3), endpoint=True).astype(dtype)


class TestReadWriteImage:
    @pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
    @pytest.mark.parametrize("colour", [True, False])
    def test_png_round_trip(self, tmp_path, dtype, colour):
        image = _rgb(dtype) if colour else _rgb(dtype)[:, :, 0].copy()
        path = tmp_path / "frame.png"
        write_image(path, image)
        back = read_image(path)
        assert back.dtype == dtype and back.shape == image.shape
        np.testing.assert_array_equal(back, image)

    def test_rgb_order_on_disk(self, tmp_path):
        """A pure red RGB image is stored as red (OpenCV reads it as BGR = (0, 0, 255))."""
        image = np.zeros((4, 4, 3), np.uint8)
        image[..., 0] = 255
        path = tmp_path / "red.png"
        write_image(path, image)
        bgr = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        np.testing.assert_array_equal(bgr[0, 0], [0, 0, 255])
        np.testing.assert_array_equal(read_image(path)[0, 0], [255, 0, 0])

    def test_png_written_by_opencv_reads_as_rgb(self, tmp_path):
        bgr = np.zeros((3, 5, 3), np.uint16)
        bgr[..., 0] = 1000  # blue
        path = tmp_path / "blue16.png"
        assert cv2.imwrite(str(path), bgr)
        rgb = read_image(path)
        assert rgb.dtype == np.uint16
        np.testing.assert_array_equal(rgb[0, 0], [0, 0, 1000])

    def test_alpha_is_dropped(self, tmp_path):
        bgra = np.zeros((3, 4, 4), np.uint8)
        bgra[..., 1] = 200  # green
        bgra[..., 3] = 17  # alpha
        path = tmp_path / "alpha.png"
        assert cv2.imwrite(str(path), bgra)
        rgb = read_image(path)
        assert rgb.shape == (3, 4, 3)
        np.testing.assert_array_equal(rgb[1, 1], [0, 200, 0])

    @pytest.mark.parametrize("name", ["frame.jpg", "FRAME.JPEG"])
    def test_jpeg_round_trip(self, tmp_path, name):
        image = np.zeros((16, 16, 3), np.uint8)
        image[..., 0] = 200
        image[..., 2] = 40
        path = tmp_path / name
        write_image(path, image)
        back = read_image(path)
        assert back.dtype == np.uint8 and back.shape == image.shape
        assert np.max(np.abs(back.astype(int) - image.astype(int))) <= 3  # lossy
        grey = np.full((16, 16), 77, np.uint8)
        write_image(path, grey)
        assert read_image(path).shape == (16, 16)

    def test_missing_file(self, tmp_path):
        path = tmp_path / "nope.png"
        with pytest.raises(ImageReadError, match="nope.png"):
            read_image(path)

    def test_empty_file(self, tmp_path):
        path = tmp_path / "empty.png"
        path.write_bytes(b"")
        with pytest.raises(ImageReadError, match=r"empty\.png.*empty"):
            read_image(path)

    def test_corrupt_file(self, tmp_path):
        path = tmp_path / "corrupt.png"
        path.write_bytes(b"\x89PNG\r\n\x1a\n this is not really a png")
        with pytest.raises(ImageReadError, match=r"corrupt\.png"):
            read_image(path)

    def test_read_error_is_oserror(self, tmp_path):
        with pytest.raises(OSError):
            read_image(tmp_path / "missing.jpg")

    def test_write_unsupported_extension(self, tmp_path):
        with pytest.raises(ValueError, match=r"unsupported extension '\.bmp'"):
            write_image(tmp_path / "x.bmp", _rgb())
        with pytest.raises(ValueError, match="unsupported extension"):
            write_image(tmp_path / "noext", _rgb())

    def test_write_uint16_jpeg_refused(self, tmp_path):
        with pytest.raises(ValueError, match="JPEG holds 8-bit"):
            write_image(tmp_path / "x.jpg", _rgb(np.uint16))

    def test_write_bad_input(self, tmp_path):
        path = tmp_path / "x.png"
        with pytest.raises(ShapeError, match=r"image must have shape \(\*, \*, 3\)"):
            write_image(path, np.zeros((4, 4, 4), np.uint8))
        with pytest.raises(ShapeError, match=r"shape \(H, W\) or \(H, W, 3\)"):
            write_image(path, np.zeros((4,), np.uint8))
        with pytest.raises(ShapeError, match=r"dtype uint8 or uint16"):
            write_image(path, np.zeros((4, 4), np.float32))
        with pytest.raises(ShapeError, match="must not be empty"):
            write_image(path, np.zeros((0, 4), np.uint8))
        with pytest.raises(ValueError, match="jpeg_quality"):
            write_image(tmp_path / "x.jpg", np.zeros((4, 4), np.uint8), jpeg_quality=101)
        assert not path.exists()


class TestPfm:
    @pytest.mark.parametrize("shape", [(5, 7), (4, 6, 3)])
    def test_round_trip(self, tmp_path, shape):
        rng = np.random.default_rng(1)
        array = rng.normal(size=shape).astype(np.float32)
        array.flat[0] = np.inf  # "unknown" marker survives
        path = tmp_path / "d.pfm"
        write_pfm(path, array)
        back = read_pfm(path)
        assert back.dtype == np.float32 and back.shape == shape
        np.testing.assert_array_equal(back, array)

    def test_file_layout(self, tmp_path):
        """Little endian, scale -1, rows bottom-to-top, header as Middlebury writes it."""
        array = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]], np.float32)
        path = tmp_path / "d.pfm"
        write_pfm(path, array)
        data = path.read_bytes()
        header = b"Pf\n3 2\n-1.0\n"
        assert data.startswith(header)
        np.testing.assert_array_equal(np.frombuffer(data[len(header):], "<f4"), [4, 5, 6, 1, 2, 3])

    def test_big_endian_read(self, tmp_path):
        top_down = np.array([[1.5, -2.0], [3.25, 0.0], [np.inf, 7.0]], np.float32)
        path = tmp_path / "be.pfm"
        path.write_bytes(b"Pf\n2 3\n1.000000\n" + np.flipud(top_down).astype(">f4").tobytes())
        back = read_pfm(path)
        assert back.dtype == np.float32 and back.dtype.byteorder in ("=", "<", "|")
        np.testing.assert_array_equal(back, top_down)

    def test_colour_big_endian_read(self, tmp_path):
        top_down = np.arange(2 * 2 * 3, dtype=np.float32).reshape(2, 2, 3)
        path = tmp_path / "be3.pfm"
        path.write_bytes(b"PF\n2 2\n2.5\n" + np.flipud(top_down).astype(">f4").tobytes())
        np.testing.assert_array_equal(read_pfm(path), top_down)

    @pytest.mark.parametrize(
        "content",
        [
            b"P6\n2 2\n255\n" + bytes(12),  # a PPM, not a PFM
            b"Pf\n2\n-1.0\n" + bytes(16),  # missing height
            b"Pf\n2 2\n0.0\n" + bytes(16),  # zero scale
            b"Pf\n2 2\n-1.0\n" + bytes(15),  # truncated data
            b"Pf\n2 2\n-1.0\n" + bytes(20),  # trailing data
            b"Pf\nab cd\n-1.0\n" + bytes(16),  # non-numeric size
        ],
    )
    def test_corrupt(self, tmp_path, content):
        path = tmp_path / "bad.pfm"
        path.write_bytes(content)
        with pytest.raises(ImageReadError, match=r"bad\.pfm"):
            read_pfm(path)

    def test_missing_and_empty(self, tmp_path):
        with pytest.raises(ImageReadError, match=r"missing\.pfm"):
            read_pfm(tmp_path / "missing.pfm")
        (tmp_path / "empty.pfm").write_bytes(b"")
        with pytest.raises(ImageReadError, match=r"empty\.pfm"):
            read_pfm(tmp_path / "empty.pfm")

    def test_write_bad_input(self, tmp_path):
        path = tmp_path / "x.pfm"
        with pytest.raises(ShapeError, match=r"array must have shape \(\*, \*, 3\)"):
            write_pfm(path, np.zeros((2, 2, 2), np.float32))
        with pytest.raises(ShapeError, match=r"shape \(H, W\) or \(H, W, 3\)"):
            write_pfm(path, np.zeros((2,), np.float32))
        with pytest.raises(ShapeError, match="floating dtype"):
            write_pfm(path, np.zeros((2, 2), np.uint8))
        with pytest.raises(ShapeError, match="must not be empty"):
            write_pfm(path, np.zeros((2, 0), np.float32))
        assert not path.exists()

    def test_float64_written_as_float32(self, tmp_path):
        path = tmp_path / "x.pfm"
        write_pfm(path, np.full((2, 2), 0.1, np.float64))
        np.testing.assert_array_equal(read_pfm(path), np.full((2, 2), 0.1, np.float32))
