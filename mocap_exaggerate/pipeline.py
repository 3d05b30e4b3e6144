"""The pipeline: stage configs composed into one declaration, presets, and `run`.

A pipeline is the ordered list of blocks that are switched on. Its whole
declaration is a `PipelineConfig`, which round-trips through TOML; the same
declaration and input give the same output, byte for byte.
"""

from __future__ import annotations

import copy
import hashlib
import logging
import time
import tomllib
from dataclasses import asdict, dataclass, field, fields
from importlib import resources
from typing import Any

import numpy as np
import tomli_w

from . import __version__
from .errors import ConfigError, check_number
from .limbs import LIMB_NAMES, find_limbs, limb_joints
from .motion import Motion
from .skeleton import Skeleton
from .stages.correct import CorrectConfig, CorrectReport, correct
from .stages.extrapolate import ExtrapolateConfig, extrapolate
from .stages.orient import motion_from_world, recover_orientations
from .stages.springs import SpringConfig, simulate_springs, spring_substeps
from .stages.stretch import AutoStretchConfig, StretchResult, StretchSpec, apply_stretches, find_strikes
from .stages.subjoints import SubjointConfig, SubjointHierarchy, build_hierarchy, position_subjoints
from .stages.tpose import detect_rest_frames

__all__ = [
    "InputConfig",
    "PipelineConfig",
    "PipelineResult",
    "DEFAULT_PRESET",
    "preset_names",
    "load_preset",
    "preset_description",
    "resolve_config",
    "resolve_weights",
    "run",
    "exaggerate",
    "pipeline_limbs",
    "make_glb",
    "STAGES",
]

log = logging.getLogger(__name__)

DEFAULT_PRESET = "cartoon"
#: Blocks in the order they run.
STAGES = ("extrapolate", "correct", "stretch", "subjoints", "springs")
_TPOSE_MODES = ("auto", "keep", "drop")
_SKELETON_MODES = ("sub", "original")


@dataclass(frozen=True, kw_only=True)
class InputConfig:
    """How the clip is read.

    tpose : ``auto`` detects a synthetic leading rest pose, keeps it out of
        every filter and writes it back unchanged; ``keep`` treats it as
        motion; ``drop`` removes it from the output.
    fps : frame rate overriding the header's ``Frame Time`` (None keeps it).
    """

    tpose: str = "auto"
    fps: float | None = None

    def __post_init__(self) -> None:
        if self.tpose not in _TPOSE_MODES:
            raise ConfigError(f"input.tpose must be one of {', '.join(_TPOSE_MODES)}, got {self.tpose!r}")
        if self.fps is not None:
            check_number("input.fps", self.fps, 0, 10000, low_open=True)


@dataclass(frozen=True, kw_only=True)
class OutputConfig:
    """What is written.

    skeleton : ``sub`` writes the rubber sub-joint hierarchy; ``original``
        the original joints only (6 channels each), for pipelines that need
        the original joint set.
    """

    skeleton: str = "sub"

    def __post_init__(self) -> None:
        if self.skeleton not in _SKELETON_MODES:
            raise ConfigError(f"output.skeleton must be one of {', '.join(_SKELETON_MODES)}, got {self.skeleton!r}")


_BLOCKS = {
    "input": InputConfig,
    "extrapolate": ExtrapolateConfig,
    "correct": CorrectConfig,
    "auto_stretch": AutoStretchConfig,
    "subjoints": SubjointConfig,
    "springs": SpringConfig,
    "output": OutputConfig,
}


