"""The declaration of a pipeline: every block's settings, presets, and TOML.

A pipeline is the ordered list of blocks that are switched on. Its whole
declaration is a `PipelineConfig`, which round-trips through TOML; the same
declaration and input give the same output, byte for byte: the BVH, and with
its ``[glb]`` block the GLB and the skin weights too. Precedence when
resolving one: shipped preset < config file < explicit overrides.
"""

from __future__ import annotations

import copy
import logging
import os
import re
import tomllib
from dataclasses import dataclass, field, fields
from importlib import resources
from typing import Any

from .analysis.loops import LOOP_MODES
from .core.errors import ConfigError, InputError, check_choice, check_flag, check_number
from .core.settings import Flag, setting
from .io.bvh import BVH_POSITIONS, FPS_RANGE, ROOT_OFFSET_MODES, UP_AXES, check_bvh_positions
from .stages.contacts import ContactConfig, TargetSpec, parse_target
from .stages.correct import CorrectConfig
from .stages.extrapolate import ExtrapolateConfig
from .stages.springs import SpringConfig
from .stages.stretch import AutoStretchConfig, StretchSpec, parse_stretch
from .stages.subjoints import SubjointConfig

__all__ = [
    "InputConfig",
    "OutputConfig",
    "GlbConfig",
    "GLB_UNITS",
    "PipelineConfig",
    "DEFAULT_PRESET",
    "preset_names",
    "load_preset",
    "preset_description",
    "resolve_config",
    "read_config_text",
    "config_preset",
    "merge_tables",
]

DEFAULT_PRESET = "cartoon"
_TPOSE_MODES = ("auto", "keep", "drop")
_SKELETON_MODES = ("sub", "original")


log = logging.getLogger(__name__)

#: Settings an earlier version wrote into every pipeline file, and why they are gone: such a file still
#: reads (with a warning), rather than being refused for a key it was written with.
RETIRED = {
    ("auto_stretch", key): "strikes are found by their shape now, not by how fast they go (min_reach, min_rise, "
                           "min_angle, min_leg_angle, window)"
    for key in ("min_rate", "min_speed", "min_extension")
}


@dataclass(frozen=True, kw_only=True)
class InputConfig:
    """How the clip is read.

    tpose : ``auto`` detects a synthetic leading rest pose, keeps it out of
        every filter and writes it back unchanged; ``keep`` treats it as
        motion; ``drop`` removes it from the output.
    fps : frame rate overriding the header's ``Frame Time`` (None keeps it).
    root_offset : position channels ``replace`` the OFFSET (most exporters), ``add``
        to it (Reallusion/iClone, MakeHuman), or ``auto``: told apart per clip.
    up : the axis the body stands along, ``x``, ``y``, ``z``, or ``auto`` (from the rest pose).
    clip : with a glTF/GLB input, the animation to take, by name ("": the first; ``info`` lists them)
    loop : ``auto`` runs a clip whose last frame repeats its first (a game's cycle) as that loop
        repeated, so the output loops too; ``on`` takes any clip as a loop (its last frame leading
        into its first where it does not repeat it); ``off`` takes every clip as a clip
        (`mocap_exaggerate.analysis.loops`)
    """

    tpose: str = setting("auto", flag=Flag(
        "--tpose", "Leading synthetic rest pose: auto (keep out of filters, unchanged), keep, drop.",
        choices=_TPOSE_MODES))
    fps: float | None = setting(None, flag=Flag("--fps", "Frame rate overriding the file's Frame Time."))
    root_offset: str = setting("auto", flag=Flag(
        "--root-offset", "Position channels replace the joint's OFFSET (most exporters) or add to it "
        "(Reallusion/iClone, MakeHuman); auto tells them apart. Default auto.", choices=ROOT_OFFSET_MODES))
    up: str = setting("auto", flag=Flag(
        "--up", "The axis the body stands along; auto: from the rest pose. Default auto.", choices=UP_AXES))
    clip: str = setting("", flag=Flag(
        "--clip", "With a .glb/.gltf input: the animation to take, by name (default: the first; info lists them).",
        metavar="NAME"))
    loop: str = setting("auto", flag=Flag(
        "--loop", "A looping cycle: auto (a clip whose last frame repeats its first is run as the loop repeated, "
        "so the output loops too), on (any clip is a loop), off. Default auto.", choices=LOOP_MODES))

    def __post_init__(self) -> None:
        check_choice("input.tpose", self.tpose, _TPOSE_MODES)
        check_choice("input.loop", self.loop, LOOP_MODES)
        if self.fps is not None:
            check_number("input.fps", self.fps, *FPS_RANGE)
        check_choice("input.root_offset", self.root_offset, ROOT_OFFSET_MODES)
        check_choice("input.up", self.up, UP_AXES)
        if not isinstance(self.clip, str) or len(self.clip) > 1000 or "\x00" in self.clip:
            raise ConfigError(f"input.clip must be an animation's name, got {self.clip!r:.60}")


