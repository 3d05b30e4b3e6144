"""What flows from stage to stage: the `State` and the typed artefacts the stages add to it.

Every stage is ``(State, settings) -> State`` and returns a new State
(``dataclasses.replace``). What each reads and adds is written on it and
held in a typed field, never a dict key another stage must know:

============  ==============================================  ==============================
stage         reads                                           adds
============  ==============================================  ==============================
extrapolate   positions, captured_pos, limbs                  positions, speed_limit, speed_report
correct       positions, captured_pos, limbs                  positions, correct_report
stretch       positions, captured_pos, limbs, paths           positions, stretch, stretch_keys
subjoints     positions                                       hierarchy, sub_positions
springs       rubber(), captured_pos, limbs                   sub_positions, substeps
constraints   rubber(), captured, limbs, stretch_keys,        sub_positions, pins, constraints,
              speed_limit                                     warnings
orient        rubber(), captured, pins, speed_limit           output
============  ==============================================  ==============================

A stage with nothing to do returns the State it was given (the same
object), and the pipeline does not list it as run.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..core.motion import Motion
from ..core.skeleton import Skeleton
from .subjoints import SubjointConfig, SubjointHierarchy, build_hierarchy

if TYPE_CHECKING:
    from .correct import CorrectReport
    from .extrapolate import SpeedLimitReport
    from .stretch import StretchResult

__all__ = ["State", "Output", "Pins", "StretchKey"]


class StretchKey(NamedTuple):
    """A stretch's promise: at ``frame`` the limb's end lies at ``vectors[frame]`` from its base.

    Made by the stretch stage, kept by the constraints stage (which the springs would otherwise soften).
    limb : the limb's name; base, end : its base joint and end effector (original joints)
    frame : the frame counted from ``State.first``
    vectors : (F - first, 3) float64 end minus base as the stretch pass left them (eased toward around the frame)
    """

    limb: str
    base: int
    end: int
    frame: int
    vectors: np.ndarray


class Pins(NamedTuple):
    """Original joints that keep their captured orientation (planted feet), and by how much.

    joints : (k,) int; weights : (F, k) float64, 1 on planted frames, eased in and out
    """

    joints: np.ndarray
    weights: np.ndarray


class Output(NamedTuple):
    """The output skeleton's motion and the world positions its FK reproduces (its world rotations
    are its FK's: `PipelineResult.world_rotations`)."""

    motion: Motion
    world_positions: np.ndarray  # (F, J_out, 3)
    original_index: np.ndarray  # (J,) where each original joint is in the output skeleton


@dataclass(frozen=True)
class State:
    """What flows from stage to stage.

    motion : the captured clip (rest frames removed with ``tpose = "drop"``)
    captured_rot, captured_pos : (F, J, 4) and (F, J, 3) its world transforms
    rest_frames : leading frames kept out of every filter and written as captured
    limbs : limb name -> `Limb`, found on the skeleton (the config's ``[limbs]`` win)
    positions : (F, J, 3) float64 working positions of the original joints
    paths : limb -> (frames, points), hand-edited end-effector paths, or None
    notes : things the user should hear about, in the order they happened (``-v``)
    warnings : things the user must hear about (said without ``-v``): a promise the stages could not keep

    Added by the stages (None until a stage adds them):

    speed_limit : the extrapolation's ``max_speed`` (times each joint's captured top
        speed), which the constraints' easing and orientation recovery keep to; 0 is none
    speed_report : how much of the exaggeration the speed limit took (`SpeedLimitReport`)
    correct_report : what the link correction did
    stretch : the stretch pass's result (events, trails, stretch factors)
    stretch_keys : the lengths the stretches promised (empty when none); None without the stretch stage
    hierarchy : the sub-joint hierarchy
    sub_positions : (F, J', 3) positions on the rubber skeleton
    substeps : the spring simulation's substeps per frame (0 without springs)
    pins : planted joints that keep their captured orientation
    constraints : the constraints stage's report for the manifest (contacts, floor, targets, keys held)
    output : the output Motion and its world transforms (orient)
    """

    motion: Motion
    captured_rot: np.ndarray
    captured_pos: np.ndarray
    rest_frames: int
    rest_frames_dropped: bool
    limbs: dict
    positions: np.ndarray
    paths: dict | None = None
    notes: tuple[str, ...] = ()
    warnings: tuple[str, ...] = ()
    speed_limit: float = 0.0
    speed_report: SpeedLimitReport | None = None
    correct_report: CorrectReport | None = None
    stretch: StretchResult | None = None
    stretch_keys: tuple[StretchKey, ...] | None = None
    hierarchy: SubjointHierarchy | None = None
    sub_positions: np.ndarray | None = None
    substeps: int = 0
    pins: Pins | None = None
    constraints: dict | None = None
    output: Output | None = None

    @property
    def first(self) -> int:
        """The first frame of real motion: the stages that filter in time start here."""
        return self.rest_frames if not self.rest_frames_dropped else 0

    def rubber(self) -> tuple[SubjointHierarchy, np.ndarray]:
        """The hierarchy the springs and orientation recovery work on, and positions on it.

        Without the subjoints stage: the original links, uncut (positions of
        the original joints, in their own order).
        """
        if self.hierarchy is not None:
            return self.hierarchy, self.sub_positions
        positions = self.sub_positions if self.sub_positions is not None else self.positions
        return uncut_hierarchy(self.motion.skeleton), positions


@functools.lru_cache(maxsize=16)
def uncut_hierarchy(skeleton: Skeleton) -> SubjointHierarchy:
    """The hierarchy of ``skeleton``'s own links, uncut, with no rubber groups."""
    hierarchy = build_hierarchy(skeleton, SubjointConfig(per_link=1))
    return replace(hierarchy, groups=())
