"""The pipeline: the declared list of stages and the loop that runs it.

A stage is a name, a pure function ``(State, settings) -> State`` and a
function that picks the stage's settings out of a `PipelineConfig` (None
when the stage is switched off). `STAGES` is the order; `run` loops over it
and records which stages ran, so the manifest says exactly what was done.
Adding a stage is one function and one line in `STAGES`.

Leading synthetic rest frames (a T-pose and its settling frames) are found
before the stages run; the stages that filter in time see only the frames
after them, and they are written back as captured.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

import numpy as np

from .analysis.limbs import LIMB_NAMES, find_limbs, limb_joints
from .analysis.tpose import detect_rest_frames
from .config import DEFAULT_PRESET, InputConfig, PipelineConfig, load_preset
from .core.errors import ConfigError
from .core.motion import Motion
from .core.skeleton import Skeleton
from .core.timing import parse_duration, smootherstep
from .stages.contacts import ContactConfig, StretchKey, TargetSpec, constrain
from .stages.correct import CorrectReport, accent_stretch, correct, keep_bends
from .stages.extrapolate import extrapolate
from .stages.orient import incoming_joint, motion_from_world, recover_orientations
from .stages.springs import simulate_springs, spring_links, stable_link_stiffness, substeps_for
from .stages.stretch import StretchResult, StretchSpec, apply_stretches, find_strikes, overlapping, strike_scale
from .stages.subjoints import (
    SubjointConfig,
    SubjointHierarchy,
    build_hierarchy,
    even_out,
    link_starts,
    minor_branches,
    position_subjoints,
    riders,
    rubber_groups,
)

__all__ = [
    "State",
    "Stage",
    "STAGES",
    "PipelineResult",
    "prepare",
    "run",
    "exaggerate",
    "pipeline_limbs",
    "resolve_weights",
    "max_link_stretch",
]


class Output(NamedTuple):
    """The output skeleton's motion and the world transforms its FK reproduces."""

    motion: Motion
    world_positions: np.ndarray  # (F, J_out, 3)
    world_rotations: np.ndarray  # (F, J_out, 4)
    original_index: np.ndarray  # (J,) where each original joint is in the output skeleton


@dataclass(frozen=True)
class State:
    """What flows from stage to stage. Stages return a new State (``dataclasses.replace``).

    motion : the captured clip (rest frames removed with ``tpose = "drop"``)
    captured_rot, captured_pos : (F, J, 4) and (F, J, 3) its world transforms
    rest_frames : leading frames kept out of every filter and written as captured
    limbs : limb name -> `Limb`, found on the skeleton (the config's ``[limbs]`` win)
    positions : (F, J, 3) float64 working positions of the original joints
    paths : limb -> (frames, points), hand-edited end-effector paths, or None
    hierarchy : the sub-joint hierarchy, once the subjoints stage has run
    sub_positions : (F, J', 3) positions on the rubber skeleton, once a stage made them
    pins : original joints ``(k,)`` and weights ``(F, k)`` by which they keep their captured
        orientation (planted feet), once the constraints stage has run
    output : the output Motion and its world transforms, once orient has run
    findings : per-stage facts for the manifest (correct report, stretch result, substeps)
    notes : things the user should hear about, in the order they happened
    """

    motion: Motion
    captured_rot: np.ndarray
    captured_pos: np.ndarray
    rest_frames: int
    rest_frames_dropped: bool
    limbs: dict
    positions: np.ndarray
    paths: dict | None = None
    hierarchy: SubjointHierarchy | None = None
    sub_positions: np.ndarray | None = None
    pins: tuple[np.ndarray, np.ndarray] | None = None
    output: Output | None = None
    findings: dict[str, Any] = field(default_factory=dict)
    notes: tuple[str, ...] = ()

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
        return _uncut_hierarchy(self.motion.skeleton), positions

    def with_findings(self, **findings: Any) -> dict[str, Any]:
        return {**self.findings, **findings}