@dataclass(frozen=True, kw_only=True)
class OutputConfig:
    """What is written.

    skeleton : ``sub`` writes the rubber sub-joint hierarchy; ``original``
        the original joints only (6 channels each), for pipelines that need
        the original joint set.
    bvh_positions : ``standard`` writes the BVH's position channels as each joint's
        translation, replacing its OFFSET (what Blender, bvhio and MotionBuilder
        read), whatever the input used; ``input`` writes them in the input's own
        convention (added to the OFFSETs for an iClone or MakeHuman clip), for
        re-import into iClone.
    preserve_volume : the GLB keeps a stretched bone's volume: each joint is scaled by
        ``1 / sqrt(stretch)`` of its bone, so the skin around a link stretched 2x is
        0.71x as thick and around one squashed to half 1.41x
        (`mocap_exaggerate.jobs.outputs.output_thickness`); off keeps every bone its own thickness.
    """

    skeleton: str = setting("sub", flag=Flag(
        "--skeleton", "Write the rubber sub-joint skeleton (sub) or the original joints only (original).",
        choices=_SKELETON_MODES))
    bvh_positions: str = setting("standard", flag=Flag(
        "--bvh-positions", "BVH position channels: standard (each joint's translation, replacing its OFFSET: what "
        "Blender, bvhio and MotionBuilder read) or input (the input's own convention: added to the OFFSETs for "
        "iClone and MakeHuman clips, for re-import into iClone). Default standard.", choices=BVH_POSITIONS))
    preserve_volume: bool = setting(True, flag=Flag(
        "--preserve-volume/--no-preserve-volume", "GLB: a stretched bone gets thinner and a squashed one fatter, "
        "keeping its volume (1/sqrt of the stretch). Default on."))

    def __post_init__(self) -> None:
        check_choice("output.skeleton", self.skeleton, _SKELETON_MODES)
        check_bvh_positions(self.bvh_positions, "output.bvh_positions")
        check_flag("output.preserve_volume", self.preserve_volume)


#: ``glb.units``: ``auto`` or metres per unit by name (the same names as `mocap_exaggerate.io.gltf.UNITS`,
#: which this light module does not import).
GLB_UNITS = ("auto", "m", "dm", "cm", "mm", "in", "ft", "cmu")
#: The UsdSkel files ``glb.usd`` may ask for, by suffix (`mocap_exaggerate.io.usd.USD_FORMATS`).
USD_FORMATS = ("usd", "usda", "usdc")
_INFLUENCES = (4, 8)
#: The ``[glb]`` keys that name a file, each with the key of its SHA-256.
GLB_FILES = (("skin", "skin_sha256"), ("joint_map", "joint_map_sha256"))


