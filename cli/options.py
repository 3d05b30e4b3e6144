"""The options shared by the commands, how they are read, and the settings they make.

One set of option decorators is reused by ``exaggerate``, ``batch``, ``plan`` and
``preview``; `FLAG_KEYS` says which setting of the pipeline file each option sets, for
the options and for the settings reference (`mocap_exaggerate_cli.reference`). Each value
is checked in its callback or by the config, before any file is looked at.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from mocap_exaggerate.config import (
    DEFAULT_PRESET,
    config_preset,
    merge_tables,
    preset_names,
    read_config_text,
    resolve_config,
)
from mocap_exaggerate.jobs.discovery import DEFAULT_GLOB
from mocap_exaggerate.stages.contacts import parse_target
from mocap_exaggerate.stages.stretch import parse_stretch

from .app import shown

__all__ = ["FLAG_KEYS", "FilePath", "pipeline_options", "output_options", "folder_arguments", "config_from_options",
           "given_options", "joint_map_of", "parsed_each", "parse_weights", "parse_settings"]


class FilePath(click.Path):
    """click's Path, refusing an empty value (which would name the current folder)."""

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        if isinstance(value, str) and not value.strip():
            self.fail("is empty", param, ctx)
        return super().convert(value, param, ctx)


def _keep_raw(ctx, param, values: tuple[str, ...]) -> None:
    """Remember an option's words as given ('plan' writes them back)."""
    ctx.meta.setdefault("mocap_exaggerate.raw", {})[param.name] = list(values)


def parsed_each(parse: Callable[[str], Any]) -> Callable:
    """A callback for a repeatable option: every value through ``parse``, a MocapError as click's BadParameter."""
    from mocap_exaggerate.core.errors import MocapError

    def callback(ctx, param, values: tuple[str, ...]):
        _keep_raw(ctx, param, values)
        try:
            return tuple(parse(v) for v in values)
        except MocapError as error:
            raise click.BadParameter(str(error)) from None

    return callback


def parse_weights(ctx, param, values: tuple[str, ...]) -> tuple[tuple[str, float], ...]:
    """``--weight NAME=W`` pairs, each weight a number from 0 to 10."""
    _keep_raw(ctx, param, values)
    out = []
    for item in values:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise click.BadParameter(f"{shown(item)} is not NAME=WEIGHT (e.g. LeftArm=2, left_leg=0.5, 'Left*'=0)")
        try:
            weight = float(value)
        except ValueError:
            raise click.BadParameter(f"{shown(item)}: weight {shown(value)} is not a number") from None
        if not math.isfinite(weight) or not 0 <= weight <= 10:
            raise click.BadParameter(f"{shown(item)}: weight must be between 0 and 10")
        out.append((key.strip(), weight))
    return tuple(out)