@dataclass(frozen=True, kw_only=True)
class PipelineConfig:
    """Every block's settings: the whole declaration of a run."""

    input: InputConfig = field(default_factory=InputConfig)
    extrapolate: ExtrapolateConfig = field(default_factory=ExtrapolateConfig)
    correct: CorrectConfig = field(default_factory=CorrectConfig)
    subjoints: SubjointConfig = field(default_factory=SubjointConfig)
    springs: SpringConfig = field(default_factory=SpringConfig)
    output: OutputConfig = field(default_factory=OutputConfig)
    auto_stretch: AutoStretchConfig = field(default_factory=AutoStretchConfig)
    stretch: tuple[StretchSpec, ...] = ()
    limbs: tuple[tuple[str, tuple[str, ...]], ...] = ()
    description: str = ""

    @classmethod
    def from_dict(cls, data: dict[str, Any], *, source: str = "config") -> PipelineConfig:
        """Build and validate from nested tables; unknown keys are errors naming the key."""
        if not isinstance(data, dict):
            raise ConfigError(f"{source}: expected a table of blocks")
        blocks: dict[str, Any] = {}
        for key, value in data.items():
            if key == "description":
                if not isinstance(value, str):
                    raise ConfigError(f"{source}: description must be text")
                blocks["description"] = value
                continue
            if key == "stretch":
                blocks["stretch"] = _stretch_from_list(value, source)
                continue
            if key == "limbs":
                blocks["limbs"] = _limbs_from_table(value, source)
                continue
            if key not in _BLOCKS:
                known = ", ".join(list(_BLOCKS) + ["limbs", "[stretch]"])
                raise ConfigError(f"{source}: unknown block [{key}] (known: {known})")
            if not isinstance(value, dict):
                raise ConfigError(f"{source}: [{key}] must be a table")
            block_type = _BLOCKS[key]
            known = {f.name for f in fields(block_type)}
            values = {}
            for name, item in value.items():
                if name not in known:
                    raise ConfigError(f"{source}: unknown key {key}.{name} (known: {', '.join(sorted(known))})")
                values[name] = item
            if key == "extrapolate" and "weights" in values:
                values["weights"] = _weights_from_table(values["weights"], source)
            for integer in ("max_iter", "per_link"):
                if isinstance(values.get(integer), float) and values[integer].is_integer():
                    values[integer] = int(values[integer])
            for listed in ("groups", "rigid"):
                if listed in values and not isinstance(values[listed], (list, tuple)):
                    raise ConfigError(f"{source}: {key}.{listed} must be a list")
            try:
                blocks[key] = block_type(**values)
            except ConfigError as error:
                raise ConfigError(f"{source}: {error}") from None
            except TypeError as error:
                raise ConfigError(f"{source}: [{key}]: {error}") from None
        try:
            return cls(**blocks)
        except ConfigError as error:
            raise ConfigError(f"{source}: {error}") from None

    def to_dict(self) -> dict[str, Any]:
        """Nested plain tables (TOML-ready: None values are left out)."""
        out: dict[str, Any] = {}
        if self.description:
            out["description"] = self.description
        for name in _BLOCKS:
            table = asdict(getattr(self, name))
            if name == "extrapolate":
                table["weights"] = {pattern: float(w) for pattern, w in self.extrapolate.weights}
            if name == "subjoints":
                table["groups"] = [list(g) for g in self.subjoints.groups]
                table["rigid"] = list(self.subjoints.rigid)
            out[name] = {k: v for k, v in table.items() if v is not None}
        if self.limbs:
            out["limbs"] = {name: list(chain) for name, chain in self.limbs}
        if self.stretch:
            out["stretch"] = [spec.to_dict() for spec in self.stretch]
        return out

    @classmethod
    def from_toml(cls, text: str, *, source: str = "config") -> PipelineConfig:
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as error:
            raise ConfigError(f"{source}: not valid TOML: {error}") from None
        return cls.from_dict(data, source=source)

    def to_toml(self) -> str:
        return tomli_w.dumps(self.to_dict())


def _stretch_from_list(items: Any, source: str) -> tuple[StretchSpec, ...]:
    if not isinstance(items, (list, tuple)):
        raise ConfigError(f"{source}: stretch must be a list of tables ([[stretch]])")
    specs = []
    known = {f.name for f in fields(StretchSpec)}
    for number, item in enumerate(items, start=1):
        if not isinstance(item, dict):
            raise ConfigError(f"{source}: stretch #{number} must be a table")
        unknown = set(item) - known
        if unknown:
            raise ConfigError(f"{source}: stretch #{number}: unknown key {sorted(unknown)[0]} (known: {', '.join(sorted(known))})")
        missing = {"limb", "start", "end", "scale"} - set(item)
        if missing:
            raise ConfigError(f"{source}: stretch #{number}: missing {', '.join(sorted(missing))}")
        values = dict(item)
        for ease in ("ease_in", "ease_out"):
            if isinstance(values.get(ease), list):
                values[ease] = tuple(values[ease])
        try:
            specs.append(StretchSpec(**values))
        except ConfigError as error:
            raise ConfigError(f"{source}: stretch #{number}: {error}") from None
    return tuple(specs)


