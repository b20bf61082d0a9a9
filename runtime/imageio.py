"""Image and PFM file I/O: PNG/JPEG (8/16-bit, grey/colour) and PFM (Middlebury/Scene Flow).

Images in memory are RGB ``(H, W, 3)`` or grey ``(H, W)``, uint8 or uint16 (OpenCV's BGR order
stays inside this module). Files are read and written as bytes (``cv2.imdecode``/``imencode``), so
any path Python can open works.

PFM layout: a header of three whitespace-terminated lines: ``Pf`` (grey) or ``PF`` (colour),
``<width> <height>``, and a scale whose sign gives the byte order (negative = little endian);
then ``width*height*channels`` float32 values, rows stored bottom-to-top.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import cv2
import numpy as np

from .errors import ImageReadError, ShapeError, check_shape

__all__ = ["read_image", "write_image", "read_pfm", "write_pfm", "IMAGE_EXTENSIONS"]

#: Extensions :func:`write_image` accepts (lower case).
IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg")
_JPEG_EXTENSIONS = (".jpg", ".jpeg")

_PFM_HEADER = re.compile(rb"\A(P[Ff])\s+(\d+)\s+(\d+)\s+([-+]?[0-9.]+(?:[eE][-+]?\d+)?)\s")
_PFM_HEADER_MAX = 256


def _read_bytes(path: str | os.PathLike) -> bytes:
    try:
        data = Path(path).read_bytes()
    except OSError as err:
        raise ImageReadError(f"cannot read {os.fspath(path)!s}: {err.strerror or err}") from err
    if not data:
        raise ImageReadError(f"cannot read {os.fspath(path)!s}: the file is empty")
    return data


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Read a PNG or JPEG (or any 8/16-bit image OpenCV decodes) without changing its depth.

    Colour images come back in RGB order; an alpha channel is dropped; grey stays 2-D (a grey +
    alpha PNG is expanded to colour by OpenCV and so comes back as RGB with equal channels).

    Args:
        path: image file.

    Returns:
        (H, W) grey or (H, W, 3) RGB image, uint8 or uint16.

    Raises:
        ImageReadError: the file is missing, empty, not decodable, or of an unsupported depth
            (e.g. float) or channel count; the message names the path.
    """
    data = _read_bytes(path)
    image = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise ImageReadError(f"cannot decode {os.fspath(path)!s}: corrupt or not an image")
    if image.dtype not in (np.uint8, np.uint16):
        raise ImageReadError(f"{os.fspath(path)!s}: unsupported pixel type {image.dtype} (need 8- or 16-bit)")
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if image.ndim == 2:
        return np.ascontiguousarray(image)
    if image.ndim == 3 and image.shape[2] == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    if image.ndim == 3 and image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2RGB)
    raise ImageReadError(f"{os.fspath(path)!s}: unsupported image shape {image.shape}")


def write_image(path: str | os.PathLike, image: np.ndarray, *, jpeg_quality: int = 95) -> None:
    """Write an RGB or grey image as PNG (8/16-bit) or JPEG (8-bit) chosen by the extension.

    Args:
        path: target file, extension ``.png``, ``.jpg`` or ``.jpeg`` (any case). Its folder must exist.
        image: (H, W) grey or (H, W, 3) RGB, uint8 or uint16 (uint16 only for PNG).
        jpeg_quality: JPEG quality 0-100.

    Raises:
        ValueError: unsupported extension, uint16 to JPEG, or a bad ``jpeg_quality``.
        ShapeError: wrong shape or dtype of ``image``.
        OSError: the file cannot be written.
    """
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in IMAGE_EXTENSIONS:
        raise ValueError(f"cannot write {path}: unsupported extension {path.suffix!r}; use one of {IMAGE_EXTENSIONS}")
    if not isinstance(image, np.ndarray) or image.ndim not in (2, 3):
        raise ShapeError(f"image must be a numpy array of shape (H, W) or (H, W, 3), got {getattr(image, 'shape', type(image).__name__)}")
    if image.ndim == 3:
        check_shape(image, (None, None, 3), "image")
    if image.dtype not in (np.uint8, np.uint16):
        raise ShapeError(f"image must have dtype uint8 or uint16, got {image.dtype}")
    if image.shape[0] == 0 or image.shape[1] == 0:
        raise ShapeError(f"image must not be empty, got shape {image.shape}")
    params: list[int] = []
    if ext in _JPEG_EXTENSIONS:
        if image.dtype != np.uint8:
            raise ValueError(f"cannot write {path}: JPEG holds 8-bit images only, got {image.dtype}; use .png")
        if isinstance(jpeg_quality, bool) or not isinstance(jpeg_quality, int) or not 0 <= jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality must be an integer in [0, 100], got {jpeg_quality!r}")
        params = [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality]
    bgr = cv2.cvtColor(image, cv2.COLOR_RGB2BGR) if image.ndim == 3 else image
    ok, encoded = cv2.imencode(ext, np.ascontiguousarray(bgr), params)
    if not ok:
        raise ValueError(f"OpenCV could not encode {image.shape} {image.dtype} as {ext}")
    path.write_bytes(encoded.tobytes())


