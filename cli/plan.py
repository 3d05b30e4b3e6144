"""``mocap-exaggerate plan``: one self-contained ``exaggerate`` command per clip, for a farm's job list."""

from __future__ import annotations

import logging
from pathlib import Path

import click

from .app import cli, emit, fail_cleanly, verbosity_options
from .batch import batch_options, find_batch_clips
from .options import folder_arguments, given_options, output_options, pipeline_options

log = logging.getLogger("mocap_exaggerate")


@cli.command()
@folder_arguments
@output_options
@pipeline_options
@click.option("--print0", "print0", is_flag=True,
              help="End each command with a NUL byte instead of a newline, for 'xargs -0' (any file name).")
@click.option("--json", "as_json", is_flag=True,
              help="Print a JSON list of {input, output, name, argv} instead, for tools that take one.")
@verbosity_options
@fail_cleanly
def plan(in_dir: Path, out_dir: Path, pattern: str, overwrite: bool, print0: bool, as_json: bool, **options) -> None:
    """Print one self-contained 'exaggerate' command per clip under IN_DIR, for a farm's job list.

    Each line converts one clip into the place 'batch' would put it, with the
    options given here (paths made absolute, quoted for the shell); feed the
    lines to Deadline, OpenCue, a Slurm array or xargs. Nothing is converted
    or written. A clip whose path holds a line break cannot be one line: it is
    left out with a warning unless --print0 or --json is given; one whose name
    has control characters, which no output may have, is left out of all three.

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
    batch_options(options, overwrite=overwrite, resume=False)  # a bad setting is refused here, not on the farm
    clips, problems = find_batch_clips(in_dir, out_dir, pattern)
    for problem in problems:
        log.warning("%s: %s", problem.input, problem.error)
    given = given_options(click.get_current_context(), exclude={"pattern", "print0", "as_json"})
    from mocap_exaggerate.core.errors import ConfigError
    from mocap_exaggerate.jobs.job import check_name

    jobs = []
    for clip in clips:
        try:
            check_name(clip.name)
        except ConfigError as error:  # (its command would only be refused on the farm)
            log.warning("%s: %s; left out (rename it)", clip.source, error)
            continue
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
            emit(shlex.join(job["argv"]) + ("\0" if print0 else ""), nl=not print0)
