"""Import an optional (training-side) module or raise :class:`MissingExtraError` naming the extra."""

from __future__ import annotations

import importlib
from types import ModuleType

from .errors import MissingExtraError


def import_optional(module: str, extra: str = "train") -> ModuleType:
    """Return ``importlib.import_module(module)`` or raise MissingExtraError naming ``extra``."""
    try:
        return importlib.import_module(module)
    except ImportError as err:
        raise MissingExtraError(module, extra) from err