@functools.lru_cache(maxsize=16)
def _uncut_hierarchy(skeleton: Skeleton) -> SubjointHierarchy:
    hierarchy = build_hierarchy(skeleton, SubjointConfig(per_link=1))
    return replace(hierarchy, groups=())


@dataclass(frozen=True)
class Stage:
    """One block of the pipeline.

    name : what the manifest calls it
    apply : ``(state, settings) -> state``, pure
    settings : picks the stage's settings out of a PipelineConfig; None switches the stage off
    """

    name: str
    apply: Callable[[State, Any], State]
    settings: Callable[[PipelineConfig], Any]


# ---------------------------------------------------------------------------- the stages


def _extrapolate(state: State, config) -> State:
    first = state.first
    skeleton = state.motion.skeleton
    weights = resolve_weights(skeleton, config.weights, state.limbs)
    positions = state.positions.copy()
    frame_time = state.motion.frame_time
    sigma = config.sigma_frames(frame_time, len(state.positions) - first)
    notes = state.notes
    asked = parse_duration(config.smooth, frame_time, what="extrapolate.smooth")
    if asked > 0.5 * sigma:
        notes += (f"extrapolate.smooth {config.smooth!r} is more than half of sigma {config.sigma!r}; used "
                  f"{0.5 * sigma * frame_time:.3g} s (the band between them is what gets exaggerated)",)
    positions[first:] = extrapolate(
        state.positions[first:], sigma=sigma, omega=config.omega, weights=weights,
        smooth=config.smooth_frames(frame_time), ramp=sigma, max_speed=config.max_speed,
        still=config.still * skeleton.height() * frame_time,
        torso=(torso_joints(skeleton, state.limbs), config.torso) if config.torso != 1 else None,
        riders=rider_joints(skeleton),
    )
    return replace(state, positions=positions, notes=notes)


def _correct(state: State, config) -> State:
    first = state.first
    skeleton = state.motion.skeleton
    frame_time = state.motion.frame_time
    smooth = parse_duration(config.smooth, frame_time, what="correct.smooth")
    max_stretch = config.max_stretch
    if config.accent_speed > 0 and max_stretch > 1:
        max_stretch = accent_stretch(state.captured_pos[first:], frame_time, skeleton.height(),
                                     max_stretch=max_stretch, accent_speed=config.accent_speed,
                                     radius=max(int(round(smooth)), 1))
    hard = None
    if config.torso < 1:
        hard = np.zeros(skeleton.num_joints, bool)
        for name in ("spine", "neck"):
            if name in state.limbs:
                hard[list(state.limbs[name].joints[1:])] = True
        max_stretch = np.broadcast_to(max_stretch, (len(state.positions) - first, skeleton.num_joints)).copy()
        max_stretch[:, hard] = 1.0 + (max_stretch[:, hard] - 1.0) * config.torso
    hinges = limb_hinges(skeleton, state.limbs)
    bent = keep_bends(state.positions[first:], state.captured_pos[first:], hinges) if hinges else state.positions[first:]
    body, report = correct(
        bent, skeleton.parents, skeleton.link_lengths(), threshold=config.threshold,
        delta=config.delta, max_stretch=max_stretch, max_iter=config.max_iter, smooth=smooth, hard=hard,
    )
    positions = state.positions.copy()
    positions[first:] = body
    notes = state.notes
    if report.unconverged_frames:
        notes += (f"correction stopped at max_iter with {report.unconverged_frames} frame(s) above threshold",)
    return replace(state, positions=positions, findings=state.with_findings(correct=report), notes=notes)


class StretchPlan(NamedTuple):
    """The stretch stage's settings: the declared events and the automatic finder's."""

    specs: tuple[StretchSpec, ...]
    auto: Any  # AutoStretchConfig


