"""The whole job for one clip: read, check every target, run, write the output set.

`convert` is what the ``exaggerate`` command runs, and what a batch worker
or a farm task calls: it takes a path, bytes or a stream, writes
``<name>.bvh``, ``.glb``, ``.weights.npz``, ``.pipeline.toml`` and the
``.json`` manifest into a folder (or the BVH alone to a stream), and returns
a `JobRecord`. Every target is checked before anything runs, and the files
are written as one set, manifest last: a refusal or a failure writes nothing.
The ``.pipeline.toml`` is the whole declaration as used, the GLB's options,
character and joint map included (`recorded_config`): read with ``--config``
from any folder, it rebuilds the same bytes.

Example::

    from mocap_exaggerate import convert, load_preset
    record = convert("walk.bvh", "out/", load_preset("looney"))
    record.outputs["bvh"]      # Path('out/walk.bvh')
"""

from __future__ import annotations

import json
import os
import re
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from ..analysis.limbs import find_limbs
from ..analysis.tpose import detect_rest_frames
from ..config import DEFAULT_PRESET, GlbConfig, PipelineConfig, load_preset
from ..core.errors import ConfigError, InputError
from ..core.motion import Motion
from ..io.bvh import iter_bvh, read_bvh, read_source
from ..io.files import (
    OutputExistsError,
    OutputSet,
    digest_of,
    digest_of_file,
    not_a_folder,
    remove_stale_temporaries,
    same_file,
    write_all,
)
from ..pipeline import PipelineResult, run
from ..rig.skinning import Skin

__all__ = ["JobRecord", "Character", "convert", "output_paths", "check_name", "check_targets", "check_output_set",
           "describe", "parameters_digest", "recorded_config"]

#: Longest output name accepted: leaves room for suffixes and temporary names within 255 bytes.
MAX_NAME = 200

Source = str | os.PathLike | bytes | BinaryIO


@dataclass
class JobRecord:
    """What one `convert` call did.

    input : the input as named in messages
    outputs : kind (``bvh``, ``glb``, ``weights``, ``usd``, ``fbx``, ``pipeline``, ``trails``, ``manifest``) -> path written
    frames, joints : of the output motion
    max_link_stretch : largest link length over its rest length, after the stretch pass
    seconds : wall time of the whole job
    timings : seconds per step (read, each stage, write, glb), as in the manifest
    warnings : what the reader noticed in the input (extra lines, a frame rate overridden), and a
        skin or joint map whose bytes are not the ones the config recorded (``glb.skin_sha256``)
    notes : what the pipeline did that the user should hear about (rest frames, stretches found)
    manifest : the manifest as written (None when the BVH went to a stream)
    result : the pipeline's result (positions, hierarchy, figures)
    captured : the input motion as read (what the pictures of a report compare against); its read Euler
        angles (``euler_hint``) only where the output is the original skeleton, the one output that uses them
    """

    input: str
    outputs: dict[str, Path]
    frames: int
    joints: int
    max_link_stretch: float
    seconds: float
    timings: dict[str, float] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    manifest: dict[str, Any] | None = None
    result: PipelineResult | None = None
    captured: Motion | None = None


def check_name(name: str) -> str:
    """``name`` if it is a plain file name for the outputs; ConfigError saying why not otherwise."""
    if not isinstance(name, str) or not name.strip():
        raise ConfigError("output name is empty")
    if "/" in name or "\\" in name or os.sep in name or (os.altsep and os.altsep in name):
        raise ConfigError(f"output name {name!r} must be a file name, without folders")
    if name in (".", "..") or name.startswith("."):
        raise ConfigError(f"output name {name!r} must not start with a dot")
    if "\x00" in name or any(ord(c) < 32 for c in name):
        raise ConfigError(f"output name {name!r} has control characters")
    size = len(os.fsencode(name))
    if size > MAX_NAME:
        raise ConfigError(f"output name is {size} bytes long; at most {MAX_NAME}")
    return name


