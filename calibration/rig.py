"""The stereo-rig model and its OpenCV ``FileStorage`` files (YAML, XML or JSON by extension).

A rig file holds the keys that OpenCV's ``stereo_calib`` sample writes -- ``M1, D1, M2, D2, R, T``
(optionally ``R1, R2, P1, P2, Q``) -- plus ``image_width`` and ``image_height``
(``spec/CONVENTIONS.md``, "Calibration files"). ``R, T`` follow ``cv2.stereoCalibrate``:
``X_right = R @ X_left + T`` in metres.
"""

from __future__ import annotations

import logging
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from spacepose.errors import CalibrationError

__all__ = [
    "StereoRig",
    "load_rig",
    "save_rig",
    "paper_rig",
    "PAPER_RIG_PATH",
    "RIG_EXTENSIONS",
    "DISTORTION_LENGTHS",
]

log = logging.getLogger(__name__)

#: the rig of the paper, shipped in the FileStorage format (written with :func:`save_rig`)
PAPER_RIG_PATH = Path(__file__).resolve().parent / "rigs" / "paper_rig.yaml"

#: file extensions :func:`load_rig` / :func:`save_rig` accept (FileStorage picks the format by them)
RIG_EXTENSIONS = (".yaml", ".yml", ".xml", ".json")

#: distortion-vector lengths OpenCV's pinhole model accepts
DISTORTION_LENGTHS = (4, 5, 8, 12, 14)

_REQUIRED_KEYS = ("M1", "D1", "M2", "D2", "R", "T", "image_width", "image_height")
#: optional rectification keys of the stereo_calib sample and their shapes
_OPTIONAL_SHAPES = {"R1": (3, 3), "R2": (3, 3), "P1": (3, 4), "P2": (3, 4), "Q": (4, 4)}

# paper rig (CONVENTIONS.md): 1280x960, fx = fy = 1600, cx, cy at the pixel-centre midpoint, B = 1 m
_PAPER_SIZE = (1280, 960)
_PAPER_FOCAL_PX = 1600.0
_PAPER_BASELINE_M = 1.0

_ROTATION_TOL = 1e-6


def _as_float_array(value: object, key: str) -> np.ndarray:
    try:
        array = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise CalibrationError(f"{key} must be a numeric array, got {type(value).__name__}", key=key) from err
    if not np.all(np.isfinite(array)):
        raise CalibrationError(f"{key} must be finite (found NaN or inf)", key=key)
    return array


def _camera_matrix(value: object, key: str) -> np.ndarray:
    K = _as_float_array(value, key)
    if K.shape != (3, 3):
        raise CalibrationError(f"{key} must be a 3x3 camera matrix, got shape {K.shape}", key=key)
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise CalibrationError(f"{key} focal lengths must be positive, got fx={K[0, 0]}, fy={K[1, 1]}", key=key)
    if not np.allclose(K[2], (0.0, 0.0, 1.0), atol=1e-9) or K[1, 0] != 0.0:
        raise CalibrationError(f"{key} must have the form [[fx, s, cx], [0, fy, cy], [0, 0, 1]], got {K.tolist()}", key=key)
    return K


def _distortion(value: object, key: str) -> np.ndarray:
    D = _as_float_array(value, key)
    if D.ndim > 2 or (D.ndim == 2 and 1 not in D.shape):
        raise CalibrationError(f"{key} must be a vector of distortion coefficients, got shape {D.shape}", key=key)
    D = D.reshape(-1)
    if D.size not in DISTORTION_LENGTHS:
        raise CalibrationError(f"{key} must hold {DISTORTION_LENGTHS} coefficients, got {D.size}", key=key)
    return D


def _rotation(value: object, key: str) -> np.ndarray:
    R = _as_float_array(value, key)
    if R.shape != (3, 3):
        raise CalibrationError(f"{key} must be a 3x3 rotation matrix, got shape {R.shape}", key=key)
    if not np.allclose(R.T @ R, np.eye(3), atol=_ROTATION_TOL) or np.linalg.det(R) <= 0:
        raise CalibrationError(f"{key} is not a rotation matrix (R^T R != I or det(R) <= 0)", key=key)
    return R


def _translation(value: object, key: str) -> np.ndarray:
    T = _as_float_array(value, key)
    if T.size != 3 or T.ndim > 2 or (T.ndim == 2 and 1 not in T.shape):
        raise CalibrationError(f"{key} must be a 3-vector, got shape {T.shape}", key=key)
    T = T.reshape(3)
    if np.linalg.norm(T) <= 0:
        raise CalibrationError(f"{key} is zero: a stereo rig needs a non-zero baseline", key=key)
    return T


