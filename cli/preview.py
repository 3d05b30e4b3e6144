"""``mocap-exaggerate preview``: the body captured and exaggerated, as still frames or an animation."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from .app import cli, fail_cleanly, printable, quiet, verbosity_options
from .options import FilePath, character_options, config_from_options, picture_options, pipeline_options


@cli.command()
@click.argument("input_path", metavar="IN.bvh", type=FilePath(path_type=Path, allow_dash=True))
@click.option("-o", "--output", required=True, type=FilePath(path_type=Path),
              help="File to write: .png (still frames), .gif (looping animation), .mp4 (needs ffmpeg) or .html (a "
                   "page that plays both GLBs).")
@click.option("--frames", "count", type=click.IntRange(1, 12), default=5, show_default=True,
              help="How many evenly spaced frames a .png shows.")
@click.option("--trajectory", metavar="JOINT", default=None,
              help="Draw this joint's captured, averaged and exaggerated paths instead (a .png).")
@picture_options
@character_options
@pipeline_options
@verbosity_options
@fail_cleanly
def preview(input_path: Path, output: Path, count: int, trajectory: str | None, start: float, seconds: float | None,
            overwrite: bool, **options) -> None:
    """Render the skinned body captured and exaggerated (no GPU, no display).

    A .png shows still frames, captured above and exaggerated below; a .gif or .mp4 plays
    them side by side at the clip's speed, looping; a .html is one self-contained page that
    plays both GLBs with the hands' and feet's paths; --trajectory draws one joint's paths.

    \b
    Examples:
      mocap-exaggerate preview sample_data/cmu_09_01_run_daz.bvh -o run.png --preset looney
      mocap-exaggerate preview sample_data/cmu_09_01_run_daz.bvh -o run.gif
      mocap-exaggerate preview sample_data/cmu_09_01_run_daz.bvh -o run.html
      mocap-exaggerate preview sample_data/cmu_09_01_run_daz.bvh -o foot.png --trajectory lFoot
    """
    from mocap_exaggerate.viz.preview import write_preview

    # The character drawn is the config's too (a run's pipeline file names the one it used).
    _, config = config_from_options(options)
    from_stdin = str(input_path) == "-"
    write_preview(sys.stdin.buffer if from_stdin else input_path, output, config, frames=count, overwrite=overwrite,
                  label="<stdin>" if from_stdin else None, trajectory=trajectory, start=start, seconds=seconds,
                  protect=(options["config_file"],) if options["config_file"] is not None else ())
    if not quiet():
        click.echo(printable(f"wrote {output}"), err=True)