def output_paths(folder: str | os.PathLike, name: str, *, glb: bool = True,
                 trails: str | os.PathLike | None = None, usd: str = "", fbx: bool = False) -> dict[str, Path]:
    """The files a job writes, by kind, in the order they are written (manifest last).

    usd : with ``glb``, the suffix of the UsdSkel file written beside the GLB (empty: none)
    fbx : with ``glb``, an FBX of the GLB's character too
    """
    folder = Path(folder)
    name = check_name(name)
    paths = {"bvh": folder / f"{name}.bvh"}
    if glb:
        paths["glb"] = folder / f"{name}.glb"
        paths["weights"] = folder / f"{name}.weights.npz"
        if usd:
            paths["usd"] = folder / f"{name}.{usd}"
        if fbx:
            paths["fbx"] = folder / f"{name}.fbx"
    paths["pipeline"] = folder / f"{name}.pipeline.toml"
    if trails is not None:
        paths["trails"] = Path(trails)
    paths["manifest"] = folder / f"{name}.json"
    return paths


def _default_name(source: Source) -> str:
    """The output stem when none is given: the input file's, else ``clip`` (bytes) or ``stdin`` (a stream)."""
    if isinstance(source, (bytes, bytearray)):
        return "clip"
    if hasattr(source, "read") or str(source) == "-":
        return "stdin"
    return Path(source).stem


def parameters_digest(config: PipelineConfig, *, preset: str | None = None, glb: bool = True, units: str = "auto",
                      influences: int = 4, skin: Skin | str | os.PathLike | None = None,
                      path_file: str | os.PathLike | None = None, joint_map: dict | str | os.PathLike | None = None) -> str:
    """``sha256:<hex>`` of everything besides the input that decides a job's output files.

    The resolved pipeline (whatever preset, file or flags it came from), the
    output options, the skin's and edited paths' bytes, the joint map, and the tool's version.
    The manifest records it as ``parameters``; ``batch --resume`` redoes a clip
    whose manifest names other parameters. The config's ``[glb]`` block counts as the
    options given here (what the job used): where the skin file is does not matter, its content does.
    """
    def skin_content(value) -> str | None:  # what the skin is, whichever file (or object) it came from
        if value is None:
            return None
        if not isinstance(value, Skin):
            from ..io.skin import load_skin

            value = load_skin(value)
        arrays = [np.ascontiguousarray(a).tobytes() for a in (value.vertices, value.faces, value.joints, value.weights)]
        said = [list(value.joint_names), {k: np.asarray(v).tolist() for k, v in sorted(value.bind.items())}]
        if value.pose:  # (a skin bound in a pose of its own: only then, so other digests stay what they were)
            said.append({k: list(v) for k, v in sorted(value.pose.items())})
        return digest_of(arrays + [json.dumps(said).encode("utf-8")])

    from .. import __version__

    pipeline = {block: table for block, table in config.to_dict().items() if block != "glb"}
    fields = {"version": __version__, "preset": preset, "config": pipeline, "glb": bool(glb),
              "units": units, "influences": int(influences), "skin": skin_content(skin),
              "path_file": digest_of_file(path_file) if path_file is not None else None}
    if glb and config.glb.usd:  # only when asked for: digests of runs without one stay what they were
        fields["usd"] = config.glb.usd
    if glb and config.glb.fbx:
        fields["fbx"] = True
    if joint_map is not None:  # only when given: digests of runs without one stay what they were
        from ..rig.binding import read_joint_map

        fields["joint_map"] = joint_map if isinstance(joint_map, dict) else read_joint_map(joint_map)
    return digest_of(json.dumps(fields, sort_keys=True, default=str).encode("utf-8"))


def shipped_preset(config: PipelineConfig) -> str | None:
    """The shipped preset ``config`` is, setting for setting; None when it is none of them (a changed one)."""
    from ..config import preset_names

    return next((name for name in preset_names() if load_preset(name) == config), None)


def check_targets(targets: dict[str, Path], inputs: list[Path], overwrite: bool) -> None:
    """Refuse, before anything runs, targets that are an input, a folder, named twice, or taken.

    Taken comes last: what ``--overwrite`` would not cure is said first.
    """
    for kind, path in targets.items():
        for given in inputs:
            if path.exists() and same_file(path, given) or path.resolve() == given.resolve():
                raise ConfigError(f"{path}: would overwrite the input {given}; choose another output folder or name")
        if path.is_dir():
            raise ConfigError(f"{path}: is a folder, so the {kind} output cannot be written there")
    names = [p.resolve() for p in targets.values()]
    if len(set(names)) != len(names):
        raise ConfigError("two outputs would be written to the same file")
    for path in targets.values():
        if path.exists() and not overwrite:
            raise OutputExistsError(path)