@dataclass(frozen=True, kw_only=True)
class GlbConfig:
    """The skinned GLB and the re-weighted skin written beside the BVH.

    enabled : write ``<name>.glb`` and ``<name>.weights.npz`` (false: the BVH alone, ``--no-glb``)
    units : what one BVH unit is, for the GLB's metres: ``auto`` (centimetres for skeletons over
        50 units tall, metres under 3, else scaled to a 1.7 m figure), ``m``, ``dm``, ``cm``, ``mm``,
        ``in``, ``ft`` or ``cmu`` (CMU's 1/0.45 inch)
    influences : joints per vertex, 4 (JOINTS_0) or 8 (a second JOINTS_1/WEIGHTS_1 set)
    usd : also write the same character as a UsdSkel, ``<name>.usd``, ``.usdc`` (binary) or
        ``.usda`` (text): the word is the suffix; empty for none (`mocap_exaggerate.io.usd`;
        needs the ``usd`` extra, Pixar's usd-core)
    fbx : also write the same character as ``<name>.fbx``, by Blender (`mocap_exaggerate.io.fbx`)
    skin : the character file (a skinned ``.glb``/``.gltf``, a MakeHuman ``.obj``, an ``.npz``);
        empty for the rubber body grown from the skeleton. A relative path is relative to the
        folder of the pipeline file that holds it (a run writes it so)
    skin_sha256 : the SHA-256 of the skin file's bytes when the run was made (hex); a rebuild
        from a skin with other bytes warns that the GLB may differ. Empty: not checked
    joint_map : a file of ``clip joint = skin joint`` lines for the pairs the automatic pairing
        misses (with ``skin``); relative as ``skin``
    joint_map_sha256 : the joint map file's SHA-256, checked as ``skin_sha256``
    """

    enabled: bool = setting(True, flag=Flag(
        "--glb/--no-glb", "Also write OUT/<name>.glb (skinned, animated) and OUT/<name>.weights.npz. [default: glb]"))
    units: str = setting("auto", flag=Flag(
        "--units", f"BVH units for the GLB (metres): {', '.join(GLB_UNITS)}. [default: auto]", metavar="UNITS"))
    influences: int = setting(4, flag=Flag(
        "--influences", "Joints per vertex in the GLB: 4 (JOINTS_0) or 8 (a second JOINTS_1/WEIGHTS_1 set). "
        "[default: 4]", choices={str(n): n for n in _INFLUENCES}))
    usd: str = setting("", flag=Flag(
        "--usd", "Also write OUT/<name>.FORMAT: the same character as a skinned, animated UsdSkel, usd or usdc "
        "(binary) or usda (text). Needs the usd extra: pip install 'mocap-exaggerate[usd]'.", metavar="FORMAT",
        choices=USD_FORMATS))
    fbx: bool = setting(False, flag=Flag(
        "--fbx", "Also write OUT/<name>.fbx: the GLB's character exported by Blender (Y up, no leaf bones, every "
        "frame baked). Needs Blender: pip install 'mocap-exaggerate[fbx]', MOCAP_BPY_PYTHON or blender on PATH.",
        sets=True))
    skin: str = setting("", flag=Flag(
        "--skin", "Your character: a skinned .glb/.gltf, a MakeHuman .obj (+ .mhw, .mhskel beside it) or an .npz "
        "bound to the clip's joints. Made for another rig, it is fitted to the clip (joints paired by role and "
        "name). Default: a rubber body grown from the skeleton.", path=True))
    skin_sha256: str = ""
    joint_map: str = setting("", flag=Flag(
        "--joint-map", "With --skin: a text file of 'clip joint = skin joint' lines, for joints the automatic "
        "pairing misses or gets wrong.", path=True))
    joint_map_sha256: str = ""

    def __post_init__(self) -> None:
        check_flag("glb.enabled", self.enabled)
        check_flag("glb.fbx", self.fbx)
        check_choice("glb.units", self.units, GLB_UNITS)
        if not isinstance(self.usd, str) or self.usd not in ("", *USD_FORMATS):
            raise ConfigError(f"glb.usd must be one of {', '.join(USD_FORMATS)} (or empty for none), got {self.usd!r:.40}")
        if isinstance(self.influences, bool) or not isinstance(self.influences, int) or self.influences not in _INFLUENCES:
            raise ConfigError(f"glb.influences must be 4 or 8, got {self.influences!r:.60}")
        for key, digest_key in GLB_FILES:
            path, digest = getattr(self, key), getattr(self, digest_key)
            if not isinstance(path, str) or "\x00" in path or len(path) > 4096:
                raise ConfigError(f"glb.{key} must be a file's path (or empty), got {path!r:.60}")
            if not isinstance(digest, str) or digest and not re.fullmatch(r"[0-9a-f]{64}", digest):
                raise ConfigError(f"glb.{digest_key} must be 64 hex digits (or empty), got {digest!r:.80}")
            if digest and not path:
                raise ConfigError(f"glb.{digest_key} is given without glb.{key}")
        if self.joint_map and not self.skin:
            raise ConfigError("glb.joint_map pairs the clip's joints with a skin's: give the skin too (--skin, glb.skin)")