def _stretch(state: State, plan: StretchPlan) -> State:
    motion, first = state.motion, state.first
    specs = list(plan.specs)
    notes = list(state.notes)
    reaches: dict[tuple[str, int, int], float] = {}
    if plan.auto.enabled:
        # Strikes are found in the captured motion, not in its exaggeration.
        found = find_strikes(state.captured_pos[first:], motion.skeleton, state.limbs, motion.frame_time, plan.auto)
        styled = [spec.shifted(first) for spec in found]
        found = [strike_scale(spec, state.positions, motion.skeleton, state.limbs, motion.frame_time)
                 for spec in styled]
        notes += [f"auto-stretch: {s.limb} frames {s.start}-{s.end} to {style.scale:g} limb lengths (x{s.scale:.3g})"
                  for s, style in zip(found, styled)]
        reaches = {(s.limb, int(s.start), int(s.end)): style.scale for s, style in zip(found, styled)}
        span = functools.partial(StretchSpec.span, frame_time=motion.frame_time, num_frames=motion.num_frames)
        for spec in found:  # the user's own events win over found ones
            if not overlapping(span(spec), [span(other) for other in specs if other.limb == spec.limb]):
                specs.append(spec)
    result = apply_stretches(state.positions, motion.skeleton, state.limbs, tuple(specs), motion.frame_time,
                             paths=state.paths)
    positions = result.positions
    positions[:first] = state.positions[:first]
    for event in result.events:
        reach = reaches.get((event["limb"], *event["frames"]))
        if reach is not None:  # a found strike: its style is the reach it ends at, in limb lengths
            event["reach"] = reach
        if event["axes_relaxed"]:
            notes.append(
                f"stretch {event['limb']} frames {event['frames'][0]}-{event['frames'][1]}: the path cannot "
                f"squash to x{event['scale']:g} on axes {event['axes']}; squashed along the limb instead"
            )
    return replace(state, positions=positions, findings=state.with_findings(stretch=result), notes=tuple(notes))


def _subjoints(state: State, config: SubjointConfig) -> State:
    skeleton = state.motion.skeleton
    hierarchy = build_hierarchy(skeleton, config)
    return replace(state, hierarchy=hierarchy,
                   sub_positions=position_subjoints(state.positions, hierarchy, skeleton.link_lengths()))