def convert(
    source: Source,
    output: str | os.PathLike | BinaryIO,
    config: PipelineConfig | None = None,
    *,
    preset: str | None = None,
    name: str | None = None,
    label: str | None = None,
    overwrite: bool = False,
    glb: bool | None = None,
    skin: Skin | str | os.PathLike | None = None,
    joint_map: dict[str, str] | str | os.PathLike | None = None,
    units: str | None = None,
    influences: int | None = None,
    trails: str | os.PathLike | None = None,
    path_file: str | os.PathLike | None = None,
    protect: tuple[str | os.PathLike, ...] = (),
    parameters: str | None = None,
) -> JobRecord:
    """Exaggerate one clip and write its output set.

    ``glb``, ``skin``, ``joint_map``, ``units`` and ``influences`` left out (None) are the
    config's ``[glb]`` block's; given, they win over it. The pipeline file written records
    what was used (`recorded_config`): file paths relative to the output folder, with their
    SHA-256 (a `Skin` or a joint map given as a dict cannot be named there: a note says so).
    A skin or joint map taken from the config whose bytes are not the ones it recorded is
    used, with a warning.

    Parameters
    ----------
    source : a BVH path, its bytes, or a binary stream
    output : a folder (created if needed), or a binary stream that gets the BVH alone
    config : the resolved pipeline (default: the ``preset``, else the default preset)
    preset : recorded in the manifest; also the config when ``config`` is None
    name : output file stem (default: the input's stem; ``stdin`` for a stream)
    label : how to call the input in messages (default: its path)
    overwrite : replace outputs that exist (an input is never replaced)
    glb : also write the skinned GLB and the re-weighted skin
    skin : a `Skin` or a skin file for the GLB (default: a body grown from the skeleton); one made
        for another rig is bound to the clip (`mocap_exaggerate.rig.binding`)
    joint_map : clip joint -> skin joint pairs for that binding (or a joint map file), for joints
        the automatic pairing misses
    units, influences : the GLB's units (``auto``, ``cm``, ...) and joints per vertex (4 or 8)
    trails : also write every stretch's end-effector paths to this JSON file
    path_file : a trails file with edited paths for the limbs to follow
    protect : more files that must never be written over (the pipeline file the config came from)
    parameters : `parameters_digest` of these settings, when the caller has it already (a batch)

    Returns
    -------
    JobRecord

    Raises
    ------
    InputError, ConfigError
        for a bad input file or setting, before anything is written
    OutputExistsError
        when a target exists and ``overwrite`` is false
    OSError
        when writing fails; nothing of the set is left behind then
    """
    started = time.perf_counter()
    if config is None:
        preset = preset or DEFAULT_PRESET
        config = load_preset(preset)
    elif preset is None:  # a shipped preset as it is (``load_preset("looney")``) is recorded as that preset
        preset = shipped_preset(config)
    to_stream = hasattr(output, "write")
    glb = (config.glb.enabled if glb is None else glb) and not to_stream
    usd = config.glb.usd if glb else ""
    fbx = config.glb.fbx and glb
    for key, asked in (("usd", config.glb.usd), ("fbx", config.glb.fbx)):
        if asked and not glb and not to_stream:
            raise ConfigError(f"glb.{key}: the {key.upper()} file is the GLB's character; it is written with the GLB "
                              "(drop --no-glb)")
    # One line naming what to install, before anything is read or written.
    if usd:
        from ..io.usd import require_usd

        require_usd()
    blender = None
    if fbx:
        from ..io.fbx import require_blender

        blender = require_blender()
    from ..io.gltf_motion import is_gltf

    gltf_input = is_gltf(source)
    # A game character: its own mesh and weights are the skin, in its own metres. Neither is a
    # choice the pipeline file records (reused on a BVH, it would bind that file's body and read
    # centimetres as metres): the same input makes the same choice again.
    own_body = gltf_input and glb and skin is None and not config.glb.skin
    if own_body:
        skin = Path(source)
    data, label = read_source(source, label)
    default = _default_name(source)
    if gltf_input and config.input.clip:  # one file, many clips: each its own outputs
        default += "_" + re.sub(r"[^A-Za-z0-9_.-]+", "_", config.input.clip)[:80]
    try:
        stem = check_name(name if name is not None else default)
    except ConfigError as error:
        if name is not None:
            raise
        raise ConfigError(f"{label}: {error} (named after the input; give another with --name)") from None
    if to_stream:
        targets = {"trails": Path(trails)} if trails is not None else {}
    else:
        folder = Path(output)
        refused = not_a_folder(folder)
        if refused:
            raise ConfigError(refused)
        targets = output_paths(folder, stem, glb=glb, trails=trails, usd=usd, fbx=fbx)
    # Outputs of an earlier run with the GLB (or a USD file) that this run will not write: they would
    # sit beside a manifest that does not list them. Refused like any output, removed with overwrite.
    from ..config import USD_FORMATS

    retired = [] if to_stream else [Path(output) / f"{stem}.{suffix}" for suffix in USD_FORMATS if suffix != usd]
    if not fbx and not to_stream:
        retired.append(Path(output) / f"{stem}.fbx")
    if not glb and not to_stream:
        retired += [Path(output) / f"{stem}.glb", Path(output) / f"{stem}.weights.npz"]
    retired = [path for path in retired if path.exists()]
    # Every option first (a bad unit, skin or path file is the first thing said), then the outputs.
    from ..io.trails import read_trails

    paths = read_trails(path_file) if path_file is not None else None
    character = Character.of(config.glb, glb=glb, skin=skin, joint_map=joint_map, units=units, influences=influences)
    inputs = [Path(p) for p in (source, path_file, character.skin_file, character.map_file, *protect)
              if isinstance(p, (str, os.PathLike)) and str(p) != "-"]
    recorded = None if to_stream else recorded_config(
        config, Path(output), glb=glb, units=character.units, influences=character.influences,
        skin=None if own_body else character.skin_file, joint_map=character.map_file)
    glb_units = "m" if gltf_input and character.units == "auto" else character.units
    changed = [] if recorded is None else _changed_since_recorded(config.glb, recorded.glb, character.skin_file,
                                                                  character.map_file)
    check_targets({**targets, **{f"old {p.suffix}": p for p in retired}}, inputs, overwrite)
    if parameters is None and not to_stream:
        parameters = parameters_digest(config, preset=preset, glb=glb, units=character.units,
                                       influences=character.influences, skin=character.skin, path_file=path_file,
                                       joint_map=character.joint_map)

    timings: dict[str, float] = {}
    motion, report = read_clip(source, config.input, name=label, data=data)
    if config.output.skeleton != "original":  # (only the original skeleton's channels are written near the read
        motion = motion.replace(euler_hint=None)  # angles: elsewhere they are 24 bytes a joint a frame for nothing)
    timings["read"] = time.perf_counter() - started
    warnings = list(report.warnings) + changed
    if not glb and not to_stream and (skin is not None or config.glb.skin):
        warnings.append("the character (--skin) is not used: no GLB is written (--no-glb)")
    if glb:
        from ..io.units import guessed_units_warning

        unlikely = guessed_units_warning(glb_units, motion.skeleton.height())
        warnings += [unlikely] if unlikely else []
    skin, binding = character.bound_to(motion, label) if glb else (None, None)  # a skin that will not bind costs nothing
    warnings += binding_warnings(binding)  # (said only in the manifest, the robot's legs hung still)
    input_hash = digest_of(data)
    del data  # the input's bytes are not needed past this point; a long clip's are tens of MB, at the pipeline's peak
    result = run(motion, config, paths=paths)
    warnings += result.warnings
    timings.update(result.timings)
    for target in targets.values():
        remove_stale_temporaries(target, keep=inputs)  # what a killed earlier run of these outputs left
    info = None
    outputs: dict[str, Any] = {}
    # (The pool inside the set: its thread is done before the set is committed, and before it is aborted
    # but for a second Ctrl-C while it finishes, when the set's files are removed under it.)
    with OutputSet(overwrite=True) as written, ThreadPoolExecutor(max_workers=1) as pool:
        # The GLB is built and written while the BVH is formatted and written: both spend most of
        # their time in NumPy, C and the file system, which let go of the GIL, so two cores share the work.
        if glb:
            from .outputs import glb_files

            slots = {kind: written.reserve(targets[kind]) for kind in ("glb", "weights", "usd")
                     if kind != "usd" or usd}
            building = pool.submit(_built_and_written, slots, glb_files, motion, result, skin, glb_units,
                                   character.influences, None, usd)
        else:
            building = None
        tick = time.perf_counter()
        if to_stream:
            for piece in iter_bvh(result.motion, positions=config.output.bvh_positions):
                write_all(output, piece)
            if hasattr(output, "flush"):
                output.flush()
        else:
            outputs["bvh"] = written.add(targets["bvh"], iter_bvh(result.motion, positions=config.output.bvh_positions))
        timings["write"] = time.perf_counter() - tick
        if building is not None:
            files, timings["glb"], digests = building.result()
            units_used = files.units
            outputs.update(digests)
            if fbx:
                from ..io.fbx import glb_to_fbx

                tick = time.perf_counter()
                outputs["fbx"] = written.add(targets["fbx"], glb_to_fbx(b"".join(files.glb), fps=motion.fps,
                                                                         command=blender))
                timings["fbx"] = time.perf_counter() - tick
            del files
        if not to_stream:
            outputs["pipeline"] = written.add(targets["pipeline"], recorded.to_toml(preset=preset).encode("utf-8"))
        if trails is not None:
            from ..io.trails import format_trails

            outputs["trails"] = written.add(targets["trails"], format_trails(
                result.stretch.trails if result.stretch else [], source=label, fps=motion.fps))
        if not to_stream:
            from .outputs import manifest

            listed: dict[str, Any] = {kind: targets[kind].name for kind in outputs}
            if "trails" in outputs:
                listed["trails"] = str(targets["trails"])
            if building is not None:
                listed["units"] = units_used
            listed["hashes"] = outputs.copy()
            timings["total"] = time.perf_counter() - started
            info = manifest(input_name=label, input_hash=input_hash, config=recorded, preset=preset, result=result,
                            outputs=listed, reader_warnings=warnings, frames_in=motion.num_frames,
                            fps=motion.fps, timings=timings)
            info["parameters"] = parameters
            if binding is not None:
                info["skin_binding"] = binding.summary()
            written.add(targets["manifest"], (json.dumps(info, indent=2) + "\n").encode("utf-8"))
        # The BVH last before the manifest: a run killed between renames leaves its other files beside a
        # new BVH, which tells it from a clip (`discovery.foreign_clips`), or the old BVH as it was.
        written.commit(retire_first=[targets["manifest"], *retired] if "manifest" in targets else [],
                       late=[targets["bvh"]] if "bvh" in outputs else [])
    return JobRecord(
        input=label,
        outputs={kind: path for kind, path in targets.items() if kind in outputs or kind == "manifest"},
        frames=result.motion.num_frames,
        joints=result.motion.skeleton.num_joints,
        max_link_stretch=result.max_link_stretch,
        seconds=time.perf_counter() - started,
        timings=timings,
        warnings=warnings,
        notes=list(result.notes) + character.unnamed(to_stream),
        manifest=info,
        result=result,
        captured=motion,
    )