_BLOCKS = {
    "input": InputConfig,
    "extrapolate": ExtrapolateConfig,
    "correct": CorrectConfig,
    "auto_stretch": AutoStretchConfig,
    "subjoints": SubjointConfig,
    "springs": SpringConfig,
    "contacts": ContactConfig,
    "output": OutputConfig,
    "glb": GlbConfig,
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
    glb: GlbConfig = field(default_factory=GlbConfig)
    auto_stretch: AutoStretchConfig = field(default_factory=AutoStretchConfig)
    contacts: ContactConfig = field(default_factory=ContactConfig)
    stretch: tuple[StretchSpec, ...] = setting((), flag=Flag(
        "--stretch", "Squash/stretch a limb along its path: LIMB:START-END:SCALE[:axes=xz][:pivot=end]"
        "[:ease_in=0.6,0.2][:ease_out=0.3,0.8][:blend=1][:release=0.1s]; frames or 1.2s. "
        "Repeatable; adds to the config's [[stretch]] list.", metavar="SPEC", parse=parse_stretch, multiple=True,
        adds=True))
    target: tuple[TargetSpec, ...] = setting((), flag=Flag(
        "--target", "Hold an end effector (a joint, or a limb: right_arm) where it was captured at FRAME (or at "
        "X,Y,Z), eased in and out over 0.25 s. Frames or 1.2s. Repeatable.", metavar="JOINT@FRAME[=X,Y,Z]",
        parse=parse_target, multiple=True, adds=True))
    limbs: tuple[tuple[str, tuple[str, ...]], ...] = ()
    description: str = ""

    @classmethod
    def from_dict(cls, data: dict[str, Any], *, source: str = "config") -> PipelineConfig:
        """Build and validate from nested tables; unknown keys are errors naming the key."""
        if not isinstance(data, dict):
            raise ConfigError(f"{source}: expected a table of blocks")
        blocks: dict[str, Any] = {}
        retired: list[tuple[str, str]] = []
        for key, value in data.items():
            if key == "preset":  # where the settings started: the base a file's blocks are laid over
                _check_preset_key(value, source)
                continue
            if key == "description":
                if not isinstance(value, str):
                    raise ConfigError(f"{source}: description must be text")
                blocks["description"] = value
                continue
            if key == "stretch":
                blocks["stretch"] = _tables_from_list(value, source, "stretch", StretchSpec, {"limb", "start", "end", "scale"})
                continue
            if key == "limbs":
                blocks["limbs"] = _limbs_from_table(value, source)
                continue
            if key == "target":
                blocks["target"] = _tables_from_list(value, source, "target", TargetSpec, {"joint", "frame"})
                continue
            if key not in _BLOCKS:
                known = ", ".join(list(_BLOCKS) + ["limbs", "[stretch]", "[target]"])
                raise ConfigError(f"{source}: unknown block [{key}] (known: {known})")
            if not isinstance(value, dict):
                raise ConfigError(f"{source}: [{key}] must be a table")
            block_type = _BLOCKS[key]
            known = {f.name for f in fields(block_type)}
            retired += [(key, name) for name in value if (key, name) in RETIRED]
            value = {n: v for n, v in value.items() if (key, n) not in RETIRED}
            for name in value:
                if name not in known:
                    raise ConfigError(f"{source}: unknown key {key}.{name} (known: {', '.join(sorted(known))})")
            values = _values_from_toml(block_type, key, value, source)
            try:
                blocks[key] = block_type(**values)
            except ConfigError as error:
                raise ConfigError(f"{source}: {error}") from None
            except TypeError as error:
                raise ConfigError(f"{source}: [{key}]: {error}") from None
        try:
            config = cls(**blocks)
        except ConfigError as error:
            raise ConfigError(f"{source}: {error}") from None
        for key, name in retired:  # (said once the file is known to be good: a refused one gets one line)
            log.warning("%s: %s.%s is retired and ignored: %s", source, key, name, RETIRED[key, name])
        return config

    def to_dict(self) -> dict[str, Any]:
        """Nested plain tables (TOML-ready: None values are left out)."""
        out: dict[str, Any] = {}
        if self.description:
            out["description"] = self.description
        for name in _BLOCKS:
            out[name] = _values_to_toml(getattr(self, name))
        if self.limbs:
            out["limbs"] = {name: list(chain) for name, chain in self.limbs}
        if self.stretch:
            out["stretch"] = [spec.to_dict() for spec in self.stretch]
        if self.target:
            out["target"] = [spec.to_dict() for spec in self.target]
        return out

    @classmethod
    def from_toml(cls, text: str, *, source: str = "config", folder: str | os.PathLike | None = None) -> PipelineConfig:
        """The declaration in ``text``; relative file paths in it (``glb.skin``, ``glb.joint_map``)
        taken from ``folder`` when given (the folder of the file the text came from)."""
        table = _parse_toml(text, source)
        return cls.from_dict(_paths_from(table, folder) if folder is not None else table, source=source)

    def to_toml(self, *, preset: str | None = None) -> str:
        """The declaration as TOML text; `from_toml` of it gives an equal config.

        preset : the shipped preset it was resolved from, written first as ``preset = "..."``
            (read back as the base its blocks are laid over; the blocks hold every setting)
        """
        import tomli_w

        table = self.to_dict()
        return tomli_w.dumps({"preset": preset, **table} if preset else table)


def _values_to_toml(block: Any) -> dict[str, Any]:
    """A block's settings as TOML values: tuples as arrays, a `setting` declared as a table
    (``extrapolate.weights``) as one, None left out."""
    out = {}
    for item in fields(block):
        value = getattr(block, item.name)
        if value is None:
            continue
        if item.metadata.get("table"):
            value = {str(name): float(number) for name, number in value}
        out[item.name] = _lists(value)
    return out


def _lists(value: Any) -> Any:
    return [_lists(v) for v in value] if isinstance(value, (tuple, list)) else value


def _values_from_toml(block_type: type, key: str, table: dict[str, Any], source: str) -> dict[str, Any]:
    """A block's TOML values as its fields take them, by each field's declared type: a table
    for a `setting` declared as one, a list where the type is a tuple, a whole number where
    it is an int (TOML's ``2.0`` too)."""
    import typing

    hints = typing.get_type_hints(block_type)
    declared = {item.name: item for item in fields(block_type)}
    values = {}
    for name, value in table.items():
        hint = hints[name]
        if declared[name].metadata.get("table"):
            value = _pairs_from_table(value, source, f"{key}.{name}")
        elif typing.get_origin(hint) is tuple and not isinstance(value, (list, tuple)):
            raise ConfigError(f"{source}: {key}.{name} must be a list")
        elif hint is int and isinstance(value, float) and value.is_integer():
            value = int(value)
        values[name] = value
    return values


def _parse_toml(text: str, source: str) -> dict[str, Any]:
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ConfigError(f"{source}: not valid TOML: {error}") from None
    except RecursionError:
        raise ConfigError(f"{source}: not valid TOML: nested too deeply") from None
    except ValueError as error:  # an integer of more than 4,300 digits (Python's own limit)
        raise ConfigError(f"{source}: not a pipeline file: {_short_error(error)}") from None


def _short_error(error: Exception) -> str:
    """An error's message, cut to its first sentence (Python's own for a long integer runs on)."""
    text = str(error).split(";")[0].split(": value has")[0]
    return text if len(text) <= 120 else text[:120] + "..."


def read_config_text(path: str | os.PathLike) -> str:
    """The text of a pipeline file; ConfigError naming the file when it cannot be read as UTF-8 text."""
    from .io.files import LIMITS, read_limited

    try:
        data = read_limited(path, limit=LIMITS["text"], what="config file")
    except InputError as error:
        raise ConfigError(str(error)) from None
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such config file") from None
    except IsADirectoryError:
        raise ConfigError(f"{path}: is a folder, not a config file") from None
    except PermissionError:
        raise ConfigError(f"{path}: permission denied") from None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise ConfigError(f"{path}: not UTF-8 text (byte {error.start} is 0x{data[error.start]:02x})") from None


def _check_preset_key(value: Any, source: str) -> str:
    if not isinstance(value, str) or value not in preset_names():
        raise ConfigError(f"{source}: preset must name a shipped preset ({', '.join(preset_names())}), got {value!r:.60}")
    return value


def _paths_from(table: dict[str, Any], folder: str | os.PathLike) -> dict[str, Any]:
    """``table`` with its relative ``[glb]`` file paths joined to ``folder`` (a copy; absolute and empty ones kept)."""
    glb = table.get("glb")
    if not isinstance(glb, dict):
        return table
    glb = dict(glb)
    for key, _ in GLB_FILES:
        path = glb.get(key)
        if isinstance(path, str) and path and "\x00" not in path and not os.path.isabs(path):
            glb[key] = os.path.join(folder, path)
    return {**table, "glb": glb}


def config_preset(text: str, *, source: str = "config") -> str | None:
    """The preset a pipeline file names (``preset = "looney"``, as a run writes it), or None."""
    value = _parse_toml(text, source).get("preset")
    return None if value is None else _check_preset_key(value, source)


def _tables_from_list(items: Any, source: str, key: str, spec: type, required: set[str]) -> tuple:
    """``[[key]]`` tables as ``spec`` instances; TOML arrays become tuples."""
    if not isinstance(items, (list, tuple)):
        raise ConfigError(f"{source}: {key} must be a list of tables ([[{key}]])")
    specs = []
    known = {f.name for f in fields(spec)}
    for number, item in enumerate(items, start=1):
        if not isinstance(item, dict):
            raise ConfigError(f"{source}: {key} #{number} must be a table")
        unknown = set(item) - known
        if unknown:
            raise ConfigError(f"{source}: {key} #{number}: unknown key {sorted(unknown)[0]} (known: {', '.join(sorted(known))})")
        missing = required - set(item)
        if missing:
            raise ConfigError(f"{source}: {key} #{number}: missing {', '.join(sorted(missing))}")
        values = {name: tuple(value) if isinstance(value, list) else value for name, value in item.items()}
        try:
            specs.append(spec(**values))
        except ConfigError as error:
            raise ConfigError(f"{source}: {key} #{number}: {error}") from None
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


def _pairs_from_table(table: Any, source: str, key: str) -> tuple[tuple[str, float], ...]:
    """``name = number`` pairs from a TOML table (or a list of pairs: ``--weight`` gives one)."""
    if isinstance(table, dict):
        items = list(table.items())
    elif isinstance(table, (list, tuple)) and all(isinstance(i, (list, tuple)) and len(i) == 2 for i in table):
        items = [tuple(item) for item in table]
    else:
        raise ConfigError(f"{source}: {key} must be a table of name = weight")
    out = []
    for pattern, weight in items:
        if isinstance(weight, bool) or not isinstance(weight, (int, float)):
            raise ConfigError(f"{source}: {key}[{pattern!r}] must be a number, got {weight!r}")
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


def merge_tables(base: dict[str, Any], top: dict[str, Any]) -> dict[str, Any]:
    """``top`` over ``base``, table by table (copies; neither is changed)."""
    out = copy.deepcopy(base)
    for key, value in top.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = merge_tables(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def _laid_over(base: dict[str, Any], top: dict[str, Any]) -> dict[str, Any]:
    """``top`` merged over ``base``; a file ``top`` names (the skin) forgets the SHA-256 ``base``
    recorded for another, unless ``top`` gives one too: a hash belongs to the path beside it."""
    out = merge_tables(base, top)
    named = top.get("glb") if isinstance(top.get("glb"), dict) else {}
    for key, digest_key in GLB_FILES:
        if key in named and digest_key not in named and isinstance(out.get("glb"), dict):
            out["glb"][digest_key] = ""
    return out


def resolve_config(
    preset: str | None = DEFAULT_PRESET,
    config_text: str | None = None,
    overrides: dict[str, Any] | None = None,
    *,
    config_source: str = "config",
    config_folder: str | os.PathLike | None = None,
) -> PipelineConfig:
    """Shipped preset < config file < explicit overrides (nested tables), validated.

    config_folder : the folder of the config file: relative file paths in it (``glb.skin``,
        ``glb.joint_map``) are relative to it, so a written pipeline file works from any
        working folder; None leaves them relative to the working folder (as overrides are)
    """
    table: dict[str, Any] = _preset_table(preset) if preset is not None else {}
    if config_text is not None:
        file_table = _parse_toml(config_text, config_source)
        if config_folder is not None:
            file_table = _paths_from(file_table, config_folder)
        PipelineConfig.from_dict(file_table, source=config_source)  # name the file in its own errors (and warnings)
        file_table = {key: {n: v for n, v in value.items() if (key, n) not in RETIRED} if isinstance(value, dict)
                      else value for key, value in file_table.items()}
        table = _laid_over(table, file_table)
    if overrides:
        table = _laid_over(table, overrides)
    table.pop("preset", None)
    return PipelineConfig.from_dict(table, source=config_source if config_text is not None else "options")