def _springs(state: State, config) -> State:
    hierarchy, positions = state.rubber()
    parents = hierarchy.skeleton.parents
    frame_time = state.motion.frame_time
    # Follow-through hangs off a solid body: the root, spine, neck, head, collars and the limbs' roots
    # follow their (exaggerated) positions exactly; the arms and legs below the shoulder and hip swing.
    # A lagging torso stretched more than the limbs (1.4x on a boxer's neck), which cartoon torsos do
    # not (the Stretch-Engine thesis's Table 1), and a lagging collar spun the chest round.
    skeleton = state.motion.skeleton
    active = ~hierarchy.rigid[hierarchy.link_child]
    limbs = [limb for name, limb in state.limbs.items() if name.endswith(("_arm", "_leg"))]
    if limbs:
        hanging = np.zeros(skeleton.num_joints, bool)
        for limb in limbs:
            hanging[limb_joints(skeleton, limb)] = True
        hanging[[limb.base for limb in limbs]] = False
        active &= hanging[hierarchy.link_child]
        # The follow-through grows along a limb's first link, from none at the shoulder or hip to all
        # of it at the elbow or knee: a sub-joint next to a fixed root swinging fully kinked the limb there.
        blend = np.full(len(parents), float(config.blend))
        for limb in limbs:
            first = hierarchy.link_child == limb.joints[1]
            blend[first] *= smootherstep(hierarchy.fraction[first])
    else:
        blend = config.blend
    links = spring_links(parents, active)
    out = positions.copy()
    out[state.first:] = simulate_springs(
        positions[state.first:], parents, frame_time, stiffness=config.stiffness,
        link_stiffness=config.link_stiffness, damping=config.damping, blend=blend, links=links,
    )
    # The knees' and elbows' lag may carry them behind the line again: bend them back, the
    # sub-joints on the two links either side moving with them in proportion.
    hinges = limb_hinges(skeleton, state.limbs)
    if hinges:
        original = hierarchy.original
        moving = out[state.first:]
        joints = moving[:, original]
        bent = keep_bends(joints, state.captured_pos[state.first:], hinges)
        for hinge in hinges:
            _, middle, end = hinge[:3]
            shift = bent[:, middle] - joints[:, middle]
            if not shift.any():
                continue
            upper = np.flatnonzero(hierarchy.link_child == middle)  # the middle joint and the sub-joints above it
            lower = np.flatnonzero((hierarchy.link_child == end) & ~hierarchy.is_original)
            moving[:, upper] += hierarchy.fraction[upper][None, :, None] * shift[:, None]
            moving[:, lower] += (1.0 - hierarchy.fraction[lower])[None, :, None] * shift[:, None]
    # The lag bunches sub-joints along a limb as well as bending it: make its sub-links even again.
    swinging = np.unique(hierarchy.link_child[np.flatnonzero(np.asarray(blend) * active > 0)])
    out[state.first:] = even_out(out[state.first:], hierarchy, swinging)
    substeps = substeps_for(frame_time, config.stiffness, config.link_stiffness, links.degree)
    carried = stable_link_stiffness(frame_time, config.link_stiffness, links.degree, substeps)
    notes = state.notes
    if carried < config.link_stiffness:
        notes += (f"springs: link stiffness {config.link_stiffness:g} is more than {substeps} substeps per frame "
                  f"can carry at {1 / frame_time:g} fps; used {carried:.4g}",)
    return replace(state, sub_positions=out, findings=state.with_findings(spring_substeps=substeps), notes=notes)


class ConstraintPlan(NamedTuple):
    """The constraints stage's settings: contact detection and the floor, and the targets."""

    contacts: ContactConfig
    targets: tuple[TargetSpec, ...]
    max_speed: float = 0.0  # the extrapolation's, which easing onto a contact keeps to


def _constraints(state: State, plan: ConstraintPlan) -> State:
    motion, first = state.motion, state.first
    skeleton = motion.skeleton
    hierarchy, positions = state.rubber()
    targets = []
    for spec in plan.targets:
        frame = spec.frame_index(motion.frame_time, motion.num_frames)
        if frame < first:
            raise ConfigError(f"target {spec.joint}@{spec.frame}: frame {frame} is a rest-pose frame "
                              f"(motion starts at {first})")
        targets.append((spec, frame - first))
    keys = []
    stretch = state.findings.get("stretch")
    if stretch is not None:
        for event in stretch.events:
            limb = state.limbs[event["limb"]]
            frame = event["frames"][1] if event["pivot"] == "start" else event["frames"][0]
            if frame >= first:
                vectors = stretch.positions[first:, limb.end] - stretch.positions[first:, limb.base]
                keys.append(StretchKey(event["limb"], limb.base, limb.end, frame - first, vectors))
    groups = hierarchy.groups or rubber_groups(skeleton, hierarchy.rigid)
    result = constrain(
        positions[first:], hierarchy, skeleton, state.limbs, state.captured_pos[first:], state.captured_rot[first:],
        motion.frame_time, config=plan.contacts, targets=tuple(targets), keys=tuple(keys), groups=groups,
        incoming=lambda joint: incoming_joint(skeleton, joint), max_speed=plan.max_speed,
        riders=rider_joints(skeleton),
    )
    out = positions.copy()
    # The chains bent to meet their targets, with even sub-links again (each keeping its direction).
    bent = [j for limb in state.limbs.values() for j in limb.joints[1:]]
    out[first:] = even_out(result.positions, hierarchy, np.array(bent, dtype=np.int64))
    weights = np.zeros((len(positions), len(result.pin_joints)))
    weights[first:] = result.pin_weights
    contacts = {name: [[int(a) + first, int(b) + first] for a, b in runs] for name, runs in result.contacts.items()}
    report = {"contacts": contacts, "anchor": plan.contacts.anchor if plan.contacts.enabled else None,
              "targets": [{**spec.to_dict(), "frame": frame + first} for spec, frame in targets],
              "stretch_keys": [{**key, "frame": key["frame"] + first} for key in result.keys]}
    if result.ground is not None:
        report["floor"] = {"axis": "XYZ"[result.ground.axis], "up": "+" if result.ground.sign > 0 else "-",
                           "height": round(result.ground.sign * result.ground.floor, 6)}
    return replace(state, sub_positions=out, pins=(result.pin_joints, weights),
                   findings=state.with_findings(constraints=report))