@dataclass(frozen=True)
class Character:
    """What a job's GLB (or a preview's body) is made with: the ``[glb]`` block, with the arguments given over it, checked
    and read (the skin parsed, the joint map read) before anything else of the job runs.

    skin_file, map_file : the files they came from, None for a `Skin` or pairs given as objects
    """

    glb: bool
    units: str
    influences: int
    skin: Skin | None
    joint_map: dict[str, str] | None
    skin_file: Path | None
    map_file: Path | None
    skin_label: str

    @classmethod
    def of(cls, settings: GlbConfig, *, glb: bool, skin, joint_map, units, influences) -> Character:
        from ..io.skin import check_skin, load_skin

        units = settings.units if units is None else units
        influences = settings.influences if influences is None else influences
        skin = settings.skin or None if skin is None else skin
        joint_map = settings.joint_map or None if joint_map is None else joint_map
        skin_file, map_file = (Path(p) if isinstance(p, (str, os.PathLike)) else None for p in (skin, joint_map))
        if glb:
            from ..io.units import unit_scale

            unit_scale(units, 1.0)  # a bad unit is refused before anything runs
            if influences not in (4, 8):
                raise ConfigError(f"influences must be 4 or 8, got {influences!r}")
        if map_file is not None:
            from ..rig.binding import read_joint_map

            joint_map = read_joint_map(map_file)
        if skin is None and joint_map:
            raise ConfigError("a joint map pairs the clip's joints with a skin's: give the skin too (--skin)")
        label = str(skin_file) if skin_file is not None else "skin"
        if skin is not None:
            skin = load_skin(skin_file) if skin_file is not None else check_skin(skin, "skin")
        return cls(glb, units, influences, skin, joint_map, skin_file, map_file, label)

    def bound_to(self, motion: Motion, clip_label: str):
        """The skin bound to the clip's skeleton and its `Binding` (None, None for the default body)."""
        if self.skin is None:
            return None, None
        from ..rig.binding import bind_skin_to_clip

        return bind_skin_to_clip(self.skin, motion.skeleton, self.joint_map, skin_label=self.skin_label,
                                 clip_label=clip_label)

    def unnamed(self, to_stream: bool) -> list[str]:
        """Notes for what the pipeline file cannot name: a skin or joint map given as objects."""
        return _unnamed(self.skin, self.skin_file, self.joint_map, self.map_file, to_stream)