def _limbs_from_table(table: Any, source: str) -> tuple[tuple[str, tuple[str, ...]], ...]:
    if not isinstance(table, dict):
        raise ConfigError(f"{source}: [limbs] must be a table of name = [joints]")
    out = []
    for name, chain in table.items():
        if not isinstance(chain, (list, tuple)) or len(chain) < 2 or not all(isinstance(n, str) for n in chain):
            raise ConfigError(f"{source}: limbs.{name} must list at least two joint names, base first")
        out.append((str(name), tuple(chain)))
    return tuple(out)


def _weights_from_table(table: Any, source: str) -> tuple[tuple[str, float], ...]:
    if isinstance(table, dict):
        items = list(table.items())
    elif isinstance(table, (list, tuple)):
        items = [tuple(item) for item in table]
    else:
        raise ConfigError(f"{source}: extrapolate.weights must be a table of name = weight")
    out = []
    for pattern, weight in items:
        if isinstance(weight, bool) or not isinstance(weight, (int, float)):
            raise ConfigError(f"{source}: extrapolate.weights[{pattern!r}] must be a number, got {weight!r}")
        out.append((str(pattern), float(weight)))
    return tuple(out)


# ---------------------------------------------------------------------------- presets


def preset_names() -> list[str]:
    """Names of the shipped presets."""
    folder = resources.files("mocap_exaggerate") / "presets"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


def _preset_table(name: str) -> dict[str, Any]:
    if name not in preset_names():
        raise ConfigError(f"unknown preset {name!r} (known: {', '.join(preset_names())})")
    text = (resources.files("mocap_exaggerate") / "presets" / f"{name}.toml").read_text(encoding="utf-8")
    return tomllib.loads(text)


def load_preset(name: str) -> PipelineConfig:
    """A shipped preset as a PipelineConfig."""
    return PipelineConfig.from_dict(_preset_table(name), source=f"preset {name}")


def preset_description(name: str) -> str:
    return str(_preset_table(name).get("description", ""))


def _merge(base: dict[str, Any], top: dict[str, Any]) -> dict[str, Any]:
    out = copy.deepcopy(base)
    for key, value in top.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def resolve_config(
    preset: str | None = DEFAULT_PRESET,
    config_text: str | None = None,
    overrides: dict[str, Any] | None = None,
    *,
    config_source: str = "config",
) -> PipelineConfig:
    """Shipped preset < config file < explicit overrides (nested tables), validated."""
    table: dict[str, Any] = _preset_table(preset) if preset else {}
    if config_text is not None:
        try:
            file_table = tomllib.loads(config_text)
        except tomllib.TOMLDecodeError as error:
            raise ConfigError(f"{config_source}: not valid TOML: {error}") from None
        PipelineConfig.from_dict(file_table, source=config_source)  # name the file in its own errors
        table = _merge(table, file_table)
    if overrides:
        table = _merge(table, overrides)
    return PipelineConfig.from_dict(table, source=config_source if config_text is not None else "options")


# ---------------------------------------------------------------------------- running


def pipeline_limbs(skeleton: Skeleton, config: PipelineConfig) -> dict:
    """Limbs found on ``skeleton``, with the config's ``[limbs]`` winning."""
    try:
        return find_limbs(skeleton, {name: list(chain) for name, chain in config.limbs})
    except (KeyError, ValueError) as error:
        raise ConfigError(f"limbs: {error.args[0]}") from None


def resolve_weights(skeleton: Skeleton, weights: tuple[tuple[str, float], ...], limbs: dict | None = None) -> np.ndarray:
    """Per-joint weights ``(J,)`` from ``(pattern, weight)`` pairs; later pairs win.

    A pattern is a limb name (its joints and everything below its end), an
    exact joint name, or a shell pattern over joint names.
    """
    out = np.ones(skeleton.num_joints)
    for pattern, weight in weights:
        if pattern in LIMB_NAMES or (limbs and pattern in limbs):
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
                    f"(joints: {sample}, ...; limbs: {', '.join(LIMB_NAMES)})"
                )
        out[joints] = weight
    return out


