"""The ``mocap-exaggerate`` command line: parses options, calls the library, reports.

No algorithm lives here.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import logging
import math
import os
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

# Only light modules at import time: `--help` must not wait for SciPy, trimesh or pygltflib.
from mocap_exaggerate import __version__
from mocap_exaggerate.config import (
    DEFAULT_PRESET,
    merge_tables,
    preset_description,
    preset_names,
    read_config_text,
    resolve_config,
)
from mocap_exaggerate.core.errors import MocapError
from mocap_exaggerate.io.files import OutputExistsError
from mocap_exaggerate.jobs.batch import DEFAULT_GLOB
from mocap_exaggerate.stages.contacts import parse_target
from mocap_exaggerate.stages.stretch import parse_stretch

log = logging.getLogger("mocap_exaggerate")


class UserError(click.ClickException):
    """A mistake in the input or the options: one line, exit code 2."""

    exit_code = 2


def _fail_cleanly(func: Callable) -> Callable:
    """Turn library errors into one-line messages; never a traceback for a user mistake.

    Exit codes: 2 for bad input or settings (and refusals), 1 for a failed
    write or read the user did not cause by a setting.
    """

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except OutputExistsError as error:
            raise UserError(f"{error}; pass --overwrite to replace it") from None
        except MocapError as error:
            raise UserError(str(error)) from None
        except BrokenPipeError:
            raise  # the reader went away (`| head`): click exits quietly
        except OSError as error:
            where = f"{error.filename}: " if getattr(error, "filename", None) else ""
            raise click.ClickException(f"{where}{error.strerror or error}") from None

    return wrapper


def _keep_raw(ctx, param, values: tuple[str, ...]) -> None:
    """Remember an option's words as given ('plan' writes them back)."""
    ctx.meta.setdefault("mocap_exaggerate.raw", {})[param.name] = list(values)


def _parsed_each(parse: Callable[[str], Any]) -> Callable:
    """A callback for a repeatable option: every value through ``parse``, a MocapError as click's BadParameter."""
    def callback(ctx, param, values: tuple[str, ...]):
        _keep_raw(ctx, param, values)
        try:
            return tuple(parse(v) for v in values)
        except MocapError as error:
            raise click.BadParameter(str(error)) from None

    return callback


def _parse_weights(ctx, param, values: tuple[str, ...]) -> tuple[tuple[str, float], ...]:
    _keep_raw(ctx, param, values)
    out = []
    for item in values:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise click.BadParameter(f"{item!r} is not NAME=WEIGHT (e.g. LeftArm=2, left_leg=0.5, 'Left*'=0)")
        try:
            weight = float(value)
        except ValueError:
            raise click.BadParameter(f"{item!r}: weight {value!r} is not a number") from None
        if not math.isfinite(weight) or not 0 <= weight <= 10:
            raise click.BadParameter(f"{item!r}: weight must be between 0 and 10")
        out.append((key.strip(), weight))
    return tuple(out)


