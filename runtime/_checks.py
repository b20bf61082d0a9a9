"""Array checks shared by the numeric runtime stages (:mod:`spacepose.fit`, :mod:`spacepose.voting`)."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from spacepose.errors import ShapeError, check_shape

__all__ = ["check_real"]


def check_real(array: object, shape: Sequence[int | None], name: str) -> np.ndarray:
    """:func:`~spacepose.errors.check_shape` plus a real-number dtype (float or int, not bool/complex),
    with the message ``"<name> must have a float or integer dtype, got <dtype>"``."""
    checked = check_shape(array, shape, name)
    if not (np.issubdtype(checked.dtype, np.floating) or np.issubdtype(checked.dtype, np.integer)):
        raise ShapeError(f"{name} must have a float or integer dtype, got {checked.dtype}")
    return checked
