"""The ``mocap-exaggerate`` command line: parses options, calls the library, reports.

No algorithm lives here.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import logging
import sys
import time
from pathlib import Path
from typing import Any, Callable

import click
import numpy as np

from mocap_exaggerate import __version__
from mocap_exaggerate.errors import MocapError
from mocap_exaggerate.io.bvh import format_bvh, read_bvh
from mocap_exaggerate.io.files import atomic_write
from mocap_exaggerate.limbs import find_limbs
from mocap_exaggerate.io.skin import load_skin
from mocap_exaggerate.pipeline import (
    DEFAULT_PRESET,
    make_glb,
    manifest,
    preset_description,
    preset_names,
    resolve_config,
    run,
)
from mocap_exaggerate.stages.stretch import parse_stretch
from mocap_exaggerate.stages.subjoints import build_hierarchy
from mocap_exaggerate.stages.tpose import detect_rest_frames

log = logging.getLogger("mocap_exaggerate")


class UserError(click.ClickException):
    """A mistake in the input or the options: one line, exit code 2."""

    exit_code = 2


def _fail_cleanly(func: Callable) -> Callable:
    """Turn library errors into one-line messages; never a traceback for a user mistake."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except MocapError as error:
            raise UserError(str(error)) from None
        except OSError as error:
            where = f"{error.filename}: " if getattr(error, "filename", None) else ""
            raise click.ClickException(f"{where}{error.strerror or error}") from None

    return wrapper


def _parse_stretches(ctx, param, values: tuple[str, ...]):
    try:
        return tuple(parse_stretch(v) for v in values)
    except MocapError as error:
        raise click.BadParameter(str(error)) from None


def _parse_weights(ctx, param, values: tuple[str, ...]) -> tuple[tuple[str, float], ...]:
    out = []
    for item in values:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise click.BadParameter(f"{item!r} is not NAME=WEIGHT (e.g. LeftArm=2, left_leg=0.5, 'Left*'=0)")
        try:
            weight = float(value)
        except ValueError:
            raise click.BadParameter(f"{item!r}: weight {value!r} is not a number") from None
        if not np.isfinite(weight) or not 0 <= weight <= 10:
            raise click.BadParameter(f"{item!r}: weight must be between 0 and 10")
        out.append((key.strip(), weight))
    return tuple(out)


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
        click.option("--stretch", "stretches", multiple=True, callback=_parse_stretches, metavar="SPEC",
                     help="Squash/stretch a limb along its path: LIMB:START-END:SCALE[:axes=xz][:pivot=end]"
                          "[:ease_in=0.6,0.2][:ease_out=0.3,0.8][:blend=1][:release=0.1s]; frames or 1.2s. "
                          "Repeatable; adds to the config's [[stretch]] list."),
        click.option("--auto-stretch/--no-auto-stretch", "auto_stretch_on", default=None,
                     help="Find strikes (punches, kicks, throws, leaps) and stretch them by the style's scale."),
        click.option("--tpose", type=click.Choice(["auto", "keep", "drop"]), default=None,
                     help="Leading synthetic rest pose: auto (keep out of filters, unchanged), keep, drop."),
        click.option("--fps", type=float, default=None, help="Frame rate overriding the file's Frame Time."),
    ]
    for option in reversed(options):
        func = option(func)
    return func


def _overrides(p: dict[str, Any]) -> dict[str, Any]:
    table: dict[str, dict[str, Any]] = {
        "input": {}, "extrapolate": {}, "correct": {}, "subjoints": {}, "springs": {}, "output": {},
        "auto_stretch": {},
    }
    pairs = [
        ("input", "tpose", p["tpose"]), ("input", "fps", p["fps"]),
        ("extrapolate", "enabled", p["extrapolate_on"]), ("extrapolate", "sigma", p["sigma"]),
        ("extrapolate", "omega", p["omega"]),
        ("correct", "enabled", p["correct_on"]), ("correct", "threshold", p["threshold"]),
        ("correct", "delta", p["delta"]), ("correct", "max_stretch", p["max_stretch"]),
        ("correct", "max_iter", p["max_iter"]),
        ("subjoints", "enabled", False if p["subjoints_off"] else None), ("subjoints", "per_link", p["per_link"]),
        ("subjoints", "sublink_length", _length(p["sublink_length"])),
        ("springs", "enabled", p["springs_on"]), ("springs", "stiffness", p["stiffness"]),
        ("springs", "link_stiffness", p["link_stiffness"]), ("springs", "damping", p["damping"]),
        ("springs", "blend", p["blend"]),
        ("output", "skeleton", p["skeleton_mode"]),
        ("auto_stretch", "enabled", p["auto_stretch_on"]),
    ]
    for block, key, value in pairs:
        if value is not None:
            table[block][key] = value
    if p["weights"]:
        table["extrapolate"]["weights"] = dict(p["weights"])
    return {k: v for k, v in table.items() if v}


