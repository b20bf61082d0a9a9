"""Argument types shared by the ``spacepose`` subcommands (stdlib only: safe for every CLI module)."""

from __future__ import annotations

import argparse
from typing import Callable

__all__ = ["non_negative_int", "parse_size", "size_type"]


def parse_size(text: str, min_side: int | None = None) -> tuple[int, int]:
    """``"WIDTHxHEIGHT"`` -> (width, height); argparse.ArgumentTypeError on anything else or, when
    ``min_side`` is given, a side below it."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"size must be WIDTHxHEIGHT (e.g. 640x480), got {text!r}") from err
    if min_side is not None and (w < min_side or h < min_side):
        raise argparse.ArgumentTypeError(f"size must be at least {min_side}x{min_side}, got {text!r}")
    return w, h


def size_type(min_side: int) -> Callable[[str], tuple[int, int]]:
    """An argparse ``type=`` like :func:`parse_size` with its own ``min_side``."""

    def parse(text: str) -> tuple[int, int]:
        return parse_size(text, min_side)

    return parse


def non_negative_int(text: str) -> int:
    """argparse type: an integer >= 0."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return value
