"""The blocks of the method: each a frozen config and a pure function over arrays.

`mocap_exaggerate.pipeline` declares the order they run in.
"""

from .correct import CorrectConfig, CorrectReport, correct, stretch_error
from .extrapolate import ExtrapolateConfig, extrapolate
from .orient import motion_from_world, recover_orientations
from .springs import SpringConfig, simulate_springs
from .subjoints import SubjointConfig, SubjointHierarchy, build_hierarchy, position_subjoints

__all__ = [
    "CorrectConfig",
    "CorrectReport",
    "ExtrapolateConfig",
    "SpringConfig",
    "SubjointConfig",
    "SubjointHierarchy",
    "build_hierarchy",
    "correct",
    "extrapolate",
    "motion_from_world",
    "position_subjoints",
    "recover_orientations",
    "simulate_springs",
    "stretch_error",
]