def _orient(state: State, plan: tuple) -> State:
    config, max_speed = plan
    motion = state.motion
    hierarchy, positions = state.rubber()
    sub_rot, sub_pos = recover_orientations(positions, hierarchy, motion, state.captured_rot, state.captured_pos,
                                            state.pins, max_speed=max_speed)
    rubber = link_starts(hierarchy)  # the skeleton sub_rot and sub_pos are on
    if config.skeleton == "original":
        keep = rubber.original
        out_pos, out_rot = sub_pos[:, keep], sub_rot[:, keep]
        out = motion_from_world(out_pos, out_rot, motion.skeleton.with_full_channels(), motion.frame_time,
                                motion.euler_hint)
        original_index = np.arange(motion.skeleton.num_joints)
    else:
        out_pos, out_rot = sub_pos, sub_rot
        out = motion_from_world(out_pos, out_rot, rubber.skeleton, motion.frame_time)
        original_index = rubber.original
    return replace(state, output=Output(out, out_pos, out_rot, original_index))


def _block(name: str) -> Callable[[PipelineConfig], Any]:
    """Settings picker for a block with an ``enabled`` switch."""
    def pick(config: PipelineConfig):
        block = getattr(config, name)
        return block if block.enabled else None

    return pick


#: The blocks in the order they run.
STAGES: tuple[Stage, ...] = (
    Stage("extrapolate", _extrapolate, _block("extrapolate")),
    Stage("correct", _correct, _block("correct")),
    Stage("stretch", _stretch,
          lambda c: StretchPlan(c.stretch, c.auto_stretch) if c.stretch or c.auto_stretch.enabled else None),
    Stage("subjoints", _subjoints, _block("subjoints")),
    Stage("springs", _springs, lambda c: c.springs if c.springs.enabled and c.springs.blend > 0 else None),
    Stage("constraints", _constraints,
          lambda c: ConstraintPlan(c.contacts, c.target, c.extrapolate.max_speed if c.extrapolate.enabled else 0.0)
          if c.contacts.enabled or c.target or c.stretch or c.auto_stretch.enabled else None),
    Stage("orient", _orient,
          lambda c: (c.output, c.extrapolate.max_speed if c.extrapolate.enabled else 0.0)),
)


# ---------------------------------------------------------------------------- running