def binding_warnings(binding) -> list[str]:
    """What a user must hear of how a character was bound (`mocap_exaggerate.rig.binding.Binding`, or None):
    the clip's main parts no joint of the character pairs with."""
    if binding is None or not binding.unpaired_roles:
        return []
    return [f"skin: no joint of the character pairs with the clip's {', '.join(binding.unpaired_roles)}: those parts "
            "of it move with the nearest joint paired, not as the clip does; name the pairs in a --joint-map file "
            "('clip joint = skin joint' a line)"]


def recorded_config(config: PipelineConfig, folder: str | os.PathLike, *, glb: bool, units: str, influences: int,
                    skin: str | os.PathLike | None = None, joint_map: str | os.PathLike | None = None) -> PipelineConfig:
    """``config`` with its ``[glb]`` block as a job in ``folder`` used it: what ``<name>.pipeline.toml`` holds.

    The skin and joint map files are named relative to ``folder`` (where the pipeline file
    is written, so it works from any working folder and when the folders move together;
    absolute when on another drive), each with its SHA-256. Without a skin file the joint
    map is not named either (it pairs with a skin the file cannot name).
    """
    folder = Path(folder)
    skin_path, skin_sha = _named(skin, folder)
    map_path, map_sha = _named(joint_map, folder) if skin_path else ("", "")
    return replace(config, glb=GlbConfig(enabled=bool(glb), units=units, influences=int(influences),
                                         usd=config.glb.usd if glb else "", fbx=config.glb.fbx and bool(glb),
                                         skin=skin_path,
                                         skin_sha256=skin_sha, joint_map=map_path, joint_map_sha256=map_sha))