@dataclass
class PipelineResult:
    """A run's output and what happened on the way.

    motion : the output Motion (6 channels on every joint)
    world_positions : (F, J_out, 3) float64 positions the output's FK reproduces
    world_rotations : (F, J_out, 4) float64 orientations it reproduces
    original_index : (J,) int, where each original joint is in the output skeleton
    hierarchy : the sub-joint hierarchy (None when sub-joints were off)
    rest_frames : leading synthetic rest frames kept out of the filters
    timings : seconds per block, in run order
    correct_report : CorrectReport or None when correction was off
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


def run(motion: Motion, config: PipelineConfig | None = None, *, paths: dict | None = None) -> PipelineResult:
    """Run the blocks that are switched on over a whole clip.

    ``paths`` maps limb names to hand-edited end-effector paths ``(frames,
    positions)`` (a trails file): the limb follows them (see `apply_stretches`).
    """
    config = config or PipelineConfig()
    timings: dict[str, float] = {}
    notes: list[str] = []

    start = time.perf_counter()
    world_rot, world = motion.forward_kinematics()
    rest = detect_rest_frames(motion, world) if config.input.tpose in ("auto", "drop") else 0
    dropped = config.input.tpose == "drop" and rest > 0
    if dropped:
        motion = motion.slice(slice(rest, None))
        world_rot, world = world_rot[rest:], world[rest:]
        notes.append(f"dropped {rest} leading rest-pose frame(s)")
    elif rest:
        notes.append(f"kept {rest} leading rest-pose frame(s) out of the filters, unchanged")
    timings["forward_kinematics"] = time.perf_counter() - start

    first = 0 if dropped else rest
    body = world[first:]
    skeleton = motion.skeleton

    limbs = pipeline_limbs(skeleton, config)
    if config.extrapolate.enabled:
        start = time.perf_counter()
        weights = resolve_weights(skeleton, config.extrapolate.weights, limbs)
        body = extrapolate(
            body,
            sigma=config.extrapolate.sigma_frames(motion.frame_time),
            omega=config.extrapolate.omega,
            weights=weights,
        )
        timings["extrapolate"] = time.perf_counter() - start

    report = None
    if config.correct.enabled:
        start = time.perf_counter()
        body, report = correct(
            body,
            skeleton.parents,
            skeleton.link_lengths(),
            threshold=config.correct.threshold,
            delta=config.correct.delta,
            max_stretch=config.correct.max_stretch,
            max_iter=config.correct.max_iter,
        )
        if report.unconverged_frames:
            notes.append(f"correction stopped at max_iter with {report.unconverged_frames} frame(s) above threshold")
        timings["correct"] = time.perf_counter() - start

    stretch_result = None
    specs = list(config.stretch)
    if config.auto_stretch.enabled:
        # Strikes are found in the captured motion, not in its exaggeration.
        found = find_strikes(world[first:], skeleton, limbs, motion.frame_time, config.auto_stretch)
        found = [s.shifted(first) for s in found]
        for spec in found:
            notes.append(f"auto-stretch: {spec.limb} frames {spec.start}-{spec.end} x{spec.scale:g}")
        for spec in found:  # the user's own events win over found ones
            if not _overlaps(spec, specs, motion.frame_time, motion.num_frames):
                specs.append(spec)
    if specs or paths:
        start = time.perf_counter()
        specs += _specs_for_paths(paths, specs, motion.frame_time, motion.num_frames)
        whole = world.copy()
        whole[first:] = body
        stretch_result = apply_stretches(whole, skeleton, limbs, tuple(specs), motion.frame_time, paths=paths)
        body = stretch_result.positions[first:]
        for event in stretch_result.events:
            if event["axes_relaxed"]:
                notes.append(
                    f"stretch {event['limb']} frames {event['frames'][0]}-{event['frames'][1]}: the path cannot "
                    f"squash to x{event['scale']:g} on axes {event['axes']}; squashed along the limb instead"
                )
        timings["stretch"] = time.perf_counter() - start

    positions = world.copy()
    positions[first:] = body
    lengths = skeleton.link_lengths()
    stretch = _max_link_stretch(positions, skeleton.parents, lengths)

    start = time.perf_counter()
    sub_config = config.subjoints if config.subjoints.enabled else SubjointConfig(per_link=1, groups=(), rigid=())
    hierarchy = build_hierarchy(skeleton, sub_config)
    if not config.subjoints.enabled:
        hierarchy = SubjointHierarchy(hierarchy.skeleton, hierarchy.original, hierarchy.link_child,
                                      hierarchy.link_parent, hierarchy.fraction, hierarchy.rigid, ())
    sub_pos = position_subjoints(positions, hierarchy, lengths)
    timings["subjoints"] = time.perf_counter() - start

    substeps = 0
    if config.springs.enabled and config.springs.blend > 0:
        start = time.perf_counter()
        active = ~hierarchy.rigid[hierarchy.link_child]
        substeps = spring_substeps(hierarchy.skeleton.parents, motion.frame_time, config.springs, active)
        sub_pos[first:] = simulate_springs(
            sub_pos[first:],
            hierarchy.skeleton.parents,
            motion.frame_time,
            stiffness=config.springs.stiffness,
            link_stiffness=config.springs.link_stiffness,
            damping=config.springs.damping,
            blend=config.springs.blend,
            active=active,
        )
        timings["springs"] = time.perf_counter() - start

    start = time.perf_counter()
    sub_rot, sub_pos = recover_orientations(sub_pos, hierarchy, motion, world_rot, world)
    if config.output.skeleton == "original":
        keep = hierarchy.original
        out_pos, out_rot = sub_pos[:, keep], sub_rot[:, keep]
        out = motion_from_world(out_pos, out_rot, skeleton.with_full_channels(), motion.frame_time,
                                motion.euler_hint)
        original_index = np.arange(skeleton.num_joints)
    else:
        out_pos, out_rot = sub_pos, sub_rot
        out = motion_from_world(out_pos, out_rot, hierarchy.skeleton, motion.frame_time)
        original_index = hierarchy.original
    timings["orient"] = time.perf_counter() - start

    return PipelineResult(
        out, out_pos, out_rot, original_index, hierarchy if config.subjoints.enabled else None,
        rest, dropped, timings, report, stretch, substeps, notes, stretch_result,
    )


def _overlaps(spec: StretchSpec, others: list[StretchSpec], frame_time: float, frames: int) -> bool:
    first, last = spec.span(frame_time, frames)
    for other in others:
        if other.limb == spec.limb:
            a, b = other.span(frame_time, frames)
            if first <= b and a <= last:
                return True
    return False


def _specs_for_paths(paths: dict | None, specs: list[StretchSpec], frame_time: float, frames: int) -> list[StretchSpec]:
    """Events (scale 1, no release) for edited paths that no stretch already covers."""
    extra = []
    for limb, (edit_frames, _) in (paths or {}).items():
        covered = any(s.limb == limb for s in specs)
        if not covered and len(edit_frames) >= 2:
            extra.append(StretchSpec(limb=limb, start=int(min(edit_frames)), end=int(max(edit_frames)), scale=1.0,
                                     release=0))
    return extra


def _max_link_stretch(positions: np.ndarray, parents: np.ndarray, lengths: np.ndarray) -> float:
    """Largest ratio of current to rest length over links longer than 1e-9 of the longest."""
    long_links = lengths > 1e-9 * max(lengths.max(), 1e-12)
    long_links[0] = False
    if not long_links.any():
        return 1.0
    current = np.linalg.norm(positions[:, long_links] - positions[:, parents[long_links]], axis=-1)
    return float((current / lengths[long_links]).max())


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


def file_digest(data: bytes) -> str:
    return "sha256:" + hashlib.sha256(data).hexdigest()


def manifest(
    *,
    input_name: str,
    input_bytes: bytes,
    config: PipelineConfig,
    preset: str | None,
    result: PipelineResult,
    outputs: dict[str, str],
    read_seconds: float,
    write_seconds: float,
    reader_warnings: list[str],
    frames_in: int,
    fps: float,
) -> dict[str, Any]:
    """The JSON manifest that records how an output was made.

    Timings are the only part that varies between identical runs; they are
    kept apart under ``timings`` so a comparison can ignore them.
    """
    info: dict[str, Any] = {
        "tool": "mocap_exaggerate",
        "version": __version__,
        "input": {"file": input_name, "hash": file_digest(input_bytes), "frames": frames_in, "fps": fps},
        "preset": preset,
        "config": config.to_dict(),
        "stages": [s for s in STAGES if s in result.timings and (s != "subjoints" or config.subjoints.enabled)],
        "rest_frames": {"count": result.rest_frames, "dropped": result.rest_frames_dropped},
        "outputs": outputs,
        "result": {
            "frames": result.motion.num_frames,
            "joints": result.motion.skeleton.num_joints,
            "max_link_stretch": round(result.max_link_stretch, 6),
            "skeleton": config.output.skeleton,
        },
        "warnings": list(reader_warnings) + list(result.notes),
        "timings": {"read": read_seconds, **result.timings, "write": write_seconds},
    }
    if result.hierarchy is not None:
        names = result.hierarchy.skeleton.names
        info["result"]["subjoints"] = result.hierarchy.skeleton.num_joints
        info["result"]["groups"] = [[names[result.hierarchy.original[j]] for j in chain] for chain in result.hierarchy.groups]
    if result.substeps:
        info["result"]["spring_substeps"] = result.substeps
    if result.stretch is not None:
        info["result"]["stretch"] = result.stretch.events
    if result.correct_report is not None:
        info["result"]["correct"] = {
            k: (round(v, 6) if isinstance(v, float) else v) for k, v in asdict(result.correct_report).items()
        }
    return info


def output_thickness(result: PipelineResult) -> np.ndarray | None:
    """World scale ``(F, J_out)`` per output joint for volume preservation, or None without a stretch pass.

    A joint's bone runs to its child: a sub-joint takes the stretch of the link
    it lies on, an original joint the largest stretch among its outgoing links;
    thickness is ``1 / sqrt(stretch)``.
    """
    if result.stretch is None:
        return None
    factors = result.stretch.stretch_factors  # (F, J): the link ending at each original joint
    skeleton = result.motion.skeleton
    hierarchy = result.hierarchy
    parents = _original_parents(result)
    outgoing = np.ones_like(factors)
    for child in range(1, factors.shape[1]):
        outgoing[:, parents[child]] = np.maximum(outgoing[:, parents[child]], factors[:, child])
    if hierarchy is not None and skeleton is hierarchy.skeleton:
        between = hierarchy.fraction < 1.0
        stretch = np.where(between[None, :], factors[:, hierarchy.link_child], outgoing[:, hierarchy.link_child])
    else:
        stretch = outgoing
    return 1.0 / np.sqrt(np.maximum(stretch, 1e-6))


def _original_parents(result: PipelineResult) -> np.ndarray:
    hierarchy = result.hierarchy
    if hierarchy is not None:
        parents = np.full(len(hierarchy.original), -1)
        originals = hierarchy.is_original
        parents[hierarchy.link_child[originals]] = hierarchy.link_parent[originals]
        return parents
    return np.asarray(result.motion.skeleton.parents)


def make_glb(motion: Motion, result: PipelineResult, skin=None, units: str = "auto",
             influences: int = 4) -> tuple[bytes, bytes, str]:
    """The skinned GLB of a run, its skin as ``.npz`` bytes, and how the units were decided.

    skin : a `Skin` bound to ``motion``'s joints in its rest pose, or None for
        the default body grown from the skeleton; either is re-weighted onto
        the sub-joints when the output skeleton is the rubber one.
    """
    from .io.gltf import format_glb, unit_scale
    from .io.skin import npz_bytes
    from .stages.body import default_skin
    from .stages.reweight import reweight

    hierarchy = result.hierarchy
    skeleton = motion.skeleton
    if skin is None:
        skin = default_skin(skeleton, hierarchy.rigid if hierarchy is not None else None)
    elif skin.bind:
        # A skin with its own bind pose must have been bound in the clip's rest pose.
        rest = skeleton.rest_positions()
        off = [np.linalg.norm(np.asarray(p) - rest[skeleton.index(n)]) for n, p in skin.bind.items()
               if n in skeleton.names]
        if not off or max(off) > 1e-3 * skeleton.height():
            raise ConfigError("the skin's bind pose is not the clip's rest pose (joints up to "
                              f"{max(off, default=float('nan')):.3g} units away); bind it in the BVH's rest pose")
    if influences not in (4, 8):
        raise ConfigError(f"influences must be 4 or 8, got {influences!r}")
    if hierarchy is not None and result.motion.skeleton is hierarchy.skeleton:
        skin = reweight(skin, skeleton, hierarchy, max_influences=influences)
    elif skin.joints.shape[1] > influences:
        from .io.skin import top_influences

        rows = np.repeat(np.arange(skin.num_vertices), skin.joints.shape[1])
        joints, weights = top_influences(rows, skin.joints.ravel(), skin.weights.ravel(), skin.num_vertices, influences)
        skin = type(skin)(skin.vertices, skin.faces, skin.joint_names, joints, weights, skin.bind)
    scale, how = unit_scale(units, skeleton.height())
    glb = format_glb(result.motion, skin, meters_per_unit=scale, thickness=output_thickness(result))
    weights = npz_bytes(joint_names=np.array(skin.joint_names), joints=skin.joints, weights=skin.weights,
                        vertices=skin.vertices, faces=skin.faces)
    return glb, weights, how
