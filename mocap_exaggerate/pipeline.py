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

import re
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
from .core.timing import parse_duration
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

    A looping cycle (``input.loop``, `mocap_exaggerate.analysis.loops`) is run as the loop
    repeated and cut back to its own frames, so the output loops too.
    """
    config = config or PipelineConfig()
    fps = config.input.fps
    if fps is not None and abs(motion.fps - fps) > 1e-9 * fps:
        motion = motion.replace(frame_time=1.0 / fps)  # (as `prepare` does: the loop's halo is in seconds)
    loop, note, warning = _loop_of(motion, config, paths)
    if loop is None:
        result = _run_stages(motion, config, paths, stages)
        result.notes[:0] = [note] if note else []
        result.warnings[:0] = [warning] if warning else []
        return result
    start = time.perf_counter()
    extended = loop.extend(motion)
    inner = replace(config, input=replace(config.input, tpose="keep"))  # a cycle has no rest pose to keep out
    result = _cut(_run_stages(extended, inner, None, stages, keep=loop.middle(motion.num_frames)), loop,
                  motion.num_frames)
    result.timings["loop"] = time.perf_counter() - start - sum(result.timings.values())
    result.notes.insert(0, loop.describe(motion.frame_time))
    return result


def _loop_of(motion: Motion, config: PipelineConfig, paths: dict | None):
    """The clip as a `Loop` (None when it is not taken as one), and a note or a warning on why a cycle was not
    taken as one (a warning where the output will not loop: the cycle's frame-keyed requests)."""
    from .analysis.loops import find_loop, repeats_first

    mode = config.input.loop
    if mode == "off" or motion.num_frames < 3:
        return None, None, None
    if mode == "auto":  # two frames tell a clip that is no loop (every capture), at no cost
        ends = Motion(motion.skeleton, motion.frame_time, motion.local_rotations[[0, -1]],
                      motion.local_positions[[0, -1]])
        if not repeats_first(ends, *_world(ends)):
            return None, None, None
    keyed = [what for what, given in (("stretches", config.stretch), ("targets", config.target),
                                      ("a path file", paths)) if given]
    if keyed:
        said = " and ".join(keyed)
        if mode == "on":
            raise ConfigError(f"input.loop = on: a clip with {said} (keyed to its frames) cannot be run as a loop; "
                              "take them off, or --loop off")
        return None, None, (f"the clip's last frame repeats its first, but it has {said}, keyed to its frames: not "
                            "run as a loop, so the output may not loop (--loop off says it is a clip)")
    positions, rotations = _world(motion)
    if config.input.tpose in ("auto", "drop") and detect_rest_frames(motion, positions) > 0:
        if mode == "on":
            raise ConfigError("input.loop = on: the clip starts in a rest pose, which a cycle has not; --tpose keep "
                              "takes it as a frame of the cycle, or --loop off")
        return None, "the clip's last frame repeats its first, but it starts in a rest pose: not run as a loop", None
    reach = 0.0
    if config.extrapolate.enabled:  # a wide Gaussian reaches further than the halo's 5 s
        reach = 10.0 * parse_duration(config.extrapolate.sigma, motion.frame_time,
                                      what="extrapolate.sigma") * motion.frame_time
    return find_loop(motion, positions, rotations, mode, reach=reach), None, None


def _world(motion: Motion) -> tuple[np.ndarray, np.ndarray]:
    """World positions and rotations."""
    rotations, positions = motion.forward_kinematics()
    return positions, rotations


_SPAN = re.compile(r"frames (\d+)-(\d+)")
_AT = re.compile(r"at frame (\d+)(?: \((-?[\d.]+) s\))?")


def _moved_message(text: str, keep: slice, frames: int, frame_time: float) -> str | None:
    """A note or warning of the run over the extended clip with its frame numbers moved onto the clip's (None
    for one about frames outside it: the same moment of another cycle)."""
    def span(match) -> str:
        first, last = int(match[1]) - keep.start, int(match[2]) - keep.start
        if last < 0 or first > frames - 1:
            raise LookupError
        return f"frames {max(first, 0)}-{min(last, frames - 1)}"

    def at(match) -> str:
        frame = int(match[1]) - keep.start
        if not 0 <= frame < frames:
            raise LookupError
        return f"at frame {frame}" + (f" ({frame * frame_time:.2f} s)" if match[2] is not None else "")

    try:
        return _AT.sub(at, _SPAN.sub(span, text))
    except LookupError:
        return None


def _cut(result: PipelineResult, loop, frames: int) -> PipelineResult:
    """The run over the extended clip cut back to the clip's own frames (`Loop.middle`): every per-frame
    array sliced, frame numbers in the reports moved, counts over the extension taken as the clip's share."""
    keep = loop.middle(frames)
    share = frames / loop.length  # a count over the frames run, for the clip's

    def frame_range(first: int, last: int) -> list[int] | None:  # an inclusive range moved onto the clip
        first, last = max(first - keep.start, 0), min(last - keep.start, frames - 1)
        return [first, last] if first <= last else None

    def counted(value):
        return int(round(value * share)) if isinstance(value, int) and not isinstance(value, bool) else value

    motion = loop.close(result.motion.slice(keep))
    world = result.world_positions[keep]
    if loop.closed:
        world = world.copy()
        world[-1] = world[0] + loop.travel
    stretch = result.stretch
    if stretch is not None:
        events = []
        for event in stretch.events:
            moved = frame_range(*event.frames)
            if moved is not None:
                events.append(replace(event, frames=tuple(moved)))
        trails = []
        for trail in stretch.trails:  # (frames, original and exaggerated paths: lists a point a frame)
            on = [k for k, f in enumerate(trail["frames"]) if keep.start <= f < keep.stop]
            if on:
                paths = {key: [trail[key][k] for k in on] for key in ("original", "exaggerated")}
                trails.append({**trail, **paths, "frames": [trail["frames"][k] - keep.start for k in on]})
        stretch = replace(stretch, positions=stretch.positions[keep], stretch_factors=stretch.stretch_factors[keep],
                          events=events, trails=trails)
    constraints = result.constraints
    if constraints is not None:
        constraints = dict(constraints)
        constraints["contacts"] = {name: [moved for a, b in runs if (moved := frame_range(a, b)) is not None]
                                   for name, runs in constraints["contacts"].items()}
        constraints["stretch_keys"] = [{**key, "frame": key["frame"] - keep.start}
                                       for key in constraints["stretch_keys"] if keep.start <= key["frame"] < keep.stop]
        constraints["body"] = {part: {what: counted(n) for what, n in counts.items()} if isinstance(counts, dict)
                               else counted(counts) for part, counts in constraints["body"].items()}
    correct_report = result.correct_report
    if correct_report is not None:
        correct_report = replace(correct_report, **{name: counted(getattr(correct_report, name)) for name in
                                                    ("frames_corrected", "unconverged_frames", "frames_floored")})
    speed_report = result.speed_report
    if speed_report is not None and speed_report.seconds is not None:  # the same moment of the cycle in the clip
        frame_time = result.motion.frame_time
        first, last = (int(round(second / frame_time)) for second in speed_report.seconds)
        moved = (first - keep.start) % loop.period
        speed_report = replace(speed_report, seconds=(moved * frame_time, min(moved + last - first, frames - 1) *
                                                      frame_time))
    frame_time = result.motion.frame_time
    said = {result.speed_report.note(): speed_report.note()} if speed_report is not None and speed_report.joints else {}
    notes, warnings = [], []
    for kept, given in ((notes, result.notes), (warnings, result.warnings)):
        for text in given:
            moved = said.get(text) or _moved_message(text, keep, frames, frame_time)
            if moved is not None and moved not in kept:
                kept.append(moved)
    return replace(result, motion=motion, world_positions=world, stretch=stretch, constraints=constraints,
                   correct_report=correct_report, speed_report=speed_report, notes=notes, warnings=warnings)


def _run_stages(motion: Motion, config: PipelineConfig, paths: dict | None, stages: tuple[Stage, ...], *,
                keep: slice = slice(None)) -> PipelineResult:
    """`run` over the clip as it is (``keep``: the frames its largest stretch is measured over)."""
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
        max_link_stretch=max_link_stretch(state.positions[keep], skeleton.parents, skeleton.link_lengths()),
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