def _image_size(value: object) -> tuple[int, int]:
    try:
        width, height = value  # type: ignore[misc]
    except (TypeError, ValueError) as err:
        raise CalibrationError(f"image_size must be (width, height), got {value!r}", key="image_width") from err
    size = []
    for key, v in (("image_width", width), ("image_height", height)):
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer, float, np.floating)):
            raise CalibrationError(f"{key} must be a positive integer, got {v!r}", key=key)
        if not np.isfinite(v) or v <= 0 or int(v) != v:
            raise CalibrationError(f"{key} must be a positive integer, got {v!r}", key=key)
        size.append(int(v))
    return size[0], size[1]


def _frozen(array: np.ndarray) -> np.ndarray:
    array = np.array(array, dtype=np.float64, copy=True)
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class StereoRig:
    """A calibrated stereo pair in OpenCV's terms (validated on construction).

    Attributes:
        M1, M2: (3, 3) float64 camera matrices of the left and right camera.
        D1, D2: (k,) float64 distortion coefficients, k in :data:`DISTORTION_LENGTHS`.
        R: (3, 3) rotation, T: (3,) translation in metres, with ``X_right = R @ X_left + T``.
        image_size: (width, height) of the raw camera images in pixels.

    Arrays are stored as read-only float64 copies. Raises :class:`CalibrationError` naming the
    FileStorage key at fault (``M1``, ``D2``, ``T``, ``image_width``, ...).
    """

    M1: np.ndarray
    D1: np.ndarray
    M2: np.ndarray
    D2: np.ndarray
    R: np.ndarray
    T: np.ndarray
    image_size: tuple[int, int]

    def __post_init__(self) -> None:
        checked = {
            "M1": _camera_matrix(self.M1, "M1"),
            "D1": _distortion(self.D1, "D1"),
            "M2": _camera_matrix(self.M2, "M2"),
            "D2": _distortion(self.D2, "D2"),
            "R": _rotation(self.R, "R"),
            "T": _translation(self.T, "T"),
        }
        for name, array in checked.items():
            object.__setattr__(self, name, _frozen(array))
        object.__setattr__(self, "image_size", _image_size(self.image_size))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, StereoRig):
            return NotImplemented
        return self.image_size == other.image_size and all(
            np.array_equal(getattr(self, k), getattr(other, k)) for k in ("M1", "D1", "M2", "D2", "R", "T")
        )

    __hash__ = None  # type: ignore[assignment]  # holds arrays: equal rigs need not hash alike

    def allclose(self, other: StereoRig, rtol: float = 1e-9, atol: float = 1e-12) -> bool:
        """True when ``other`` has the same image size and numerically close parameters."""
        if self.image_size != other.image_size:
            return False
        for k in ("M1", "D1", "M2", "D2", "R", "T"):
            a, b = getattr(self, k), getattr(other, k)
            if a.shape != b.shape or not np.allclose(a, b, rtol=rtol, atol=atol):
                return False
        return True

    @property
    def width(self) -> int:
        return self.image_size[0]

    @property
    def height(self) -> int:
        return self.image_size[1]

    @property
    def baseline_m(self) -> float:
        """Distance between the two camera centres in metres (``||T||``)."""
        return float(np.linalg.norm(self.T))

    def scaled(self, width: int, height: int) -> StereoRig:
        """The same rig at another image resolution.

        ``fx, skew, cx`` scale with ``width / image_width`` and ``fy, cy`` with
        ``height / image_height``, pixel centres at integer coordinates: ``cx' = (cx + 0.5) * s - 0.5``.
        Distortion (in normalised coordinates), R and T are unchanged.
        """
        new_size = _image_size((width, height))
        sx = new_size[0] / self.image_size[0]
        sy = new_size[1] / self.image_size[1]

        def scale(K: np.ndarray) -> np.ndarray:
            K = K.copy()
            K[0, 0] *= sx
            K[0, 1] *= sx
            K[0, 2] = (K[0, 2] + 0.5) * sx - 0.5
            K[1, 1] *= sy
            K[1, 2] = (K[1, 2] + 0.5) * sy - 0.5
            return K

        return StereoRig(scale(self.M1), self.D1, scale(self.M2), self.D2, self.R, self.T, new_size)

    def check_image_size(self, shape: tuple[int, ...]) -> None:
        """Raise :class:`CalibrationError` unless ``shape`` ((H, W) or (H, W, C)) fits ``image_size``."""
        try:
            shape = tuple(int(s) for s in shape)
        except (TypeError, ValueError) as err:
            raise CalibrationError(f"image shape must be a tuple of ints, got {shape!r}", key=None) from err
        if len(shape) not in (2, 3):
            raise CalibrationError(f"an image must have shape (H, W) or (H, W, C), got {shape}", key=None)
        height, width = shape[:2]
        if width != self.image_size[0]:
            raise CalibrationError(
                f"image width {width} does not match the calibration (image_width={self.image_size[0]}, "
                f"image {width}x{height})",
                key="image_width",
            )
        if height != self.image_size[1]:
            raise CalibrationError(
                f"image height {height} does not match the calibration (image_height={self.image_size[1]}, "
                f"image {width}x{height})",
                key="image_height",
            )