@dataclass
class PipelineResult:
    """A run's output and what happened on the way.

    motion : the output Motion (6 channels on every joint)
    world_positions : (F, J_out, 3) float64 positions the output's FK reproduces
    world_rotations : (F, J_out, 4) float64 orientations it reproduces
    original_index : (J,) int, where each original joint is in the output skeleton
    hierarchy : the rubber skeleton written out, with each cut link's start joint
        (`mocap_exaggerate.stages.subjoints.link_starts`); None when sub-joints were off
    rest_frames : leading synthetic rest frames kept out of the filters
    stages : names of the stages that ran, in order
    timings : seconds per step, in run order
    correct_report : CorrectReport or None when correction was off
    preserve_volume : ``output.preserve_volume``: the skinned outputs (GLB, previews) scale
        each joint by `mocap_exaggerate.jobs.outputs.output_thickness`
    """

    motion: Motion
    world_positions: np.ndarray
    world_rotations: np.ndarray
    original_index: np.ndarray
    hierarchy: SubjointHierarchy | None
    rest_frames: int
    rest_frames_dropped: bool
    timings: dict[str, float]
    correct_report: CorrectReport | None = None
    max_link_stretch: float = 1.0
    substeps: int = 0
    notes: list[str] = field(default_factory=list)
    stretch: StretchResult | None = None
    stages: list[str] = field(default_factory=list)
    constraints: dict | None = None
    preserve_volume: bool = True

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
    if paths:
        config = replace(config, stretch=config.stretch + _specs_for_paths(paths, config.stretch))
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
        state = stage.apply(state, settings)
        timings[stage.name] = time.perf_counter() - start
        ran.append(stage.name)
    if state.output is None:
        raise ValueError("the pipeline's stages produced no output motion (is orient in the list?)")
    skeleton = state.motion.skeleton
    return PipelineResult(
        motion=state.output.motion,
        world_positions=state.output.world_positions,
        world_rotations=state.output.world_rotations,
        original_index=state.output.original_index,
        hierarchy=link_starts(state.hierarchy) if state.hierarchy is not None else None,
        rest_frames=state.rest_frames,
        rest_frames_dropped=state.rest_frames_dropped,
        timings=timings,
        correct_report=state.findings.get("correct"),
        max_link_stretch=max_link_stretch(state.positions, skeleton.parents, skeleton.link_lengths()),
        substeps=state.findings.get("spring_substeps", 0),
        notes=list(state.notes),
        stretch=state.findings.get("stretch"),
        stages=ran,
        constraints=state.findings.get("constraints"),
        preserve_volume=config.output.preserve_volume,
    )


def _specs_for_paths(paths: dict, specs: tuple[StretchSpec, ...]) -> tuple[StretchSpec, ...]:
    """Events (scale 1, no release) for edited paths on limbs no declared stretch covers."""
    extra = []
    for limb, (edit_frames, _) in paths.items():
        if not any(s.limb == limb for s in specs) and len(edit_frames) >= 2:
            extra.append(StretchSpec(limb=limb, start=int(min(edit_frames)), end=int(max(edit_frames)), scale=1.0,
                                     release=0))
    return tuple(extra)


def max_link_stretch(positions: np.ndarray, parents: np.ndarray, lengths: np.ndarray) -> float:
    """Largest ratio of current to rest length over links longer than 1e-3 of the longest.

    Shorter ones are placeholders (Reallusion's pelvis sits 0.7 micrometres from its hip):
    moved a centimetre they read as a 37,000x stretch.
    """
    long_links = lengths > 1e-3 * max(lengths.max(), 1e-12)
    long_links[0] = False
    if not long_links.any():
        return 1.0
    current = np.linalg.norm(positions[:, long_links] - positions[:, parents[long_links]], axis=-1)
    return float((current / lengths[long_links]).max())


def limb_hinges(skeleton: Skeleton, limbs: dict) -> list[tuple[int, ...]]:
    """(base, middle, end) of every arm and leg, and for a leg its longest toe after them."""
    hinges = []
    lengths = skeleton.link_lengths()
    for name, limb in limbs.items():
        if name.endswith(("_arm", "_leg")) and len(limb.joints) >= 3:
            toes = [int(c) for c in skeleton.children(limb.joints[2])] if name.endswith("_leg") else []
            reach = [lengths[c] for c in toes]
            hinges.append(tuple(limb.joints[:3]) + ((toes[int(np.argmax(reach))],) if toes and max(reach) > 0 else ()))
    return hinges


def rider_joints(skeleton: Skeleton) -> dict[int, list[int]]:
    """Joint -> the joints of minor branches riding rigidly on it (toes on a foot, fingers on a hand)."""
    return riders(skeleton, minor_branches(skeleton))


