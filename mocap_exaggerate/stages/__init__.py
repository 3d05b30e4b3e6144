"""The blocks of the method: each a frozen config and a pure function over arrays."""

from .correct import CorrectConfig, CorrectReport, correct, stretch_error
from .extrapolate import ExtrapolateConfig, extrapolate, gaussian_average, parse_duration
from .orient import positions_to_motion
from .tpose import detect_rest_frames

__all__ = [
    "CorrectConfig",
    "CorrectReport",
    "ExtrapolateConfig",
    "correct",
    "detect_rest_frames",
    "extrapolate",
    "gaussian_average",
    "parse_duration",
    "positions_to_motion",
    "stretch_error",
]
