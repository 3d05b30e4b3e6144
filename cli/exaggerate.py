"""``mocap-exaggerate exaggerate``: one clip (or a few) into a folder, or a stream to a stream."""

from __future__ import annotations

import logging
import os
import sys
from pathlib import Path

import click

from .app import UserError, cli, fail_cleanly, printable, quiet, verbosity_options
from .batch import batch_options, run_reported
from .options import FilePath, config_from_options, folder_argument, output_options, pipeline_options

log = logging.getLogger("mocap_exaggerate")


@cli.command()
@click.argument("input_paths", metavar="IN.bvh...", nargs=-1, required=True,
                type=FilePath(path_type=Path, allow_dash=True))
@click.option("-o", "--output", "output", required=True, callback=folder_argument,
              help="Output folder (created if needed), or - to write the BVH to stdout.")
@click.option("--name", default=None, help="Output file stem (default: the input's; 'stdin' for -).")
@output_options
@click.option("--trails", "trails_path", type=FilePath(dir_okay=False, path_type=Path), default=None,
              help="Write the original and exaggerated end-effector paths of every stretch as JSON.")
@click.option("--path-file", "path_file", type=FilePath(dir_okay=False, path_type=Path), default=None,
              help="Apply hand-edited paths: a --trails file whose 'exaggerated' points you moved.")
@pipeline_options
@verbosity_options
@fail_cleanly
def exaggerate(input_paths: tuple[Path, ...], output: Path, name: str | None, overwrite: bool,
               trails_path: Path | None, path_file: Path | None, **options) -> None:
    """Exaggerate clips: writes OUT/<name>.bvh, .glb, .weights.npz, .pipeline.toml and .json (manifest) for each.

    OUT/<name>.pipeline.toml records every setting, the GLB's and the character's too:
    '--config OUT/<name>.pipeline.toml' rebuilds the same files, from any folder. With several
    files, a bad one is reported and the rest go on (exit 1 if any failed); for whole folders
    see 'batch'.

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
      mocap-exaggerate exaggerate run.bvh -o again/ --config out/walk.pipeline.toml   # walk's settings
      cat walk.bvh | mocap-exaggerate exaggerate - -o - > walk_cartoon.bvh
    """
    known = (".bvh", ".glb", ".gltf", ".usd", ".usda", ".usdc", ".fbx")
    if str(output) != "-" and output.suffix.lower() in known and not output.exists():  # (a file there is refused)
        log.warning("%s: -o names a folder (made if needed), and the files go inside it; '-o -' writes the BVH to "
                    "standard output", printable(str(output)))
    if len(input_paths) > 1:
        return _exaggerate_several(input_paths, output, name, overwrite, trails_path, path_file, options)
    input_path = input_paths[0]
    from mocap_exaggerate.jobs.job import convert

    preset, config = config_from_options(options)
    from_stdin = str(input_path) == "-"
    for stream, which in ((sys.stdin, "input") if from_stdin else (None, None),
                          (sys.stdout, "output") if str(output) == "-" else (None, None)):
        if which is not None and (stream is None or stream.closed):  # (started with <&- or >&-)
            raise UserError(f"standard {which} is closed; give a file, or open it")
    record = convert(
        sys.stdin.buffer if from_stdin else input_path,
        sys.stdout.buffer if str(output) == "-" else output,
        config,  # the GLB's options too: its [glb] block
        preset=preset,
        name=name if name is not None or not from_stdin else "stdin",
        label="<stdin>" if from_stdin else None,
        overwrite=overwrite,
        trails=trails_path,
        path_file=path_file,
        protect=(options["config_file"],) if options["config_file"] is not None else (),
    )
    for warning in record.warnings:
        log.warning("%s: %s", record.input, warning)
    for note in record.notes:
        log.info("%s: %s", record.input, note)
    if record.manifest is not None and not quiet():
        written = record.outputs
        suffixes = {"glb": ".glb", "weights": ".weights.npz", "fbx": ".fbx", "pipeline": ".pipeline.toml"}
        if "usd" in written:
            suffixes["usd"] = Path(written["usd"]).suffix
        extras = ", ".join(suffixes[k] for k in written if k in suffixes)
        frames = f"{record.frames} frame{'s' * (record.frames != 1)}"
        joints = f"{record.joints} joint{'s' * (record.joints != 1)}"
        click.echo(printable(
            f"wrote {written['bvh']}{', ' + extras if extras else ''} and {written['manifest'].name}: "
            f"{frames}, {joints}, max link stretch {record.max_link_stretch:.2f}x, {record.seconds:.2f} s"),
            err=True,
        )


def _exaggerate_several(input_paths, output: Path, name, overwrite, trails_path, path_file, options) -> None:
    from mocap_exaggerate.jobs.batch import Clip, same_outputs

    if any(str(p) == "-" for p in input_paths):
        raise UserError("'-' (standard input) can only be the one input")
    if str(output) == "-":
        raise UserError("-o - (standard output) takes one input; give a folder for several")
    for flag, value in (("--name", name), ("--trails", trails_path), ("--path-file", path_file)):
        if value is not None:
            raise UserError(f"{flag} belongs to one clip; give one input with it")
    from mocap_exaggerate.io.files import not_a_folder

    refused = not_a_folder(output)
    if refused:
        raise UserError(refused)
    clips = [Clip(path, Path(path.name)) for path in input_paths]
    for clip, other in same_outputs(clips).items():
        if os.path.realpath(other.source) == os.path.realpath(clip.source):
            raise UserError(f"{clip.source} is given twice")
        raise UserError(f"{other.source} and {clip.source} would write the same outputs in {output}; convert them "
                        f"apart (or use 'batch', which mirrors folders)")
    code = run_reported(clips, output, batch_options(options, overwrite=overwrite, resume=False), jobs=1,
                        as_json=False)
    if code:
        click.get_current_context().exit(code)
