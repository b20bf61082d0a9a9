"""Typed errors of spacepose and the one-line guards that raise them at public boundaries."""

from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = [
    "SpaceposeError",
    "ShapeError",
    "CalibrationError",
    "ImageReadError",
    "BundleError",
    "DatasetError",
    "MissingExtraError",
    "check_shape",
    "check_finite",
]


class SpaceposeError(Exception):
    """Base class of every error spacepose raises on purpose."""


class ShapeError(SpaceposeError, ValueError):
    """An array has the wrong shape or dtype."""


class CalibrationError(SpaceposeError, ValueError):
    """A calibration file or rig is missing a key, malformed, or does not fit the images.

    ``key`` names the offending FileStorage key (or ``None`` when the whole file is at fault).
    """

    def __init__(self, message: str, key: str | None = None) -> None:
        super().__init__(message)
        self.key = key


class ImageReadError(SpaceposeError, OSError):
    """An image file is missing, unreadable or of an unsupported format."""


class BundleError(SpaceposeError, ValueError):
    """A model bundle is missing, corrupt, or does not fit the calibration it is used with."""


class DatasetError(SpaceposeError, ValueError):
    """A dataset folder is inconsistent, foreign, or cannot be written as asked."""


class MissingExtraError(SpaceposeError, ImportError):
    """A training-side feature was used without its optional dependencies installed."""

    def __init__(self, module: str, extra: str = "train") -> None:
        super().__init__(
            f"this feature needs the optional module {module!r}; install it with "
            f"`pip install 'spacepose[{extra}]'`"
        )
        self.module = module
        self.extra = extra


def check_shape(array: object, shape: Sequence[int | None], name: str, dtypes: Sequence[type] | None = None) -> np.ndarray:
    """Check that ``array`` is an ndarray of ``shape`` (``None`` = any size) and return it.

    A leading ``...`` is not supported on purpose: public functions state their exact rank.

    Raises:
        ShapeError: naming ``name``, the expected and the actual shape (or dtype).
    """
    if not isinstance(array, np.ndarray):
        raise ShapeError(f"{name} must be a numpy array, got {type(array).__name__}")
    if array.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, array.shape)):
        want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
        raise ShapeError(f"{name} must have shape {want}, got {tuple(array.shape)}")
    if dtypes is not None and not any(np.issubdtype(array.dtype, d) for d in dtypes):
        names = [getattr(d, "__name__", str(d)) for d in dtypes]
        raise ShapeError(f"{name} must have dtype in {names}, got {array.dtype}")
    return array


def check_finite(array: np.ndarray, name: str) -> np.ndarray:
    """Raise :class:`ShapeError` if ``array`` holds NaN or inf."""
    if not np.all(np.isfinite(array)):
        raise ShapeError(f"{name} must be finite (found NaN or inf)")
    return array
