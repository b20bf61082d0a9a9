"""Stereo rectification of a :class:`~spacepose.calibration.rig.StereoRig` (``cv2.stereoRectify``).

After rectification both images share one camera matrix ``K``, rows are aligned and the right
camera sits at ``+baseline_m`` along the left camera's x axis, so disparity ``d = x_left - x_right``
and depth ``Z = focal_px * baseline_m / d`` (CONVENTIONS.md). The remap tables are computed once per
:class:`Rectification`, on first use.
"""

from __future__ import annotations

import logging
import threading

import cv2
import numpy as np

from spacepose.errors import CalibrationError, ShapeError

from .rig import StereoRig

__all__ = ["Rectification", "rectify"]

log = logging.getLogger(__name__)

_IDENTITY_RTOL = 1e-9
_IDENTITY_ATOL = 1e-9


def _is_ideal(rig: StereoRig) -> bool:
    """Parallel, undistorted, identical square-pixel cameras with the baseline along +x."""
    K = rig.M1
    return (
        not np.any(rig.D1)
        and not np.any(rig.D2)
        and np.allclose(rig.R, np.eye(3), rtol=0.0, atol=_IDENTITY_ATOL)
        and np.allclose(rig.M1, rig.M2, rtol=_IDENTITY_RTOL, atol=_IDENTITY_ATOL)
        and np.isclose(K[0, 0], K[1, 1], rtol=_IDENTITY_RTOL, atol=0.0)
        and K[0, 1] == 0.0
        and abs(rig.T[1]) <= _IDENTITY_ATOL * abs(rig.T[0])
        and abs(rig.T[2]) <= _IDENTITY_ATOL * abs(rig.T[0])
        and rig.T[0] < 0
    )


def _frozen(array: np.ndarray) -> np.ndarray:
    array = np.array(array, dtype=np.float64, copy=True)
    array.setflags(write=False)
    return array