def _named(path: str | os.PathLike | None, folder: Path) -> tuple[str, str]:
    """A file as a pipeline file in ``folder`` names it, and its SHA-256 (hex); empty strings for None."""
    if path is None:
        return "", ""
    target = Path(path).resolve()
    try:
        shown = Path(os.path.relpath(target, folder.resolve())).as_posix()
    except ValueError:  # another drive: no relative path leads there
        shown = target.as_posix()
    from ..io.skin import known_digest

    try:
        return shown, (known_digest(target) or digest_of_file(target)).removeprefix("sha256:")
    except OSError as error:
        raise InputError(f"cannot read ({error.strerror or error})", source=str(target)) from None


def _changed_since_recorded(settings: GlbConfig, now: GlbConfig, skin: Path | None,
                            joint_map: Path | None) -> list[str]:
    """Warnings for the config's skin and joint map files whose bytes (``now``) are not the ones it recorded.

    Only where the file used is the one the config names: a skin given instead is another file,
    and its recorded hash says nothing about it.
    """
    warnings = []
    for key, used, named, recorded, actual in (
            ("skin", skin, settings.skin, settings.skin_sha256, now.skin_sha256),
            ("joint_map", joint_map, settings.joint_map, settings.joint_map_sha256, now.joint_map_sha256)):
        if not recorded or not actual or used is None or used.resolve() != Path(named).resolve():
            continue
        if actual != recorded:
            warnings.append(f"glb.{key} {used} is not the file the pipeline file recorded (SHA-256 {actual[:12]}..., "
                            f"recorded {recorded[:12]}...): the GLB and weights may differ from the ones it made")
    return warnings