def torso_joints(skeleton: Skeleton, limbs: dict) -> np.ndarray:
    """The torso: the spine chain and everything above it (neck, head, collars, shoulder balls), not the arms.

    With no spine found, the neck chain (and what hangs off it) if there is one.
    """
    base = limbs["spine"].base if "spine" in limbs else limbs["neck"].base if "neck" in limbs else None
    if base is None:
        return np.zeros(0, dtype=np.int64)
    torso = set(skeleton.descendants(base).tolist()) | {base}
    for name, limb in limbs.items():
        if name.endswith("_arm"):  # the arm below its shoulder ball: twist and share bones too
            torso -= set(skeleton.descendants(limb.base).tolist()) - {limb.base}
    return np.array(sorted(torso), dtype=np.int64)


def pipeline_limbs(skeleton: Skeleton, config: PipelineConfig) -> dict:
    """Limbs found on ``skeleton``, with the config's ``[limbs]`` winning."""
    try:
        return find_limbs(skeleton, {name: list(chain) for name, chain in config.limbs})
    except (KeyError, ValueError) as error:
        raise ConfigError(f"limbs: {error.args[0]}") from None


def resolve_weights(skeleton: Skeleton, weights: tuple[tuple[str, float], ...], limbs: dict | None = None) -> np.ndarray:
    """Per-joint weights ``(J,)`` from ``(pattern, weight)`` pairs; later pairs win.

    A pattern is a limb name (its joints and everything below its end), an
    exact joint name, ``root`` or ``pelvis`` (the root, on any rig, unless a joint
    has that name), or a shell pattern over joint names.

    Joints welded together (a link shorter than `WELD` of the body's height:
    Reallusion's CC_Base_Pelvis on CC_Base_Hip, CMU's LHipJoint on Hips) take
    one weight: the last given to any of them. Two welded joints exaggerated
    apart would open a link of no length into one of centimetres, a stretch
    of thousands of times that no correction can undo. For the same reason the
    joints riding rigidly on another (`rider_joints`: fingers on a hand, toes on
    a foot) take the weight of the joint they ride on.
    """
    out = np.ones(skeleton.num_joints)
    weld = welded(skeleton)
    for pattern, weight in weights:
        if pattern in ROOT_NAMES and pattern not in skeleton.names:
            joints = np.array([0])
        elif pattern in LIMB_NAMES or (limbs and pattern in limbs):
            limbs = find_limbs(skeleton) if limbs is None else limbs
            if pattern not in limbs:
                raise ConfigError(f"weight {pattern}={weight:g}: no {pattern} found on this skeleton")
            joints = limb_joints(skeleton, limbs[pattern])
        elif pattern in skeleton.names:
            joints = np.array([skeleton.index(pattern)])
        else:
            joints = skeleton.match(pattern)
            if not len(joints):
                sample = ", ".join(skeleton.names[:6])
                raise ConfigError(
                    f"weight {pattern}={weight:g}: no joint or limb matches {pattern!r} "
                    f"(joints: {sample}, ...; limbs: {', '.join(LIMB_NAMES)}; root)"
                )
        out[np.isin(weld, weld[joints])] = weight
    for anchor, below in rider_joints(skeleton).items():
        out[below] = out[anchor]
    return out


#: Names a weight can give the root by on every rig.
ROOT_NAMES = ("root", "pelvis")
#: Links shorter than this share of the body's height weld their joints together (`welded`).
WELD = 0.01


def welded(skeleton: Skeleton) -> np.ndarray:
    """``(J,)`` for each joint, the highest joint it is welded to by links shorter than `WELD` x height."""
    short = skeleton.link_lengths() < WELD * skeleton.height()
    weld = np.arange(skeleton.num_joints)
    for j in range(1, skeleton.num_joints):  # parents come first: one pass (joints, not frames)
        if short[j]:
            weld[j] = weld[skeleton.parents[j]]
    return weld


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