class Rectification:
    """The rectified rig: ``R1, R2`` (3, 3), ``P1, P2`` (3, 4), ``Q`` (4, 4) from ``cv2.stereoRectify``.

    Use :func:`rectify` to build one. Thread-safe: the remap tables are computed under a lock, once.
    """

    def __init__(
        self,
        rig: StereoRig,
        alpha: float,
        R1: np.ndarray,
        R2: np.ndarray,
        P1: np.ndarray,
        P2: np.ndarray,
        Q: np.ndarray,
        roi1: tuple[int, int, int, int],
        roi2: tuple[int, int, int, int],
        is_identity: bool,
    ) -> None:
        self.rig = rig
        self.alpha = float(alpha)
        self.R1, self.R2, self.P1, self.P2, self.Q = (_frozen(m) for m in (R1, R2, P1, P2, Q))
        self.roi1 = tuple(int(v) for v in roi1)
        self.roi2 = tuple(int(v) for v in roi2)
        self.is_identity = bool(is_identity)
        self._lock = threading.Lock()
        self._maps: tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None

    def __repr__(self) -> str:
        return (
            f"Rectification({self.image_size[0]}x{self.image_size[1]}, focal_px={self.focal_px:.3f}, "
            f"baseline_m={self.baseline_m:.6f}, alpha={self.alpha}, is_identity={self.is_identity})"
        )

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state.pop("_lock")
        state["_maps"] = None
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._lock = threading.Lock()

    @property
    def image_size(self) -> tuple[int, int]:
        """(width, height) of the raw and of the rectified images (they are the same)."""
        return self.rig.image_size

    @property
    def K(self) -> np.ndarray:
        """(3, 3) camera matrix of the left rectified camera (also the right one's)."""
        return self.P1[:, :3].copy()

    @property
    def focal_px(self) -> float:
        """Rectified focal length in pixels (fx = fy)."""
        return float(self.P1[0, 0])

    @property
    def baseline_m(self) -> float:
        """Rectified baseline in metres (the right camera sits at ``(+baseline_m, 0, 0)``)."""
        return float(-self.P2[0, 3] / self.P2[0, 0])

    def rectify_maps(self) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """``((map1, map2) left, (map1, map2) right)`` for ``cv2.remap`` (``CV_16SC2``), cached."""
        if self._maps is None:
            with self._lock:
                if self._maps is None:
                    size = self.rig.image_size
                    left = cv2.initUndistortRectifyMap(self.rig.M1, self.rig.D1, self.R1, self.P1, size, cv2.CV_16SC2)
                    right = cv2.initUndistortRectifyMap(self.rig.M2, self.rig.D2, self.R2, self.P2, size, cv2.CV_16SC2)
                    self._maps = (left, right)
                    log.debug("computed rectification maps for %dx%d", *size)
        return self._maps

    def _check_image(self, image: object, name: str) -> np.ndarray:
        if not isinstance(image, np.ndarray):
            raise ShapeError(f"{name} must be a numpy array, got {type(image).__name__}")
        if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] not in (1, 3, 4)):
            raise ShapeError(f"{name} must have shape (H, W) or (H, W, C) with C in (1, 3, 4), got {image.shape}")
        self.rig.check_image_size(image.shape)
        return image

    def rectify_image(self, image: np.ndarray, side: str = "left", interpolation: int = cv2.INTER_LINEAR) -> np.ndarray:
        """Rectify one raw image of camera ``side`` (``"left"`` or ``"right"``); same shape and dtype."""
        if side not in ("left", "right"):
            raise ValueError(f"side must be 'left' or 'right', got {side!r}")
        image = self._check_image(image, side)
        if self.is_identity:
            return image
        map1, map2 = self.rectify_maps()[0 if side == "left" else 1]
        out = cv2.remap(image, map1, map2, interpolation, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        return out.reshape(image.shape)

    def rectify_pair(
        self, left: np.ndarray, right: np.ndarray, interpolation: int = cv2.INTER_LINEAR
    ) -> tuple[np.ndarray, np.ndarray]:
        """Rectify a raw stereo pair (RGB or grey, any dtype ``cv2.remap`` takes).

        For an ideal rig (:attr:`is_identity`) the inputs come back unchanged, as the same objects.

        Raises:
            ShapeError: an input is not an image array.
            CalibrationError: an image size does not match the rig (key ``image_width``/``image_height``).
        """
        left = self._check_image(left, "left")
        right = self._check_image(right, "right")
        if self.is_identity:
            return left, right
        return self.rectify_image(left, "left", interpolation), self.rectify_image(right, "right", interpolation)


def rectify(rig: StereoRig, alpha: float = 0.0) -> Rectification:
    """Rectify ``rig`` with ``cv2.stereoRectify`` (``CALIB_ZERO_DISPARITY``, same image size).

    Args:
        rig: the raw stereo rig.
        alpha: free scaling, 0 (only valid pixels) to 1 (all source pixels kept), or -1 for OpenCV's
            default.

    Raises:
        CalibrationError: the rig is not a horizontal left-right pair (``key="T"``).
        ValueError: ``alpha`` is out of range.
    """
    if not isinstance(rig, StereoRig):
        raise TypeError(f"rectify needs a StereoRig, got {type(rig).__name__}")
    alpha = float(alpha)
    if not (alpha == -1.0 or 0.0 <= alpha <= 1.0):
        raise ValueError(f"alpha must be in [0, 1] or -1, got {alpha}")
    T = rig.T.reshape(3, 1)  # OpenCV 5 wants a 3x1 column
    if abs(T[0, 0]) < max(abs(T[1, 0]), abs(T[2, 0])):
        raise CalibrationError(
            f"T = {rig.T.tolist()}: the baseline is not mostly horizontal; spacepose needs a left-right rig", key="T"
        )
    if T[0, 0] >= 0:
        raise CalibrationError(
            f"T = {rig.T.tolist()}: the right camera is not to the right of the left one (T[0] must be < 0); "
            "are the left and right cameras swapped?",
            key="T",
        )
    R1, R2, P1, P2, Q, roi1, roi2 = cv2.stereoRectify(
        rig.M1, rig.D1, rig.M2, rig.D2, rig.image_size, rig.R, T, flags=cv2.CALIB_ZERO_DISPARITY, alpha=alpha
    )
    identity = (
        _is_ideal(rig)
        and np.allclose(R1, np.eye(3), rtol=0.0, atol=_IDENTITY_ATOL)
        and np.allclose(R2, np.eye(3), rtol=0.0, atol=_IDENTITY_ATOL)
        and np.allclose(P1[:, :3], rig.M1, rtol=_IDENTITY_RTOL, atol=_IDENTITY_ATOL)
        and np.allclose(P2[:, :3], rig.M2, rtol=_IDENTITY_RTOL, atol=_IDENTITY_ATOL)
    )
    return Rectification(rig, alpha, R1, R2, P1, P2, Q, roi1, roi2, identity)