def _parse_settings(ctx, param, values: tuple[str, ...]) -> dict[str, Any]:
    """``--set block.key=value`` pairs as a nested table; the config checks the keys and values."""
    import tomllib

    _keep_raw(ctx, param, values)
    table: dict[str, Any] = {}
    for item in values:
        key, sep, text = item.partition("=")
        path = [part.strip() for part in key.split(".")]
        if not sep or len(path) < 2 or not all(re.fullmatch(r"[A-Za-z_][\w*?\[\]-]*", part) for part in path):
            raise click.BadParameter(f"{_shown(item)} is not KEY=VALUE with a dotted key (e.g. springs.blend=0.3)")
        if len(text) > 1000:  # also keeps TOML's numbers under Python's 4,300-digit limit
            raise click.BadParameter(f"{_shown(item)}: the value is {len(text)} characters; a setting is short")
        try:
            value = tomllib.loads(f"v = {text.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            value = text.strip()  # plain text: 0.2s, looney
        node = table
        for part in path[:-1]:
            if not isinstance(node.setdefault(part, {}), dict):
                raise click.BadParameter(f"{_shown(item)}: {part} is set to a value and to a table")
            node = node[part]
        node[path[-1]] = value
    return table


def _folder_argument(ctx, param, value: str) -> Path:
    """A folder argument as given: an empty one is a mistake, not the current folder."""
    if not value.strip():
        raise click.BadParameter("is empty (say . for the current folder)")
    return Path(value)


# ---------------------------------------------------------------------------- shared options


def pipeline_options(func: Callable) -> Callable:
    """The options that set the pipeline, shared by every command that runs it."""
    options = [
        click.option("--preset", default=None, metavar="NAME",
                     help=f"Starting point: {', '.join(preset_names())} (default {DEFAULT_PRESET})."),
        click.option("--config", "config_file", type=click.Path(dir_okay=False, path_type=Path), default=None,
                     help="Pipeline TOML file; overrides the preset, overridden by flags."),
        click.option("--sigma", default=None, metavar="DURATION",
                     help="Width of the Gaussian average: 0.2s, 200ms or 18f (frames)."),
        click.option("--omega", type=float, default=None,
                     help="Extrapolation factor: 1 = as captured, 5 = the paper's, <1 calms."),
        click.option("--weight", "weights", multiple=True, callback=_parse_weights, metavar="NAME=W",
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
        click.option("--stretch", "stretches", multiple=True, callback=_parsed_each(parse_stretch), metavar="SPEC",
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
        click.option("--target", "targets", multiple=True, callback=_parsed_each(parse_target), metavar="JOINT@FRAME[=X,Y,Z]",
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
        click.option("--set", "settings", multiple=True, callback=_parse_settings, metavar="KEY=VALUE",
                     help="Any setting of a pipeline file by its key, e.g. extrapolate.max_speed=2 or "
                          "springs.blend=0.3 (docs/reference/config.md lists them); the value is read as TOML, "
                          "else as text. Repeatable; the flags above win over it."),
    ]
    for option in reversed(options):
        func = option(func)
    return func


def output_options(func: Callable) -> Callable:
    """What a conversion writes besides the BVH, shared by ``exaggerate`` and ``batch``."""
    options = [
        click.option("--overwrite", is_flag=True, help="Replace outputs that exist already."),
        click.option("--skin", "skin_path", type=click.Path(dir_okay=False, path_type=Path), default=None,
                     help="Your character for the GLB: a skinned .glb/.gltf, a MakeHuman .obj (+ .mhw, .mhskel "
                          "beside it) or an .npz bound to the clip's joints. Made for another rig, it is fitted to "
                          "the clip (joints paired by role and name). Default: a rubber body grown from the skeleton."),
        click.option("--joint-map", "joint_map_path", type=click.Path(dir_okay=False, path_type=Path), default=None,
                     help="With --skin: a text file of 'clip joint = skin joint' lines, for joints the automatic "
                          "pairing misses or gets wrong."),
        click.option("--units", default="auto", show_default=True,
                     help="BVH units for the GLB (metres): auto, m, dm, cm, mm, in, ft, cmu."),
        click.option("--influences", type=click.Choice(["4", "8"]), default="4", show_default=True,
                     help="Joints per vertex in the GLB: 4 (JOINTS_0) or 8 (a second JOINTS_1/WEIGHTS_1 set)."),
        click.option("--glb/--no-glb", "write_glb", default=True, show_default=True,
                     help="Also write OUT/<name>.glb (skinned, animated) and OUT/<name>.weights.npz."),
    ]
    for option in reversed(options):
        func = option(func)
    return func


def _length_value(value: str | None) -> float | str | None:
    """A --sublink-length value: a number of skeleton units, or a share such as '3%'."""
    if value is None or value.strip().endswith("%"):
        return value
    try:
        return float(value)
    except ValueError:
        return value  # the config names it in its error


#: Which setting each pipeline option sets: (option's parameter name, block, key, how its value is read).
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
    ]
)


def _overrides(p: dict[str, Any]) -> dict[str, Any]:
    """The settings the options given set, as nested tables: ``--set`` first, the named flags over it."""
    flags: dict[str, dict[str, Any]] = {}
    for name, block, key, read in FLAG_KEYS:
        value = p[name] if read is None else read(p[name])
        if value is not None:
            flags.setdefault(block, {})[key] = value
    return merge_tables(p.get("settings") or {}, flags)


def _config_from_options(p: dict[str, Any]):
    text = read_config_text(p["config_file"]) if p["config_file"] is not None else None
    preset = p["preset"] or DEFAULT_PRESET
    config = resolve_config(preset, text, _overrides(p), config_source=str(p["config_file"] or "options"))
    if p["stretches"]:
        config = dataclasses.replace(config, stretch=config.stretch + p["stretches"])
    if p["targets"]:
        config = dataclasses.replace(config, target=config.target + p["targets"])
    return preset, config


def _set_verbosity(ctx: click.Context, param: click.Parameter, value: Any) -> None:
    """``-v``/``-q`` may stand before or after the subcommand; both places add up."""
    root = ctx.find_root()
    state = root.meta.setdefault("mocap_exaggerate.verbosity", {"verbose": 0, "quiet": False})
    if param.name == "verbose":
        state["verbose"] += value or 0
    elif value:
        state["quiet"] = True
    level = logging.ERROR if state["quiet"] else (logging.WARNING, logging.INFO, logging.DEBUG)[min(state["verbose"], 2)]
    logging.basicConfig(level=level, format="%(levelname)s: %(message)s", stream=sys.stderr, force=True)


def verbosity_options(func: Callable) -> Callable:
    func = click.option("-q", "--quiet", is_flag=True, expose_value=False, callback=_set_verbosity,
                        help="Only errors on stderr.")(func)
    return click.option("-v", "--verbose", count=True, expose_value=False, callback=_set_verbosity,
                        help="More detail on stderr (-vv for debugging).")(func)


def _quiet() -> bool:
    ctx = click.get_current_context(silent=True)
    return bool(ctx and ctx.find_root().meta.get("mocap_exaggerate.verbosity", {}).get("quiet"))


# ---------------------------------------------------------------------------- commands


#: Characters of a usage error's message shown before it is cut short.
_LONGEST_MESSAGE = 300


class _Commands(click.Group):
    """click's group, with usage mistakes reported in one line like every other error."""

    def main(self, *args: Any, **kwargs: Any) -> Any:
        standalone = kwargs.pop("standalone_mode", True)
        try:
            return super().main(*args, standalone_mode=False, **kwargs)
        except click.exceptions.UsageError as error:
            if not standalone:
                raise
            if type(error).__name__ == "NoArgsIsHelpError":  # bare command: the help is the answer
                error.show()
                sys.exit(error.exit_code)
            where = f" (see '{error.ctx.command_path} --help')" if error.ctx is not None else ""
            message = error.format_message().rstrip(".")
            if len(message) > _LONGEST_MESSAGE:  # click quotes a bad value whole, however long
                message = f"{message[:_LONGEST_MESSAGE]}... ({len(message)} characters)"
            click.echo(f"Error: {message}{where}", err=True)
            sys.exit(error.exit_code)
        except click.ClickException as error:
            if not standalone:
                raise
            error.show()
            sys.exit(error.exit_code)
        except click.exceptions.Abort:
            if not standalone:
                raise
            click.echo("Aborted!", err=True)
            sys.exit(1)


@click.group(cls=_Commands, context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(__version__, prog_name="mocap-exaggerate")
@verbosity_options
def cli() -> None:
    """Turn motion capture (BVH) into cartoon-style motion.

    \b
    Example:
      mocap-exaggerate exaggerate sample_data/cmu_09_01_run_daz.bvh -o out/ --sigma 0.2s --omega 5
      mocap-exaggerate info sample_data/cmu_09_01_run_daz.bvh --limbs
    """


@cli.command()
@click.argument("input_paths", metavar="IN.bvh...", nargs=-1, required=True,
                type=click.Path(path_type=Path, allow_dash=True))
@click.option("-o", "--output", "output", required=True, callback=_folder_argument,
              help="Output folder (created if needed), or - to write the BVH to stdout.")
@click.option("--name", default=None, help="Output file stem (default: the input's; 'stdin' for -).")
@output_options
@click.option("--trails", "trails_path", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Write the original and exaggerated end-effector paths of every stretch as JSON.")
@click.option("--path-file", "path_file", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Apply hand-edited paths: a --trails file whose 'exaggerated' points you moved.")
@pipeline_options
@verbosity_options
@_fail_cleanly
def exaggerate(input_paths: tuple[Path, ...], output: Path, name: str | None, overwrite: bool, skin_path: Path | None,
               units: str, influences: str, write_glb: bool, trails_path: Path | None, path_file: Path | None, **options) -> None:
    """Exaggerate clips: writes OUT/<name>.bvh, .glb, .weights.npz and .json (manifest) for each.

    With several files, a bad one is reported and the rest go on (exit 1 if any
    failed); for whole folders see 'batch'.

    \b
    Examples:
      mocap-exaggerate exaggerate walk.bvh -o out/                       # cartoon preset
      mocap-exaggerate exaggerate walk.bvh -o out/ --preset looney --weight Hips=0
      mocap-exaggerate exaggerate walk.bvh -o out/ --sigma 18f --omega 3 --no-correct
      mocap-exaggerate exaggerate walk.bvh -o out/ --subjoints 6 --blend 0.7 --stiffness 100
      mocap-exaggerate exaggerate walk.bvh -o out/ --skeleton original   # original joint set
      mocap-exaggerate exaggerate iclone.bvh -o out/ --bvh-positions input   # back into iClone
      mocap-exaggerate exaggerate punch.bvh -o out/ --stretch "left_arm:120-160:3:axes=xz:ease_in=0.6,0.2"
      mocap-exaggerate exaggerate fight.bvh -o out/ --preset looney --auto-stretch -v
      mocap-exaggerate exaggerate walk.bvh run.bvh jump.bvh -o out/
      cat walk.bvh | mocap-exaggerate exaggerate - -o - > walk_cartoon.bvh
    """
    joint_map_path = options.pop("joint_map_path")
    if len(input_paths) > 1:
        return _exaggerate_several(input_paths, output, name, overwrite, skin_path, units, influences, write_glb,
                                   trails_path, path_file, options, joint_map_path)
    input_path = input_paths[0]
    from mocap_exaggerate.jobs.job import convert

    preset, config = _config_from_options(options)
    from_stdin = str(input_path) == "-"
    record = convert(
        sys.stdin.buffer if from_stdin else input_path,
        sys.stdout.buffer if str(output) == "-" else output,
        config,
        preset=preset,
        name=name if name is not None or not from_stdin else "stdin",
        label="<stdin>" if from_stdin else None,
        overwrite=overwrite,
        glb=write_glb,
        skin=skin_path,
        joint_map=_joint_map(skin_path, joint_map_path),
        units=units,
        influences=int(influences),
        trails=trails_path,
        path_file=path_file,
        protect=(options["config_file"],) if options["config_file"] is not None else (),
    )
    for warning in record.warnings:
        log.warning("%s: %s", record.input, warning)
    for note in record.notes:
        log.info("%s: %s", record.input, note)
    if record.manifest is not None and not _quiet():
        written = record.outputs
        suffixes = {"glb": ".glb", "weights": ".weights.npz", "pipeline": ".pipeline.toml"}
        extras = ", ".join(suffixes[k] for k in written if k in suffixes)
        click.echo(
            f"wrote {written['bvh']}{', ' + extras if extras else ''} and {written['manifest'].name}: "
            f"{record.frames} frames, {record.joints} joints, max link stretch {record.max_link_stretch:.2f}x, "
            f"{record.seconds:.2f} s",
            err=True,
        )


def _check_output_settings(units: str, influences: str, skin_path: Path | None,
                           joint_map_path: Path | None = None) -> dict | None:
    """Refuse a bad unit, skin or joint map once, before any file of a batch runs (each would fail
    alike); the joint map read."""
    from mocap_exaggerate.io.gltf import unit_scale
    from mocap_exaggerate.io.skin import load_skin

    unit_scale(units, 1.0)
    joint_map = _joint_map(skin_path, joint_map_path)
    if skin_path is not None:
        load_skin(skin_path)
    return joint_map


def _joint_map(skin_path: Path | None, joint_map_path: Path | None) -> dict | None:
    """The --joint-map file read (None without one); refused without a --skin to pair with."""
    from mocap_exaggerate.rig.binding import read_joint_map

    if joint_map_path is None:
        return None
    if skin_path is None:
        raise UserError("--joint-map pairs the clip's joints with a --skin's: give the skin too")
    return read_joint_map(joint_map_path)


def _batch_options(options: dict[str, Any], *, overwrite: bool, resume: bool, write_glb: bool,
                   skin_path: Path | None, units: str, influences: str, joint_map_path: Path | None = None):
    from mocap_exaggerate.jobs.batch import BatchOptions

    preset, config = _config_from_options(options)
    joint_map = (_check_output_settings(units, influences, skin_path, joint_map_path) if write_glb
                 else _joint_map(skin_path, joint_map_path))
    return BatchOptions(config, preset=preset, overwrite=overwrite, resume=resume, glb=write_glb,
                        skin=str(skin_path.resolve()) if skin_path is not None else None, joint_map=joint_map,
                        units=units, influences=int(influences))


def _run_reported(clips, out_dir: Path, batch_options, *, jobs: int, as_json: bool, problems=(),
                  scheduler: str | None = None, settings: str = "") -> int:
    """Run a batch with progress and a summary (and the report page when the options ask for it);
    the exit code (0 all done, 1 some failed, 130 interrupted)."""
    import time

    from mocap_exaggerate.jobs.batch import BatchInterrupted, run_batch

    from .report import Progress, summary

    quiet = _quiet()
    progress = Progress(len(clips) + len(problems), quiet=quiet, as_json=as_json)
    for problem in problems:
        progress(problem)
    started = time.perf_counter()
    if scheduler is None:
        workers: int | str = min(jobs, max(len(clips), 1))
    else:
        workers = f"a local Dask cluster of {jobs} worker(s)" if scheduler == "local" else f"Dask at {scheduler}"
    pending, reason = [], None
    try:
        results = run_batch(clips, out_dir, batch_options, jobs=jobs, on_result=progress, scheduler=scheduler)
    except BatchInterrupted as stop:
        results, pending, reason = stop.results, stop.pending, stop.reason
    finally:
        progress.close()
    if reason:
        log.error("%s; %d file(s) not done (--resume finishes them)", reason, len(pending))
    results = list(problems) + results
    report = None
    if batch_options.report:
        from mocap_exaggerate.viz.report import write_report

        try:
            report = str(write_report(out_dir, results, pending=pending, title=f"Batch report: {out_dir}",
                                      settings=settings))
        except OSError as error:
            log.error("%s: the report could not be written: %s", out_dir / "index.html", error.strerror or error)
    summary(results, time.perf_counter() - started, workers=workers, pending=len(pending), quiet=quiet,
            report=report)
    if pending:
        return 1 if reason else 130
    return 1 if any(r.status == "failed" for r in results) else 0


def _exaggerate_several(input_paths, output: Path, name, overwrite, skin_path, units, influences, write_glb,
                        trails_path, path_file, options, joint_map_path=None) -> None:
    from mocap_exaggerate.jobs.batch import Clip, same_outputs

    if any(str(p) == "-" for p in input_paths):
        raise UserError("'-' (standard input) can only be the one input")
    if str(output) == "-":
        raise UserError("-o - (standard output) takes one input; give a folder for several")
    for flag, value in (("--name", name), ("--trails", trails_path), ("--path-file", path_file)):
        if value is not None:
            raise UserError(f"{flag} belongs to one clip; give one input with it")
    if output.exists() and not output.is_dir():
        raise UserError(f"{output}: exists and is not a folder")
    clips = [Clip(path, Path(path.name)) for path in input_paths]
    for clip, other in same_outputs(clips).items():
        if os.path.realpath(other.source) == os.path.realpath(clip.source):
            raise UserError(f"{clip.source} is given twice")
        raise UserError(f"{other.source} and {clip.source} would write the same outputs in {output}; convert them "
                        f"apart (or use 'batch', which mirrors folders)")
    batch_options = _batch_options(options, overwrite=overwrite, resume=False, write_glb=write_glb,
                                   skin_path=skin_path, units=units, influences=influences,
                                   joint_map_path=joint_map_path)
    code = _run_reported(clips, output, batch_options, jobs=1, as_json=False)
    if code:
        click.get_current_context().exit(code)


def folder_arguments(func: Callable) -> Callable:
    """IN_DIR, OUT_DIR and --glob, shared by ``batch`` and ``plan``."""
    func = click.option("--glob", "pattern", default=DEFAULT_GLOB, show_default=True,
                        help="Which files under IN_DIR, by their path under it (case-insensitive; ** is any "
                             "folders).")(func)
    func = click.argument("out_dir", metavar="OUT_DIR", callback=_folder_argument)(func)
    return click.argument("in_dir", metavar="IN_DIR", callback=_folder_argument)(func)


def _find_batch_clips(in_dir: Path, out_dir: Path, pattern: str):
    """The clips a batch or plan takes, and what was met on the way; a usage error when none match."""
    from mocap_exaggerate.jobs.batch import check_folders, find_clips

    check_folders(in_dir, out_dir, pattern)
    clips, problems = find_clips(in_dir, pattern, exclude=[out_dir])
    if not clips:
        for problem in problems:  # -v: what was met on the way; the error is that nothing matched
            log.info("%s: %s", problem.input, problem.error)
        raise UserError(f"{in_dir}: no file matches {_shown(pattern)} (see --glob)")
    return clips, problems


@cli.command()
@folder_arguments
@click.option("-j", "--jobs", type=click.IntRange(1, 512), default=None,
              help="Worker processes, 1 to 512 (default: one per core).")
@click.option("--resume", is_flag=True,
              help="Keep clips whose outputs are complete and made from the same input and options; redo the rest.")
@click.option("--json", "as_json", is_flag=True,
              help="Print one JSON line per file on stdout (input, outputs, status, frames, seconds, "
                   "max_link_stretch, error).")
@click.option("--report", "write_report", is_flag=True,
              help="Also write OUT_DIR/index.html: each clip's poses and its fastest end effector's path, captured "
                   "and exaggerated, with its figures and links (the pictures go under OUT_DIR/report/).")
@click.option("--scheduler", metavar="ADDRESS", default=None,
              help="Run the clips on Dask distributed: 'local' (a LocalCluster of -j workers) or a scheduler "
                   "address such as tcp://host:8786 (the folders must be at the same paths on its workers). "
                   "Needs the dask extra (from a checkout: pip install '.[dask]').")
@output_options
@pipeline_options
@verbosity_options
@_fail_cleanly
def batch(in_dir: Path, out_dir: Path, pattern: str, jobs: int | None, resume: bool, as_json: bool,
          write_report: bool, scheduler: str | None, overwrite: bool, skin_path: Path | None, units: str,
          influences: str, write_glb: bool, **options) -> None:
    """Exaggerate every clip under IN_DIR into OUT_DIR, mirroring its folders.

    A bad file is reported and the rest go on; exit 0 when every file was
    converted (or kept by --resume), 1 when some failed, 2 for a usage
    mistake, 130 when stopped with Ctrl-C (clips being converted finish).

    \b
    Examples:
      mocap-exaggerate batch mocap/ out/ --preset looney -j 2
      mocap-exaggerate batch mocap/ out/ --resume --json > results.jsonl
      mocap-exaggerate batch mocap/ out/ --glob 'walk*/**/*.bvh' --no-glb
      mocap-exaggerate batch mocap/ out/ --report        (then open out/index.html)
      mocap-exaggerate batch /shared/mocap /shared/out --scheduler tcp://farm:8786
    """
    import shlex

    from mocap_exaggerate.jobs.batch import check_scheduler, default_jobs

    batch_options = _batch_options(options, overwrite=overwrite, resume=resume, write_glb=write_glb,
                                   skin_path=skin_path, units=units, influences=influences,
                                   joint_map_path=options.pop("joint_map_path"))
    batch_options = dataclasses.replace(batch_options, report=write_report)
    if scheduler is not None:
        if scheduler != "local" and jobs is not None:
            raise UserError("-j sets the size of --scheduler local; a Dask scheduler has the workers it has")
        check_scheduler(scheduler)  # imports Dask, which logs its own way: said with -vv (we say what matters)
        verbose = click.get_current_context().find_root().meta.get("mocap_exaggerate.verbosity", {}).get("verbose", 0)
        logging.getLogger("distributed").setLevel(logging.INFO if verbose >= 2 else logging.CRITICAL)
    clips, problems = _find_batch_clips(in_dir, out_dir, pattern)
    created = not out_dir.exists()
    _writable(out_dir)
    try:
        if write_report:
            from mocap_exaggerate.viz.report import check_report

            check_report(out_dir)
        given = _given_options(click.get_current_context(), exclude=set())
        settings = shlex.join(["mocap-exaggerate", "batch", str(in_dir), str(out_dir), *given])
        code = _run_reported(clips, out_dir, batch_options, jobs=jobs or default_jobs(), as_json=as_json,
                             problems=problems, scheduler=scheduler, settings=settings)
    except (UserError, MocapError):  # refused before any clip ran: leave no empty folder of ours behind
        if created:
            try:
                out_dir.rmdir()
            except OSError:
                pass
        raise
    if code:
        click.get_current_context().exit(code)


def _shown(text: str, most: int = 80) -> str:
    """``text`` quoted for a message, cut short when it is long."""
    return repr(text) if len(text) <= most else repr(text[:most]) + f"... ({len(text)} characters)"


def _writable(folder: Path) -> None:
    """Make ``folder`` and check a file can be written there, before any clip is worked on."""
    import tempfile

    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as error:
        raise UserError(f"{folder}: cannot write there ({error.strerror or error})") from None


@cli.command()
@folder_arguments
@output_options
@pipeline_options
@click.option("--print0", "print0", is_flag=True,
              help="End each command with a NUL byte instead of a newline, for 'xargs -0' (any file name).")
@click.option("--json", "as_json", is_flag=True,
              help="Print a JSON list of {input, output, name, argv} instead, for tools that take one.")
@verbosity_options
@_fail_cleanly
def plan(in_dir: Path, out_dir: Path, pattern: str, overwrite: bool, skin_path: Path | None, units: str,
         influences: str, write_glb: bool, print0: bool, as_json: bool, **options) -> None:
    """Print one self-contained 'exaggerate' command per clip under IN_DIR, for a farm's job list.

    Each line converts one clip into the place 'batch' would put it, with the
    options given here (paths made absolute, quoted for the shell); feed the
    lines to Deadline, OpenCue, a Slurm array or xargs. Nothing is converted
    or written. A clip whose path holds a line break cannot be one line: it is
    left out with a warning unless --print0 or --json is given.

    \b
    Examples:
      mocap-exaggerate plan mocap/ /farm/out --preset looney > jobs.txt
      sed -n "${SLURM_ARRAY_TASK_ID}p" jobs.txt | sh          # one Slurm array task
      mocap-exaggerate plan mocap/ out/ --print0 | xargs -0 -n 1 -P 8 sh -c
    """
    import json
    import shlex

    if print0 and as_json:
        raise click.UsageError("--print0 and --json are two forms of the same list: give one")
    _batch_options(options, overwrite=overwrite, resume=False, write_glb=write_glb, skin_path=skin_path,
                   units=units, influences=influences,
                   joint_map_path=options.pop("joint_map_path"))  # a bad setting is refused here, not on the farm
    clips, problems = _find_batch_clips(in_dir, out_dir, pattern)
    for problem in problems:
        log.warning("%s: %s", problem.input, problem.error)
    given = _given_options(click.get_current_context(), exclude={"pattern", "print0", "as_json"})
    jobs = []
    for clip in clips:
        folder = (out_dir / clip.relative.parent).absolute()
        argv = ["mocap-exaggerate", "exaggerate", str(clip.source.absolute()), "-o", str(folder),
                "--name", clip.name, *given]
        if not (print0 or as_json) and any("\n" in word or "\r" in word for word in argv):
            log.warning("%s: its path has a line break, so it cannot be one line of a job list; left out "
                        "(--print0 or --json list it)", clip.source)
            continue
        jobs.append({"input": str(clip.source.absolute()), "output": str(folder), "name": clip.name, "argv": argv})
    if as_json:
        click.echo(json.dumps(jobs, indent=1, ensure_ascii=False))
    else:
        for job in jobs:
            click.echo(shlex.join(job["argv"]), nl=not print0)
            if print0:
                click.echo("\0", nl=False)


def _given_options(ctx: click.Context, exclude: set[str]) -> list[str]:
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


@cli.command()
@click.argument("input_path", metavar="IN.bvh", type=click.Path(path_type=Path, allow_dash=True))
@click.option("--limbs", is_flag=True, help="Also list the limbs found (base to end effector).")
@click.option("--groups", is_flag=True, help="Also list the rubber-joint groups and the joints that ride rigidly.")
@click.option("--contacts", is_flag=True, help="Also list where the end effectors touch the ground (frames).")
@click.option("--fps", type=float, default=None, help="Frame rate overriding the file's Frame Time.")
@click.option("--root-offset", "root_offset", type=click.Choice(["auto", "replace", "add"]), default="auto",
              show_default=True, help="Position channels replace the joint's OFFSET or add to it (iClone, MakeHuman).")
@click.option("--up", type=click.Choice(["auto", "x", "y", "z"]), default="auto", show_default=True,
              help="The axis the body stands along.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object instead of text.")
@verbosity_options
@_fail_cleanly
def info(input_path: Path, limbs: bool, groups: bool, contacts: bool, fps: float | None, root_offset: str, up: str,
         as_json: bool) -> None:
    """Describe a clip: joints, channels, rotation orders, frames, fps, duration, height.

    \b
    Example:
      mocap-exaggerate info sample_data/cmu_09_01_run_daz.bvh --limbs --groups --contacts
    """
    from mocap_exaggerate.jobs.job import describe

    label = "<stdin>" if str(input_path) == "-" else str(input_path)
    data = describe(input_path, fps=fps, limbs=limbs, groups=groups, contacts=contacts, label=label,
                    root_offset=root_offset, up=up)
    orders = data["rotation_orders"]
    if as_json:
        click.echo(json.dumps(data, indent=2))
        return
    click.echo(f"{label}")
    click.echo(f"  joints      {data['joints']} (+{data['end_sites']} End Sites), root {data['root']}")
    added = " (added to the OFFSET: --root-offset add)" if data["root_offset"] == "add" else ""
    click.echo(f"  channels    {data['channels']}; position channels on "
               f"{', '.join(data['position_channel_joints'][:6]) or 'none'}"
               f"{' ...' if len(data['position_channel_joints']) > 6 else ''}{added}")
    click.echo(f"  rotation    {', '.join(f'{o} x{n}' for o, n in orders.items())}")
    click.echo(f"  frames      {data['frames']} at {data['fps']:g} fps ({data['duration_s']:.3f} s)")
    click.echo(f"  height      {data['height']:g} units along {data['up_axis']} (rest pose)")
    if data["rest_frames"]:
        click.echo(f"  rest pose   {data['rest_frames']} leading synthetic frame(s) (see --tpose)")
    for warning in data["warnings"]:
        click.echo(f"  warning     {warning}")
    if limbs:
        for name, chain in data["limbs"].items():
            click.echo(f"  {name:<11} {' > '.join(chain)}")
    if contacts:
        floor = data["contacts"]["floor"]
        click.echo(f"  floor       {floor['height']:g} along {floor['up']}{floor['axis']} (the lowest any joint goes)")
        for joint, runs in data["contacts"]["contacts"].items():
            spans = ", ".join(f"{a}-{b}" for a, b in runs) or "none"
            click.echo(f"  contact     {joint}: {spans}")
    if groups:
        click.echo(f"  sub-joints  {data['subjoints']} with the default 4 sub-links per link")
        for chain in data["groups"]:
            click.echo(f"  group       {chain[0]} | {' > '.join(chain[1:])}")
        rigid = data["rigid"]
        if rigid:
            shown = ", ".join(rigid[:8]) + (f", ... ({len(rigid)} in all)" if len(rigid) > 8 else "")
            click.echo(f"  rigid       {shown}")


@cli.command()
@click.argument("input_path", metavar="IN.bvh", type=click.Path(path_type=Path, allow_dash=True))
@click.option("-o", "--output", required=True, type=click.Path(path_type=Path),
              help="File to write: .png (still frames), .gif (looping animation) or .mp4 (needs ffmpeg).")
@click.option("--frames", "count", type=click.IntRange(1, 12), default=5, show_default=True,
              help="How many evenly spaced frames a .png shows.")
@click.option("--trajectory", metavar="JOINT", default=None,
              help="Draw this joint's captured, averaged and exaggerated paths instead (a .png).")
@click.option("--start", type=click.FloatRange(min=0.0), default=0.0, show_default=True, metavar="SECONDS",
              help="Show the motion from this many seconds in.")
@click.option("--seconds", type=click.FloatRange(min=0.0, min_open=True), default=None, metavar="SECONDS",
              help="Show this many seconds [default: all; an animation stops at 10].")
@click.option("--overwrite", is_flag=True, help="Replace the file if it exists.")
@click.option("--skin", "skin_path", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Draw your character (as 'exaggerate --skin' takes it) instead of the default rubber body.")
@click.option("--joint-map", "joint_map_path", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="With --skin: 'clip joint = skin joint' lines for joints the pairing misses.")
@pipeline_options
@verbosity_options
@_fail_cleanly
def preview(input_path: Path, output: Path, count: int, trajectory: str | None, start: float, seconds: float | None,
            overwrite: bool, skin_path: Path | None, joint_map_path: Path | None, **options) -> None:
    """Render the skinned body captured and exaggerated (no GPU, no display).

    A .png shows still frames, captured above and exaggerated below; a .gif or .mp4 plays
    them side by side at the clip's speed, looping; --trajectory draws one joint's paths.

    \b
    Examples:
      mocap-exaggerate preview sample_data/cmu_09_01_run_daz.bvh -o run.png --preset looney
      mocap-exaggerate preview sample_data/cmu_09_01_run_daz.bvh -o run.gif
      mocap-exaggerate preview sample_data/cmu_09_01_run_daz.bvh -o foot.png --trajectory lFoot
    """
    from mocap_exaggerate.viz.preview import write_preview

    _, config = _config_from_options(options)
    from_stdin = str(input_path) == "-"
    write_preview(sys.stdin.buffer if from_stdin else input_path, output, config, frames=count, overwrite=overwrite,
                  label="<stdin>" if from_stdin else None, trajectory=trajectory, start=start, seconds=seconds,
                  skin=skin_path, joint_map=_joint_map(skin_path, joint_map_path))
    if not _quiet():
        click.echo(f"wrote {output}", err=True)


@cli.command()
@verbosity_options
def presets() -> None:
    """List the shipped presets and what they do.

    \b
    Example:
      mocap-exaggerate presets
    """
    for name in preset_names():
        mark = " (default)" if name == DEFAULT_PRESET else ""
        click.echo(f"{name}{mark}: {preset_description(name)}")


def main() -> None:
    code = cli.main(prog_name="mocap-exaggerate")
    sys.exit(code if isinstance(code, int) else 0)


if __name__ == "__main__":
    main()