def _unnamed(skin, skin_file, joint_map, map_file, to_stream: bool) -> list[str]:
    """Notes for a skin or joint map the pipeline file cannot name (given as objects, not files)."""
    if to_stream:
        return []
    notes = []
    if skin is not None and skin_file is None:
        notes.append("the skin was given as a Skin, not a file: the pipeline file names no skin (glb.skin)")
    if joint_map and map_file is None:
        notes.append("the joint map was given as pairs, not a file: the pipeline file names none (glb.joint_map)")
    return notes


def check_output_set(manifest: str | os.PathLike, info: dict | None = None) -> list[str]:
    """What is wrong with the output set a manifest describes: an empty list when it is complete.

    Complete means: the manifest reads, and every file it lists is there with
    the hash it recorded. A run writes its manifest last and deletes the old
    one before replacing anything, so a set interrupted at any point reads as
    incomplete here, never as a complete set of mixed runs.
    info : the manifest's data, when the caller has read it
    """
    manifest = Path(manifest)
    try:
        if info is None:
            from ..io.files import LIMITS, read_limited

            info = json.loads(read_limited(manifest, limit=LIMITS["text"], what="manifest").decode("utf-8"))
        hashes = dict(info["outputs"]["hashes"])
        names = {kind: str(info["outputs"][kind]) for kind in hashes}
    except FileNotFoundError:
        return [f"{manifest}: no manifest"]
    except (OSError, ValueError, KeyError, TypeError, AttributeError, RecursionError) as error:
        return [f"{manifest}: not a readable manifest ({type(error).__name__})"]
    problems = []
    for kind, digest in hashes.items():
        if kind == "trails":  # a side file wherever the user put it, named as they gave it
            continue
        path = manifest.parent / Path(names[kind]).name
        try:
            actual = digest_of_file(path)
        except OSError:
            problems.append(f"{path}: missing")
            continue
        if actual != digest:
            problems.append(f"{path}: not the file the manifest recorded")
    return problems


def read_clip(source: Source, settings, *, name: str | None = None, data: bytes | None = None):
    """A clip as a `Motion` and its reader's report: a ``.glb``/``.gltf`` by one of its animations
    (`mocap_exaggerate.io.gltf_motion`), anything else as BVH (``data``: its bytes, already read).

    settings : the pipeline's `InputConfig` (``fps``, ``clip``; ``root_offset`` and ``up`` for BVH)
    """
    from ..io.gltf_motion import is_gltf, read_gltf_motion

    if is_gltf(source):
        return read_gltf_motion(source, fps=settings.fps, clip=settings.clip, name=name)
    if settings.clip:
        raise ConfigError(f"input.clip (--clip) names one of a .glb/.gltf's animations; {name or source} is a "
                          "BVH, which holds one clip")
    return read_bvh(source if data is None else data, name=name, fps=settings.fps,
                    root_offset=settings.root_offset, up=settings.up)


def _timed(func, *args):
    tick = time.perf_counter()
    return func(*args), time.perf_counter() - tick


def _built_and_written(slots: dict, build, *args) -> tuple[Any, float, dict[str, str]]:
    """The character's files built by ``build(*args)`` (`glb_files`), the seconds that took, and the
    digests of the files written into ``slots`` (kind -> `OutputSet.reserve`'s writer), in the GLB,
    weights, USD order of the manifest."""
    files, seconds = _timed(build, *args)
    digests = {"glb": slots["glb"](files.glb), "weights": slots["weights"](files.weights)}
    if "usd" in slots:
        digests["usd"] = slots["usd"](files.usd)
    return files, seconds, digests


