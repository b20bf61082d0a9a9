"""Stereo-rig calibration: the rig model and its files, rectification, chessboard calibration.

Imports only numpy and OpenCV, so the flight runtime may use it.
"""

from .chessboard import CalibrationResult, calibrate_stereo, find_chessboard
from .rectify import Rectification, rectify
from .rig import PAPER_RIG_PATH, StereoRig, load_rig, paper_rig, save_rig

__all__ = [
    "StereoRig",
    "load_rig",
    "save_rig",
    "paper_rig",
    "PAPER_RIG_PATH",
    "Rectification",
    "rectify",
    "CalibrationResult",
    "calibrate_stereo",
    "find_chessboard",
]