def paper_rig(width: int = _PAPER_SIZE[0], height: int = _PAPER_SIZE[1]) -> StereoRig:
    """The reference rig of the paper (CONVENTIONS.md), scaled to ``width`` x ``height``.

    1280x960, fx = fy = 1600 px, cx = 639.5, cy = 479.5, no distortion, R = I, T = [-1, 0, 0] m.
    """
    w0, h0 = _PAPER_SIZE
    K = np.array([[_PAPER_FOCAL_PX, 0.0, (w0 - 1) / 2.0], [0.0, _PAPER_FOCAL_PX, (h0 - 1) / 2.0], [0.0, 0.0, 1.0]])
    rig = StereoRig(K, np.zeros(5), K, np.zeros(5), np.eye(3), np.array([-_PAPER_BASELINE_M, 0.0, 0.0]), _PAPER_SIZE)
    if (width, height) == _PAPER_SIZE:
        return rig
    return rig.scaled(width, height)


# ---------------------------------------------------------------------------------------- files


def _check_extension(path: Path) -> None:
    if path.suffix.lower() not in RIG_EXTENSIONS:
        raise CalibrationError(
            f"{path}: unsupported calibration file extension {path.suffix!r}; use one of {RIG_EXTENSIONS}", key=None
        )


def _read_node(node: cv2.FileNode, key: str, path: Path) -> object:
    """A FileStorage node as a float array (opencv-matrix or plain sequence) or a number."""
    try:
        if node.isMap():
            return node.mat()
        if node.isSeq():
            rows = [node.at(i) for i in range(node.size())]
            if rows and all(r.isSeq() for r in rows):
                return [[r.at(j).real() for j in range(r.size())] for r in rows]
            if not all(r.isInt() or r.isReal() for r in rows):
                raise CalibrationError(f"{path}: {key} must hold numbers", key=key)
            return [r.real() for r in rows]
        if node.isInt() or node.isReal():
            return node.real()
    except (cv2.error, SystemError) as err:
        raise CalibrationError(f"{path}: {key} is malformed ({err})", key=key) from err
    raise CalibrationError(f"{path}: {key} must be a matrix or a number, not a string", key=key)


def load_rig(path: str | os.PathLike[str]) -> StereoRig:
    """Read a rig from an OpenCV FileStorage file (``.yaml``/``.yml``/``.xml``/``.json``).

    The optional rectification keys (``R1, R2, P1, P2, Q``) are shape-checked but otherwise ignored:
    :func:`spacepose.calibration.rectify.rectify` recomputes them. A file ``R1`` more than
    :data:`R1_WARN_DEG` from the recomputed one is logged as a warning (the pose's reference frame).

    Raises:
        CalibrationError: missing file, unknown extension or unparseable file (``key=None``); a
            missing key, wrong shape or invalid value (``key`` names it).
    """
    path = Path(path)
    _check_extension(path)
    if not path.is_file():
        raise CalibrationError(f"calibration file not found: {path}", key=None)
    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as err:
        raise CalibrationError(f"{path}: not a readable OpenCV FileStorage file ({err})", key=None) from err
    try:
        if not fs.isOpened():
            raise CalibrationError(f"{path}: cannot open calibration file", key=None)
        root = fs.root()
        if not root.isMap():
            raise CalibrationError(f"{path}: the top level of a calibration file must be a map of keys", key=None)
        keys = set(root.keys())
        values = {}
        for key in _REQUIRED_KEYS:
            if key not in keys:
                raise CalibrationError(f"{path}: missing key {key!r} (needs {', '.join(_REQUIRED_KEYS)})", key=key)
            values[key] = _read_node(fs.getNode(key), key, path)
        optional = {}
        for key, shape in _OPTIONAL_SHAPES.items():
            if key in keys:
                array = _as_float_array(_read_node(fs.getNode(key), key, path), key)
                if array.shape != shape:
                    raise CalibrationError(f"{path}: {key} must have shape {shape}, got {array.shape}", key=key)
                optional[key] = array
    finally:
        fs.release()
    try:
        rig = StereoRig(
            values["M1"], values["D1"], values["M2"], values["D2"], values["R"], values["T"],
            (values["image_width"], values["image_height"]),
        )
    except CalibrationError as err:
        raise CalibrationError(f"{path}: {err}", key=err.key) from err
    if "R1" in optional:
        _warn_if_other_rectification(rig, optional["R1"], path)
    log.debug("loaded rig %s: %dx%d, baseline %.4f m", path, rig.width, rig.height, rig.baseline_m)
    return rig