def read_pfm(path: str | os.PathLike) -> np.ndarray:
    """Read a PFM file (Middlebury / Scene Flow disparity).

    Args:
        path: ``.pfm`` file.

    Returns:
        float32 native byte order, rows top-to-bottom: (H, W) for ``Pf``, (H, W, 3) for ``PF``.
        Values are returned as stored (the scale's magnitude is not applied; inf stays inf).

    Raises:
        ImageReadError: missing/empty file, malformed header, zero scale, or a data size that
            does not match the header; the message names the path.
    """
    data = _read_bytes(path)
    match = _PFM_HEADER.match(data[:_PFM_HEADER_MAX])
    if match is None:
        raise ImageReadError(f"{os.fspath(path)!s}: not a PFM file (bad header)")
    kind, width, height, scale_text = match.groups()
    channels = 3 if kind == b"PF" else 1
    width, height = int(width), int(height)
    try:
        scale = float(scale_text)
    except ValueError as err:
        raise ImageReadError(f"{os.fspath(path)!s}: bad PFM scale {scale_text!r}") from err
    if scale == 0.0 or width == 0 or height == 0:
        raise ImageReadError(f"{os.fspath(path)!s}: bad PFM header (size {width}x{height}, scale {scale})")
    payload = data[match.end():]
    expected = width * height * channels * 4
    if len(payload) != expected:
        raise ImageReadError(
            f"{os.fspath(path)!s}: PFM data holds {len(payload)} bytes, header says {expected} "
            f"({width}x{height}x{channels} float32)"
        )
    dtype = np.dtype("<f4") if scale < 0 else np.dtype(">f4")
    array = np.frombuffer(payload, dtype=dtype).reshape(height, width, channels) if channels == 3 else (
        np.frombuffer(payload, dtype=dtype).reshape(height, width)
    )
    return np.ascontiguousarray(np.flipud(array).astype(np.float32))


def write_pfm(path: str | os.PathLike, array: np.ndarray) -> None:
    """Write a float map as little-endian PFM (scale -1), rows bottom-to-top.

    Args:
        path: target file (conventionally ``.pfm``). Its folder must exist.
        array: (H, W) → ``Pf``, or (H, W, 3) → ``PF``; floating (written as float32; inf/NaN kept).

    Raises:
        ShapeError: wrong shape or dtype.
        OSError: the file cannot be written.
    """
    if not isinstance(array, np.ndarray) or array.ndim not in (2, 3):
        raise ShapeError(f"array must be a numpy array of shape (H, W) or (H, W, 3), got {getattr(array, 'shape', type(array).__name__)}")
    if array.ndim == 3:
        check_shape(array, (None, None, 3), "array")
    if not np.issubdtype(array.dtype, np.floating):
        raise ShapeError(f"array must have a floating dtype, got {array.dtype}")
    height, width = array.shape[:2]
    if height == 0 or width == 0:
        raise ShapeError(f"array must not be empty, got shape {array.shape}")
    kind = "PF" if array.ndim == 3 else "Pf"
    header = f"{kind}\n{width} {height}\n-1.0\n".encode("ascii")
    body = np.ascontiguousarray(np.flipud(array).astype("<f4")).tobytes()
    Path(path).write_bytes(header + body)