def describe(source: Source, *, fps: float | None = None, limbs: bool = False, groups: bool = False,
             contacts: bool = False, label: str | None = None, root_offset: str = "auto",
             up: str = "auto", clip: str = "") -> dict[str, Any]:
    """What ``info`` shows about a clip, as plain data (JSON-ready); a glTF's animations too."""
    from ..analysis.loops import find_loop
    from ..config import InputConfig
    from ..io.gltf_motion import gltf_animations, is_gltf

    motion, report = read_clip(source, InputConfig(fps=fps, root_offset=root_offset, up=up, clip=clip), name=label)
    skeleton = motion.skeleton
    rotations, positions = motion.forward_kinematics()
    orders: dict[str, int] = {}
    for j in range(skeleton.num_joints):
        if skeleton.channels[j]:
            orders[skeleton.rotation_order(j)] = orders.get(skeleton.rotation_order(j), 0) + 1
    data: dict[str, Any] = {
        "file": report.source,
        "joints": skeleton.num_joints,
        "root": skeleton.names[0],
        "end_sites": int(np.isfinite(skeleton.end_sites[:, 0]).sum()),
        "channels": skeleton.num_channels,
        "position_channel_joints": [skeleton.names[j] for j in range(skeleton.num_joints)
                                    if skeleton.has_position_channels(j)],
        "rotation_orders": orders,
        "frames": motion.num_frames,
        "fps": round(motion.fps, 6),
        "duration_s": round(motion.duration, 6),
        "up_axis": "XYZ"[skeleton.up_axis()],
        "root_offset": report.root_offset,
        "height": round(skeleton.height(), 4),
        "rest_frames": detect_rest_frames(motion, positions),
        "warnings": report.warnings,
    }
    loop = None if data["rest_frames"] else find_loop(motion, positions, rotations)
    data["loop"] = None if loop is None else {"period": loop.period, "closed": loop.closed}
    if is_gltf(source):
        data["clip"] = report.clip
        data["animations"] = gltf_animations(source)
    if limbs:
        data["limbs"] = {name: [skeleton.names[j] for j in limb.joints] for name, limb in find_limbs(skeleton).items()}
    if contacts:
        data["contacts"] = clip_contacts(motion)
    if groups:
        from ..stages.subjoints import build_hierarchy, link_starts

        hierarchy = build_hierarchy(skeleton)
        data["groups"] = [[skeleton.names[j] for j in chain] for chain in hierarchy.groups]
        data["rigid"] = [skeleton.names[j] for j in np.flatnonzero(hierarchy.rigid)]
        # The joints the default output writes: each cut link's start is a joint of its own there
        # (the rubber hierarchy alone, 79 on a 31-joint clip, was said where the BVH has 95).
        data["subjoints"] = link_starts(hierarchy).skeleton.num_joints
    return data


def clip_contacts(motion, config=None) -> dict[str, Any]:
    """Where a captured clip touches the ground, as the constraints stage finds it (JSON-ready).

    ``{"floor": {...}, "contacts": {joint: [[start, end], ...]}}`` with frames counted
    in the file (leading rest-pose frames are not searched).
    """
    from ..analysis.branches import minor_branches, rubber_groups
    from ..stages.contacts import ContactConfig, find_contacts, find_effectors

    config = config or ContactConfig()
    skeleton = motion.skeleton
    world = motion.world_positions()
    first = detect_rest_frames(motion, world)
    found = find_limbs(skeleton)
    rigid = minor_branches(skeleton)
    effectors = find_effectors(skeleton, found, rigid, rubber_groups(skeleton, rigid))
    ground, runs = find_contacts(skeleton, world[first:], motion.frame_time, found, effectors, config)
    return {
        "floor": {"axis": "XYZ"[ground.axis], "up": "+" if ground.sign > 0 else "-",
                  "height": round(ground.sign * ground.floor, 6)},
        "contacts": {skeleton.names[j]: (r + first).tolist() for j, r in runs.items()},
    }