#: a file's ``R1`` further than this from ``cv2.stereoRectify``'s is reported (degrees)
R1_WARN_DEG = 0.05


def _warn_if_other_rectification(rig: StereoRig, R1: np.ndarray, path: Path) -> float:
    """Log a warning when the file's ``R1`` turns the left camera otherwise than ``cv2.stereoRectify``
    does: poses are reported in the latter's left rectified camera, so a tool that rectified with the
    file's ``R1`` would see them turned by that angle. Returns the angle in degrees (NaN if not compared)."""
    from .rectify import rectify  # here: rectify imports this module

    try:
        ours = np.asarray(rectify(rig).R1)
    except CalibrationError:
        return float("nan")          # rectify refuses the rig itself; the runtime will say why
    cos = (np.trace(ours.T @ R1) - 1.0) / 2.0
    angle = float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
    if not angle <= R1_WARN_DEG:
        log.warning("%s: its R1 is %.3f deg from cv2.stereoRectify's; spacepose ignores it and reports poses in "
                    "cv2.stereoRectify's left rectified camera (CONVENTIONS.md)", path, angle)
    return angle


def _write(rig: StereoRig, path: str, with_rectification: bool) -> None:
    fs = cv2.FileStorage(path, cv2.FILE_STORAGE_WRITE)
    try:
        if not path.lower().endswith(".json"):  # JSON has no comments
            fs.writeComment("spacepose stereo rig: X_right = R X_left + T (metres); pixel centres at integers")
        fs.write("image_width", int(rig.width))
        fs.write("image_height", int(rig.height))
        fs.write("M1", rig.M1)
        fs.write("D1", rig.D1.reshape(1, -1))
        fs.write("M2", rig.M2)
        fs.write("D2", rig.D2.reshape(1, -1))
        fs.write("R", rig.R)
        fs.write("T", rig.T.reshape(3, 1))
        if with_rectification:
            from .rectify import rectify  # local: rectify imports this module

            rect = rectify(rig)
            for key in ("R1", "R2", "P1", "P2", "Q"):
                fs.write(key, getattr(rect, key))
    finally:
        fs.release()


def save_rig(
    rig: StereoRig, path: str | os.PathLike[str], overwrite: bool = False, with_rectification: bool = True
) -> Path:
    """Write ``rig`` as an OpenCV FileStorage file; the extension picks YAML, XML or JSON.

    With ``with_rectification`` the file also holds ``R1, R2, P1, P2, Q`` (``alpha = 0``), as OpenCV's
    ``stereo_calib`` sample writes them; :func:`load_rig` ignores them. The file appears atomically.

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is False.
        CalibrationError: unsupported extension.
    """
    if not isinstance(rig, StereoRig):
        raise TypeError(f"save_rig needs a StereoRig, got {type(rig).__name__}")
    path = Path(path)
    _check_extension(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; pass overwrite=True to replace it")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    try:
        _write(rig, tmp_name, with_rectification)
        if overwrite:
            os.replace(tmp_name, path)
        else:
            try:
                os.link(tmp_name, path)  # atomic and refuses to replace a file created meanwhile
            except FileExistsError:
                raise FileExistsError(f"{path} exists; pass overwrite=True to replace it") from None
            except OSError:  # filesystem without hard links
                if path.exists():
                    raise FileExistsError(f"{path} exists; pass overwrite=True to replace it") from None
                os.replace(tmp_name, path)
    finally:
        if os.path.exists(tmp_name):
            os.unlink(tmp_name)
    log.info("wrote rig %s", path)
    return path
