"""The pipeline: the declared list of stages and the loop that runs it.

A stage is a name, a pure function ``(State, settings) -> State`` and a
function that picks the stage's settings out of a `PipelineConfig` (None
when the stage is switched off). Each stage's function lives in its own
module under `mocap_exaggerate.stages`, with its config and its kernels; what it
reads from the `State` and adds to it is in `mocap_exaggerate.stages.state`.
`STAGES` is the order; `run` loops over it and records which stages ran (a
stage with nothing to do returns the State it got and is not listed), so
the manifest says exactly what was done. Adding a stage is one function and
one line in `STAGES`.

Leading synthetic rest frames (a T-pose and its settling frames) are found
before the stages run; the stages that filter in time see only the frames
after them, and they are written back as captured.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np

from .analysis.limbs import find_limbs
from .analysis.tpose import detect_rest_frames
from .config import DEFAULT_PRESET, InputConfig, PipelineConfig, load_preset
from .core.errors import ConfigError
from .core.motion import Motion
from .core.skeleton import Skeleton
from .stages.contacts import ConstraintPlan, constraints_stage
from .stages.correct import CorrectReport, correct_stage, max_link_stretch
from .stages.extrapolate import SpeedLimitReport, extrapolate_stage
from .stages.orient import orient_stage
from .stages.springs import springs_stage
from .stages.state import State
from .stages.stretch import StretchPlan, StretchResult, stretch_stage
from .stages.subjoints import SubjointHierarchy, link_starts, subjoints_stage

__all__ = [
    "State",
    "Stage",
    "STAGES",
    "PipelineResult",
    "prepare",
    "run",
    "exaggerate",
    "pipeline_limbs",
]


@dataclass(frozen=True)
class Stage:
    """One block of the pipeline.

    name : what the manifest calls it
    apply : ``(state, settings) -> state``, pure; the same State back when it has nothing to do
    settings : picks the stage's settings out of a PipelineConfig; None switches the stage off
    """

    name: str
    apply: Callable[[State, Any], State]
    settings: Callable[[PipelineConfig], Any]


def _block(name: str) -> Callable[[PipelineConfig], Any]:
    """Settings picker for a block with an ``enabled`` switch."""
    def pick(config: PipelineConfig):
        block = getattr(config, name)
        return block if block.enabled else None

    return pick


def _extrapolate_settings(config: PipelineConfig):
    """The extrapolation's block, its crouch floor off where nothing plants the feet after it lifts the body
    (contacts or the floor off: a lifted body's feet would hover)."""
    block = config.extrapolate
    if not block.enabled:
        return None
    planted = config.contacts.enabled and config.contacts.floor
    return block if planted or block.crouch == 0 else replace(block, crouch=0.0)


#: The blocks in the order they run.
STAGES: tuple[Stage, ...] = (
    Stage("extrapolate", extrapolate_stage, _extrapolate_settings),
    Stage("correct", correct_stage, _block("correct")),
    Stage("stretch", stretch_stage, lambda c: StretchPlan(c.stretch, c.auto_stretch, c.contacts)),
    Stage("subjoints", subjoints_stage, _block("subjoints")),
    Stage("springs", springs_stage, lambda c: c.springs if c.springs.enabled and c.springs.blend > 0 else None),
    Stage("constraints", constraints_stage, lambda c: ConstraintPlan(c.contacts, c.target)),
    Stage("orient", orient_stage, lambda c: c.output),
)


# ---------------------------------------------------------------------------- running


@dataclass
class PipelineResult:
    """A run's output and what happened on the way.

    motion : the output Motion (6 channels on every joint)
    world_positions : (F, J_out, 3) float64 positions the output's FK reproduces
    world_rotations : (F, J_out, 4) float64 orientations (a property: the output's forward
        kinematics, made when first asked for and kept; a run does not hold them beside the
        local rotations, 32 bytes a joint a frame)
    original_index : (J,) int, where each original joint is in the output skeleton
    hierarchy : the rubber skeleton written out, with each cut link's start joint
        (`mocap_exaggerate.stages.subjoints.link_starts`); None when sub-joints were off
    rest_frames : leading synthetic rest frames kept out of the filters
    stages : names of the stages that ran, in order
    timings : seconds per step, in run order
    correct_report : CorrectReport or None when correction was off
    speed_report : how much of the exaggeration the speed limit took (`SpeedLimitReport`); None
        without extrapolation or a limit
    notes : what the user should hear about with ``-v`` (rest frames, strikes found, the speed limit)
    warnings : what the user must hear about: a promise the stages could not keep (a stretch's length
        the floor held back)
    preserve_volume : ``output.preserve_volume``: the skinned outputs (GLB, previews) scale
        each joint by `mocap_exaggerate.jobs.outputs.output_thickness`
    """

    motion: Motion
    world_positions: np.ndarray
    original_index: np.ndarray
    hierarchy: SubjointHierarchy | None
    rest_frames: int
    rest_frames_dropped: bool
    timings: dict[str, float]
    correct_report: CorrectReport | None = None
    speed_report: SpeedLimitReport | None = None
    max_link_stretch: float = 1.0
    substeps: int = 0
    notes: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    stretch: StretchResult | None = None
    stages: list[str] = field(default_factory=list)
    constraints: dict | None = None
    preserve_volume: bool = True

    @cached_property
    def world_rotations(self) -> np.ndarray:
        """(F, J_out, 4) float64 world orientations of the output (its forward kinematics)."""
        return self.motion.world_rotations()

    @property
    def first(self) -> int:
        """The first frame of real motion in the output (after any rest frames kept)."""
        return self.rest_frames if not self.rest_frames_dropped else 0


def prepare(motion: Motion, config: InputConfig | None = None, *, limbs: dict | None = None,
            paths: dict | None = None) -> State:
    """The state the stages start from: forward kinematics, rest frames found (and dropped if asked)."""
    config = config or InputConfig()
    if config.fps is not None and abs(motion.fps - config.fps) > 1e-9 * config.fps:
        motion = motion.replace(frame_time=1.0 / config.fps)  # what the reader does with --fps
    world_rot, world = motion.forward_kinematics()
    rest = detect_rest_frames(motion, world) if config.tpose in ("auto", "drop") else 0
    dropped = config.tpose == "drop" and rest > 0
    notes: tuple[str, ...] = ()
    if dropped:
        motion = motion.slice(slice(rest, None))
        world_rot, world = world_rot[rest:], world[rest:]
        notes = (f"dropped {rest} leading rest-pose frame(s)",)
    elif rest:
        notes = (f"kept {rest} leading rest-pose frame(s) out of the filters, unchanged",)
    return State(motion=motion, captured_rot=world_rot, captured_pos=world, rest_frames=rest,
                 rest_frames_dropped=dropped, limbs=find_limbs(motion.skeleton) if limbs is None else limbs,
                 positions=world.copy(), paths=paths, notes=notes)


def run(motion: Motion, config: PipelineConfig | None = None, *, paths: dict | None = None,
        stages: tuple[Stage, ...] = STAGES) -> PipelineResult:
    """Run the stages that are switched on over a whole clip.

    ``paths`` maps limb names to hand-edited end-effector paths ``(frames,
    positions)`` (a trails file): the limb follows them (see `apply_stretches`);
    an edited path that no stretch covers becomes an event of its own.
    ``stages`` is the declared list (default `STAGES`); it must end with a
    stage that sets ``state.output`` (orient).
    """
    config = config or PipelineConfig()
    timings: dict[str, float] = {}
    start = time.perf_counter()
    state = prepare(motion, config.input, limbs=pipeline_limbs(motion.skeleton, config), paths=paths)
    timings["forward_kinematics"] = time.perf_counter() - start
    ran = []
    for stage in stages:
        settings = stage.settings(config)
        if settings is None:
            continue
        start = time.perf_counter()
        after = stage.apply(state, settings)
        if after is state:  # nothing to do
            continue
        state = after
        timings[stage.name] = time.perf_counter() - start
        ran.append(stage.name)
    if state.output is None:
        raise ValueError("the pipeline's stages produced no output motion (is orient in the list?)")
    skeleton = state.motion.skeleton
    return PipelineResult(
        motion=state.output.motion,
        world_positions=state.output.world_positions,
        original_index=state.output.original_index,
        hierarchy=link_starts(state.hierarchy) if state.hierarchy is not None else None,
        rest_frames=state.rest_frames,
        rest_frames_dropped=state.rest_frames_dropped,
        timings=timings,
        correct_report=state.correct_report,
        speed_report=state.speed_report,
        max_link_stretch=max_link_stretch(state.positions, skeleton.parents, skeleton.link_lengths()),
        substeps=state.substeps,
        notes=list(state.notes),
        warnings=list(state.warnings),
        stretch=state.stretch,
        stages=ran,
        constraints=state.constraints,
        preserve_volume=config.output.preserve_volume,
    )


def pipeline_limbs(skeleton: Skeleton, config: PipelineConfig) -> dict:
    """Limbs found on ``skeleton``, with the config's ``[limbs]`` winning."""
    try:
        return find_limbs(skeleton, {name: list(chain) for name, chain in config.limbs})
    except (KeyError, ValueError) as error:
        raise ConfigError(f"limbs: {error.args[0]}") from None


def exaggerate(motion: Motion, config: PipelineConfig | None = None, **preset: Any) -> Motion:
    """Exaggerate a clip with ``config`` (default: the `DEFAULT_PRESET` preset); the output Motion.

    Example::

        from mocap_exaggerate import load_bvh, exaggerate, save_bvh
        save_bvh(exaggerate(load_bvh("walk.bvh")), "walk_cartoon.bvh")
    """
    if config is None:
        config = load_preset(preset.pop("preset", DEFAULT_PRESET))
    if preset:
        raise TypeError(f"unexpected arguments: {', '.join(preset)}")
    return run(motion, config).motion