def _length(value: str | None) -> float | str | None:
    """A --sublink-length value: a number of skeleton units, or a share such as '3%'."""
    if value is None or value.strip().endswith("%"):
        return value
    try:
        return float(value)
    except ValueError:
        return value  # the config names it in its error


def _config_from_options(p: dict[str, Any]):
    text = None
    if p["config_file"] is not None:
        try:
            text = p["config_file"].read_text(encoding="utf-8")
        except FileNotFoundError:
            raise UserError(f"{p['config_file']}: no such config file") from None
    preset = p["preset"] or DEFAULT_PRESET
    config = resolve_config(preset, text, _overrides(p), config_source=str(p["config_file"] or "options"))
    if p["stretches"]:
        config = dataclasses.replace(config, stretch=config.stretch + p["stretches"])
    return preset, config


# ---------------------------------------------------------------------------- commands


@click.group(context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(__version__, prog_name="mocap-exaggerate")
@click.option("-v", "--verbose", count=True, help="More detail on stderr (-vv for debugging).")
@click.option("-q", "--quiet", is_flag=True, help="Only errors on stderr.")
def cli(verbose: int, quiet: bool) -> None:
    """Turn motion capture (BVH) into cartoon-style motion.

    \b
    Example:
      mocap-exaggerate exaggerate sample_data/cmu_09_01_run_daz.bvh -o out/ --sigma 0.2s --omega 5
      mocap-exaggerate info sample_data/cmu_09_01_run_daz.bvh --limbs
    """
    level = logging.ERROR if quiet else (logging.WARNING, logging.INFO, logging.DEBUG)[min(verbose, 2)]
    logging.basicConfig(level=level, format="%(levelname)s: %(message)s", stream=sys.stderr, force=True)


@cli.command()
@click.argument("input_path", metavar="IN.bvh", type=click.Path(path_type=Path, allow_dash=True))
@click.option("-o", "--output", "output", required=True, type=click.Path(path_type=Path, allow_dash=True),
              help="Output folder (created if needed), or - to write the BVH to stdout.")
@click.option("--name", default=None, help="Output file stem (default: the input's; 'stdin' for -).")
@click.option("--overwrite", is_flag=True, help="Replace outputs that exist already.")
@click.option("--skin", "skin_path", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Skin for the GLB: .npz (vertices, faces, joint_names, weights) bound to the clip's joints "
                   "in its rest pose. Default: a capsule body grown from the skeleton.")
@click.option("--units", default="auto", show_default=True,
              help="BVH units for the GLB (metres): auto, m, dm, cm, mm, in, ft, cmu.")
@click.option("--influences", type=click.Choice(["4", "8"]), default="4", show_default=True,
              help="Joints per vertex in the GLB: 4 (JOINTS_0) or 8 (a second JOINTS_1/WEIGHTS_1 set).")
@click.option("--glb/--no-glb", "write_glb", default=True, show_default=True,
              help="Also write OUT/<name>.glb (skinned, animated) and OUT/<name>.weights.npz.")
@click.option("--trails", "trails_path", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Write the original and exaggerated end-effector paths of every stretch as JSON.")
@click.option("--path-file", "path_file", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Apply hand-edited paths: a --trails file whose 'exaggerated' points you moved.")
@pipeline_options
@_fail_cleanly
def exaggerate(input_path: Path, output: Path, name: str | None, overwrite: bool, skin_path: Path | None,
               units: str, influences: str, write_glb: bool, trails_path: Path | None, path_file: Path | None, **options) -> None:
    """Exaggerate one clip: writes OUT/<name>.bvh, .glb, .weights.npz and .json (manifest).

    \b
    Examples:
      mocap-exaggerate exaggerate walk.bvh -o out/                       # cartoon preset
      mocap-exaggerate exaggerate walk.bvh -o out/ --preset looney --weight Hips=0
      mocap-exaggerate exaggerate walk.bvh -o out/ --sigma 18f --omega 3 --no-correct
      mocap-exaggerate exaggerate walk.bvh -o out/ --subjoints 6 --blend 0.7 --stiffness 100
      mocap-exaggerate exaggerate walk.bvh -o out/ --skeleton original   # original joint set
      mocap-exaggerate exaggerate punch.bvh -o out/ --stretch "left_arm:120-160:3:axes=xz:ease_in=0.6,0.2"
      mocap-exaggerate exaggerate fight.bvh -o out/ --preset looney --auto-stretch -v
      cat walk.bvh | mocap-exaggerate exaggerate - -o - > walk_cartoon.bvh
    """
    preset, config = _config_from_options(options)
    started = time.perf_counter()
    if str(input_path) == "-":
        data = sys.stdin.buffer.read()
        label = "<stdin>"
        stem = name or "stdin"
    else:
        try:
            data = input_path.read_bytes()
        except FileNotFoundError:
            raise UserError(f"{input_path}: no such file") from None
        except IsADirectoryError:
            raise UserError(f"{input_path}: is a folder; give a .bvh file") from None
        label = str(input_path)
        stem = name or input_path.stem
    motion, report = read_bvh(data, name=label, fps=config.input.fps)
    read_seconds = time.perf_counter() - started
    for warning in report.warnings:
        log.warning("%s: %s", label, warning)

    paths = _read_path_file(path_file) if path_file else None
    result = run(motion, config, paths=paths)
    for note in result.notes:
        log.info("%s: %s", label, note)
    if trails_path is not None:
        if trails_path.exists() and not overwrite:
            raise UserError(f"{trails_path} exists; pass --overwrite to replace it")
        trails = {"input": label, "fps": motion.fps, "trails": result.stretch.trails if result.stretch else []}
        atomic_write(trails_path, (json.dumps(trails, indent=1) + "\n").encode("utf-8"), overwrite=True)

    started = time.perf_counter()
    bvh_bytes = format_bvh(result.motion)
    write_seconds = time.perf_counter() - started

    if str(output) == "-":
        sys.stdout.buffer.write(bvh_bytes)
        sys.stdout.buffer.flush()
        return

    bvh_path = output / f"{stem}.bvh"
    json_path = output / f"{stem}.json"
    glb_path = output / f"{stem}.glb"
    weights_path = output / f"{stem}.weights.npz"
    if output.exists() and not output.is_dir():
        raise UserError(f"{output}: exists and is not a folder")
    written = [bvh_path, json_path] + ([glb_path, weights_path] if write_glb else [])
    for path in written:
        if str(input_path) != "-" and path.resolve() == input_path.resolve():
            raise UserError(f"{path}: would overwrite the input; choose another -o folder or --name")
        if path.exists() and not overwrite:
            raise UserError(f"{path} exists; pass --overwrite to replace it")
    extra: dict[str, bytes] = {}
    outputs = {"bvh": bvh_path.name}
    if write_glb:
        started_glb = time.perf_counter()
        glb_bytes, npz_bytes_, how = make_glb(motion, result, load_skin(skin_path) if skin_path else None, units,
                                              int(influences))
        extra = {glb_path.name: glb_bytes, weights_path.name: npz_bytes_}
        outputs.update(glb=glb_path.name, weights=weights_path.name, units=how)
        result.timings["glb"] = time.perf_counter() - started_glb
    info = manifest(
        input_name=label,
        input_bytes=data,
        config=config,
        preset=preset,
        result=result,
        outputs=outputs,
        read_seconds=read_seconds,
        write_seconds=write_seconds,
        reader_warnings=report.warnings,
        frames_in=motion.num_frames,
        fps=motion.fps,
    )
    started = time.perf_counter()
    atomic_write(bvh_path, bvh_bytes, overwrite=True)
    info["timings"]["write"] += time.perf_counter() - started
    for file_name, data in extra.items():
        atomic_write(output / file_name, data, overwrite=True)
    atomic_write(json_path, (json.dumps(info, indent=2) + "\n").encode("utf-8"), overwrite=True)
    total = sum(info["timings"].values())
    if not _quiet():
        click.echo(
            f"wrote {bvh_path}{', .glb, .weights.npz' if write_glb else ''} and {json_path.name}: "
            f"{result.motion.num_frames} frames, "
            f"{result.motion.skeleton.num_joints} joints, max link stretch {result.max_link_stretch:.2f}x, "
            f"{total:.2f} s",
            err=True,
        )


def _read_path_file(path: Path) -> dict:
    """Edited paths from a trails JSON file: limb -> (frames, positions)."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise UserError(f"{path}: no such path file") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        raise UserError(f"{path}: not a JSON trails file ({error})") from None
    paths = {}
    for number, trail in enumerate(data.get("trails", []) if isinstance(data, dict) else [], start=1):
        try:
            frames = [int(f) for f in trail["frames"]]
            points = np.asarray(trail["exaggerated"], dtype=np.float64)
            limb = str(trail["limb"])
        except (KeyError, TypeError, ValueError):
            raise UserError(f"{path}: trail #{number} needs limb, frames and exaggerated points") from None
        if points.shape != (len(frames), 3) or not np.all(np.isfinite(points)):
            raise UserError(f"{path}: trail #{number} ({limb}) has {len(frames)} frames but points of shape "
                            f"{points.shape}; expected one finite x, y, z per frame")
        paths[limb] = (frames, points)
    if not paths:
        raise UserError(f"{path}: no trails in it")
    return paths


def _quiet() -> bool:
    ctx = click.get_current_context(silent=True)
    return bool(ctx and ctx.find_root().params.get("quiet"))


@cli.command()
@click.argument("input_path", metavar="IN.bvh", type=click.Path(path_type=Path, allow_dash=True))
@click.option("--limbs", is_flag=True, help="Also list the limbs found (base to end effector).")
@click.option("--groups", is_flag=True, help="Also list the rubber-joint groups and the joints that ride rigidly.")
@click.option("--fps", type=float, default=None, help="Frame rate overriding the file's Frame Time.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object instead of text.")
@_fail_cleanly
def info(input_path: Path, limbs: bool, groups: bool, fps: float | None, as_json: bool) -> None:
    """Describe a clip: joints, channels, rotation orders, frames, fps, duration, height.

    \b
    Example:
      mocap-exaggerate info sample_data/cmu_09_01_run_daz.bvh --limbs --groups
    """
    label = "<stdin>" if str(input_path) == "-" else str(input_path)
    motion, report = read_bvh(input_path, name=label, fps=fps)
    skeleton = motion.skeleton
    orders: dict[str, int] = {}
    for j in range(skeleton.num_joints):
        if skeleton.channels[j]:
            orders[skeleton.rotation_order(j)] = orders.get(skeleton.rotation_order(j), 0) + 1
    end_sites = int(np.isfinite(skeleton.end_sites[:, 0]).sum())
    data: dict[str, Any] = {
        "file": label,
        "joints": skeleton.num_joints,
        "end_sites": end_sites,
        "channels": skeleton.num_channels,
        "position_channel_joints": [skeleton.names[j] for j in range(skeleton.num_joints) if skeleton.has_position_channels(j)],
        "rotation_orders": orders,
        "frames": motion.num_frames,
        "fps": round(motion.fps, 6),
        "duration_s": round(motion.duration, 6),
        "up_axis": "XYZ"[skeleton.up_axis()],
        "height": round(skeleton.height(), 4),
        "rest_frames": detect_rest_frames(motion),
        "warnings": report.warnings,
    }
    if limbs:
        data["limbs"] = {name: [skeleton.names[j] for j in limb.joints] for name, limb in find_limbs(skeleton).items()}
    if groups:
        hierarchy = build_hierarchy(skeleton)
        data["groups"] = [[skeleton.names[j] for j in chain] for chain in hierarchy.groups]
        data["rigid"] = [skeleton.names[j] for j in np.flatnonzero(hierarchy.rigid)]
        data["subjoints"] = hierarchy.skeleton.num_joints
    if as_json:
        click.echo(json.dumps(data, indent=2))
        return
    click.echo(f"{label}")
    click.echo(f"  joints      {data['joints']} (+{end_sites} End Sites), root {skeleton.names[0]}")
    click.echo(f"  channels    {data['channels']}; position channels on {', '.join(data['position_channel_joints']) or 'none'}")
    click.echo(f"  rotation    {', '.join(f'{o} x{n}' for o, n in orders.items())}")
    click.echo(f"  frames      {data['frames']} at {motion.fps:g} fps ({motion.duration:.3f} s)")
    click.echo(f"  height      {data['height']:g} units along {data['up_axis']} (rest pose)")
    if data["rest_frames"]:
        click.echo(f"  rest pose   {data['rest_frames']} leading synthetic frame(s) (see --tpose)")
    for warning in report.warnings:
        click.echo(f"  warning     {warning}")
    if limbs:
        for name, chain in data["limbs"].items():
            click.echo(f"  {name:<11} {' > '.join(chain)}")
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
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="PNG file to write.")
@click.option("--frames", "count", type=click.IntRange(1, 12), default=5, show_default=True,
              help="How many evenly spaced frames to show.")
@click.option("--overwrite", is_flag=True, help="Replace the PNG if it exists.")
@pipeline_options
@_fail_cleanly
def preview(input_path: Path, output: Path, count: int, overwrite: bool, **options) -> None:
    """Render the skinned body, captured above and exaggerated below, to a PNG (no GPU, no display).

    \b
    Example:
      mocap-exaggerate preview sample_data/cmu_09_01_run_daz.bvh -o run.png --preset looney
    """
    from mocap_exaggerate.preview import render_preview

    preset, config = _config_from_options(options)
    if output.exists() and not overwrite:
        raise UserError(f"{output} exists; pass --overwrite to replace it")
    label = "<stdin>" if str(input_path) == "-" else str(input_path)
    motion, _ = read_bvh(input_path, name=label, fps=config.input.fps)
    result = run(motion, config)
    atomic_write(output, render_preview(motion, result, frames=count), overwrite=True)
    if not _quiet():
        click.echo(f"wrote {output}", err=True)


@cli.command()
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
    cli(prog_name="mocap-exaggerate")


if __name__ == "__main__":
    main()