def parse_settings(ctx, param, values: tuple[str, ...]) -> dict[str, Any]:
    """``--set block.key=value`` pairs as a nested table; the config checks the keys and values."""
    import tomllib

    _keep_raw(ctx, param, values)
    table: dict[str, Any] = {}
    for item in values:
        key, sep, text = item.partition("=")
        path = [part.strip() for part in key.split(".")]
        if not sep or len(path) < 2 or not all(re.fullmatch(r"[A-Za-z_][\w*?\[\]-]*", part) for part in path):
            raise click.BadParameter(f"{shown(item)} is not KEY=VALUE with a dotted key (e.g. springs.blend=0.3)")
        if len(text) > 1000:  # also keeps TOML's numbers under Python's 4,300-digit limit
            raise click.BadParameter(f"{shown(item)}: the value is {len(text)} characters; a setting is short")
        if "\n" in text or "\r" in text:  # TOML would read the second line as another key, unasked
            raise click.BadParameter(f"{shown(item)}: the value holds a line break; a setting is one line")
        try:
            value = tomllib.loads(f"v = {text.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            value = text.strip()  # plain text: 0.2s, looney
        except RecursionError:
            raise click.BadParameter(f"{shown(item)}: the value is nested too deeply") from None
        node = table
        for part in path[:-1]:
            if not isinstance(node.setdefault(part, {}), dict):
                raise click.BadParameter(f"{shown(item)}: {part} is set to a value and to a table")
            node = node[part]
        node[path[-1]] = value
    return table


def folder_argument(ctx, param, value: str) -> Path:
    """A folder argument as given: an empty one is a mistake, not the current folder."""
    if not value.strip():
        raise click.BadParameter("is empty (say . for the current folder)")
    return Path(value)


def _length_value(value: str | None) -> float | str | None:
    """A --sublink-length value: a number of skeleton units, or a share such as '3%'."""
    if value is None or value.strip().endswith("%"):
        return value
    try:
        return float(value)
    except ValueError:
        return value  # the config names it in its error


def _text(value: Any) -> str | None:
    return None if value is None else str(value)


# ---------------------------------------------------------------------------- shared options


def pipeline_options(func: Callable) -> Callable:
    """The options that set the pipeline, shared by every command that runs it."""
    options = [
        click.option("--preset", default=None, metavar="NAME",
                     help=f"Starting point: {', '.join(preset_names())} (default: the one the --config file names, "
                          f"else {DEFAULT_PRESET})."),
        click.option("--config", "config_file", type=FilePath(dir_okay=False, path_type=Path), default=None,
                     help="Pipeline TOML file (a run's OUT/<name>.pipeline.toml rebuilds that run, from any "
                          "folder); overrides the preset, overridden by flags."),
        click.option("--sigma", default=None, metavar="DURATION",
                     help="Width of the Gaussian average: 0.2s, 200ms or 18f (frames)."),
        click.option("--omega", type=float, default=None,
                     help="Extrapolation factor: 1 = as captured, 5 = the paper's, <1 calms."),
        click.option("--weight", "weights", multiple=True, callback=parse_weights, metavar="NAME=W",
                     help="Per-joint exaggeration weight; NAME is a joint, a pattern (Left*) or a limb "
                          "(left_arm, right_leg, spine, neck). Repeatable; 0 keeps it as captured."),
        click.option("--extrapolate/--no-extrapolate", "extrapolate_on", default=None,
                     help="Switch trajectory extrapolation on or off."),
        click.option("--threshold", type=float, default=None,
                     help="Correction: summed stretch allowed per frame, as a fraction of total link length."),
        click.option("--delta", type=float, default=None, help="Correction: share of excess removed per iteration, (0, 1]."),
        click.option("--max-stretch", type=float, default=None,
                     help="Correction: stretch up to this factor of a link's length is free."),
        click.option("--max-iter", type=int, default=None, help="Correction: iteration bound."),
        click.option("--correct/--no-correct", "correct_on", default=None, help="Switch link correction on or off."),
        click.option("--subjoints", "per_link", type=int, default=None, metavar="M",
                     help="Cut every link into M rubber sub-links (default from the preset, 4 in cartoon)."),
        click.option("--sublink-length", default=None, metavar="LEN",
                     help="Instead of M: target sub-link length, in skeleton units or as '3%' of the height."),
        click.option("--no-subjoints", "subjoints_off", is_flag=True, default=False,
                     help="Switch the rubber sub-joint hierarchy (Bézier groups) off."),
        click.option("--stiffness", type=float, default=None,
                     help="Follow-through spring to the motion, 1/s^2: (2 pi f)^2 wobbles at f Hz (158 = 2 Hz)."),
        click.option("--link-stiffness", type=float, default=None, help="Springs between neighbouring sub-joints, 1/s^2."),
        click.option("--damping", type=float, default=None, help="Drag on the follow-through, 1/s; higher settles sooner."),
        click.option("--blend", type=float, default=None,
                     help="Share of the simulated follow-through in the result, 0 (none) to 1."),
        click.option("--springs/--no-springs", "springs_on", default=None, help="Switch the follow-through on or off."),
        click.option("--skeleton", "skeleton_mode", type=click.Choice(["sub", "original"]), default=None,
                     help="Write the rubber sub-joint skeleton (sub) or the original joints only (original)."),
        click.option("--bvh-positions", "bvh_positions", type=click.Choice(["standard", "input"]), default=None,
                     help="BVH position channels: standard (each joint's translation, replacing its OFFSET: what "
                          "Blender, bvhio and MotionBuilder read) or input (the input's own convention: added to "
                          "the OFFSETs for iClone and MakeHuman clips, for re-import into iClone). Default standard."),
        click.option("--preserve-volume/--no-preserve-volume", "preserve_volume", default=None,
                     help="GLB: a stretched bone gets thinner and a squashed one fatter, keeping its volume "
                          "(1/sqrt of the stretch). Default on."),
        click.option("--stretch", "stretches", multiple=True, callback=parsed_each(parse_stretch), metavar="SPEC",
                     help="Squash/stretch a limb along its path: LIMB:START-END:SCALE[:axes=xz][:pivot=end]"
                          "[:ease_in=0.6,0.2][:ease_out=0.3,0.8][:blend=1][:release=0.1s]; frames or 1.2s. "
                          "Repeatable; adds to the config's [[stretch]] list."),
        click.option("--auto-stretch/--no-auto-stretch", "auto_stretch_on", default=None,
                     help="Find strikes (punches, kicks, throws, leaps) and stretch them by the style's scale."),
        click.option("--contacts", "contacts_mode", type=click.Choice(["auto", "off"]), default=None,
                     help="Feet (or the joints in [contacts]) that touch the ground in the capture stay planted "
                          "there, and no joint goes below the captured floor (auto); off leaves them as exaggerated."),
        click.option("--anchor", type=click.Choice(["captured", "exaggerated"]), default=None,
                     help="Where a planted foot stays: where it was captured, or where the exaggeration put it "
                          "when it landed (keeps the bigger stride)."),
        click.option("--floor/--no-floor", "floor_on", default=None,
                     help="Keep every joint above the captured floor (with --contacts auto)."),
        click.option("--target", "targets", multiple=True, callback=parsed_each(parse_target), metavar="JOINT@FRAME[=X,Y,Z]",
                     help="Hold an end effector (a joint, or a limb: right_arm) where it was captured at FRAME "
                          "(or at X,Y,Z), eased in and out over 0.25 s. Frames or 1.2s. Repeatable."),
        click.option("--tpose", type=click.Choice(["auto", "keep", "drop"]), default=None,
                     help="Leading synthetic rest pose: auto (keep out of filters, unchanged), keep, drop."),
        click.option("--fps", type=float, default=None, help="Frame rate overriding the file's Frame Time."),
        click.option("--root-offset", "root_offset", type=click.Choice(["auto", "replace", "add"]), default=None,
                     help="Position channels replace the joint's OFFSET (most exporters) or add to it "
                          "(Reallusion/iClone, MakeHuman); auto tells them apart. Default auto."),
        click.option("--up", type=click.Choice(["auto", "x", "y", "z"]), default=None,
                     help="The axis the body stands along; auto: from the rest pose. Default auto."),
        click.option("--set", "settings", multiple=True, callback=parse_settings, metavar="KEY=VALUE",
                     help="Any setting of a pipeline file by its key, e.g. extrapolate.max_speed=2 or "
                          "springs.blend=0.3 (docs/reference/config.md lists them); the value is read as TOML, "
                          "else as text. Repeatable; the flags above win over it."),
    ]
    for option in reversed(options):
        func = option(func)
    return func


def output_options(func: Callable) -> Callable:
    """What a conversion writes besides the BVH, shared by ``exaggerate``, ``batch`` and ``plan``.

    All but ``--overwrite`` are settings of the ``[glb]`` block (`FLAG_KEYS`): not given, the
    preset's or the ``--config`` file's values hold.
    """
    options = [
        click.option("--overwrite", is_flag=True, help="Replace outputs that exist already."),
        click.option("--skin", "skin_path", type=FilePath(dir_okay=False, path_type=Path), default=None,
                     help="Your character for the GLB: a skinned .glb/.gltf, a MakeHuman .obj (+ .mhw, .mhskel "
                          "beside it) or an .npz bound to the clip's joints. Made for another rig, it is fitted to "
                          "the clip (joints paired by role and name). Default: a rubber body grown from the skeleton."),
        click.option("--joint-map", "joint_map_path", type=FilePath(dir_okay=False, path_type=Path), default=None,
                     help="With --skin: a text file of 'clip joint = skin joint' lines, for joints the automatic "
                          "pairing misses or gets wrong."),
        click.option("--units", default=None, metavar="UNITS",
                     help="BVH units for the GLB (metres): auto, m, dm, cm, mm, in, ft, cmu. [default: auto]"),
        click.option("--influences", type=click.Choice(["4", "8"]), default=None,
                     help="Joints per vertex in the GLB: 4 (JOINTS_0) or 8 (a second JOINTS_1/WEIGHTS_1 set). "
                          "[default: 4]"),
        click.option("--glb/--no-glb", "write_glb", default=None,
                     help="Also write OUT/<name>.glb (skinned, animated) and OUT/<name>.weights.npz. [default: glb]"),
    ]
    for option in reversed(options):
        func = option(func)
    return func


def folder_arguments(func: Callable) -> Callable:
    """IN_DIR, OUT_DIR and --glob, shared by ``batch`` and ``plan``."""
    func = click.option("--glob", "pattern", default=DEFAULT_GLOB, show_default=True,
                        help="Which files under IN_DIR, by their path under it (case-insensitive; ** is any "
                             "folders).")(func)
    func = click.argument("out_dir", metavar="OUT_DIR", callback=folder_argument)(func)
    return click.argument("in_dir", metavar="IN_DIR", callback=folder_argument)(func)


#: Which setting each option sets: (option's parameter name, block, key, how its value is read).
#: One table for the options and for the settings reference (cli/reference.py).
FLAG_KEYS: tuple[tuple[str, str, str, Callable[[Any], Any]], ...] = tuple(
    (name, block, key, read) for name, block, key, read in [
        ("tpose", "input", "tpose", None), ("fps", "input", "fps", None),
        ("root_offset", "input", "root_offset", None), ("up", "input", "up", None),
        ("extrapolate_on", "extrapolate", "enabled", None), ("sigma", "extrapolate", "sigma", None),
        ("omega", "extrapolate", "omega", None), ("weights", "extrapolate", "weights", lambda v: dict(v) or None),
        ("correct_on", "correct", "enabled", None), ("threshold", "correct", "threshold", None),
        ("delta", "correct", "delta", None), ("max_stretch", "correct", "max_stretch", None),
        ("max_iter", "correct", "max_iter", None),
        ("subjoints_off", "subjoints", "enabled", lambda v: False if v else None),
        ("per_link", "subjoints", "per_link", None), ("sublink_length", "subjoints", "sublink_length", _length_value),
        ("springs_on", "springs", "enabled", None), ("stiffness", "springs", "stiffness", None),
        ("link_stiffness", "springs", "link_stiffness", None), ("damping", "springs", "damping", None),
        ("blend", "springs", "blend", None),
        ("skeleton_mode", "output", "skeleton", None), ("bvh_positions", "output", "bvh_positions", None),
        ("preserve_volume", "output", "preserve_volume", None),
        ("auto_stretch_on", "auto_stretch", "enabled", None),
        ("contacts_mode", "contacts", "enabled", lambda v: None if v is None else v == "auto"),
        ("anchor", "contacts", "anchor", None), ("floor_on", "contacts", "floor", None),
        ("write_glb", "glb", "enabled", None), ("units", "glb", "units", None),
        ("influences", "glb", "influences", lambda v: None if v is None else int(v)),
        ("skin_path", "glb", "skin", _text), ("joint_map_path", "glb", "joint_map", _text),
    ]
)


def _overrides(p: dict[str, Any]) -> dict[str, Any]:
    """The settings the options given set, as nested tables: ``--set`` first, the named flags over it.

    A command without one of the options (``preview`` writes no GLB) leaves its setting alone.
    """
    flags: dict[str, dict[str, Any]] = {}
    for name, block, key, read in FLAG_KEYS:
        value = p.get(name) if read is None else read(p.get(name))
        if value is not None:
            flags.setdefault(block, {})[key] = value
    return merge_tables(p.get("settings") or {}, flags)


def config_from_options(p: dict[str, Any]):
    """The preset's name and the resolved config: preset < ``--config FILE`` < ``--set`` < the named flags.

    The preset is ``--preset``, else the one the file names (a run's pipeline file does), else
    the default. Relative file paths in the file are relative to the file's folder.
    """
    config_file = p["config_file"]
    text = read_config_text(config_file) if config_file is not None else None
    source = str(config_file) if config_file is not None else "options"
    named = config_preset(text, source=source) if text is not None else None
    preset = p["preset"] if p["preset"] is not None else named or DEFAULT_PRESET
    config = resolve_config(preset, text, _overrides(p), config_source=source,
                            config_folder=config_file.parent if config_file is not None else None)
    if p["stretches"]:
        config = dataclasses.replace(config, stretch=config.stretch + p["stretches"])
    if p["targets"]:
        config = dataclasses.replace(config, target=config.target + p["targets"])
    return preset, config


def joint_map_of(config) -> dict | None:
    """The config's joint map file read, None without one (the config pairs it with a skin)."""
    from mocap_exaggerate.rig.binding import read_joint_map

    return read_joint_map(config.glb.joint_map) if config.glb.joint_map else None


def given_options(ctx: click.Context, exclude: set[str]) -> list[str]:
    """The options given on this command line, written back as arguments (paths made absolute)."""
    from click.core import ParameterSource

    words: list[str] = []
    for param in ctx.command.params:
        if not isinstance(param, click.Option) or param.name in exclude or param.expose_value is False:
            continue
        if ctx.get_parameter_source(param.name) != ParameterSource.COMMANDLINE:
            continue
        value = ctx.params[param.name]
        if param.is_flag and param.secondary_opts:  # --x/--no-x
            words.append(param.opts[0] if value else param.secondary_opts[0])
        elif param.is_flag:
            if value:
                words.append(param.opts[0])
        else:
            # Parsed values go back as the user wrote them: raw strings for options parsed by a callback.
            raw = ctx.meta.get("mocap_exaggerate.raw", {}).get(param.name)
            values = raw if raw is not None else (value if param.multiple else [value])
            for item in values:
                if isinstance(item, Path):
                    item = item.resolve()
                words += [param.opts[-1] if param.opts[-1].startswith("--") else param.opts[0], str(item)]
    return words
