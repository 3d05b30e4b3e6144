"""``mocap-exaggerate compare``: one clip with lists of settings, drawn side by side in one grid."""

from __future__ import annotations

import itertools
import shlex
import sys
from pathlib import Path

import click

from mocap_exaggerate.core.errors import MocapError

from .app import UserError, cli, emit, fail_cleanly, printable, quiet, shown, verbosity_options
from .options import FilePath, config_from_options, picture_options, run_options_command

#: The options of a run, as ``exaggerate`` reads them: each cell's words are parsed by this command.
_settings = run_options_command()


def _one_value() -> set[str]:
    """The parameters that say how the clip is read and which character draws it (the ``input`` and ``glb``
    blocks, ``--config``): every cell shares them, so they take one value."""
    from mocap_exaggerate.config import PipelineConfig
    from mocap_exaggerate.core.settings import flagged_settings

    from .options import setting_param

    return {"config_file"} | {setting_param(block, key) for block, key, _ in flagged_settings(PipelineConfig)
                              if block in ("input", "glb")}


_ONE_VALUE = _one_value()


def _as_list(param: click.Option) -> click.Option:
    """``param`` for ``compare``: a flag as it is; an option of one value taking a comma-separated list of
    them (read as text: each value is checked when its cell's words are parsed); a repeatable one as text."""
    if param.is_flag:
        return param
    help_text = param.help or ""
    if not param.multiple and param.name not in _ONE_VALUE:
        help_text += " Comma-separated values compare each."
    return click.Option([*param.opts, param.name], type=str, multiple=param.multiple, default=None,
                        metavar=param.metavar, help=help_text)


def _words(param: click.Option, value) -> list[str]:
    """The command line words that give ``param`` its ``value`` (nothing where it was not given)."""
    if param.is_flag:
        if value is None or (value is False and not param.secondary_opts):
            return []
        return [param.opts[0]] if value else [param.secondary_opts[0]]
    if param.multiple:
        return [word for item in value or () for word in (param.opts[-1], item)]
    return [] if value is None else [param.opts[-1], value]


def _listed(text: str, option: str) -> list[str]:
    values = [part.strip() for part in text.split(",")]
    if any(not part for part in values):
        raise UserError(f"{option} {shown(text)}: an empty value in the list")
    return list(dict.fromkeys(values))


def cells_of(options: dict) -> tuple[list, int, list[str]]:
    """The cells (`mocap_exaggerate.viz.compare.Cell`) the options' lists make, the grid's columns (the last
    list's length) and the words every cell shares."""
    from mocap_exaggerate.viz.compare import MAX_CELLS, Cell

    fixed: list[str] = []
    lists: list[tuple[click.Option, list[str]]] = []
    for param in _settings.params:
        value = options.get(param.name)
        if isinstance(param, click.Option) and not param.is_flag and not param.multiple and value is not None:
            lists.append((param, _listed(value, param.opts[-1])))
        elif isinstance(param, click.Option):
            fixed += _words(param, value)
    varying = [(param, values) for param, values in lists if len(values) > 1]
    for param, values in varying:  # one clip, read one way, one character: what every cell is drawn from
        if param.name in _ONE_VALUE:
            raise UserError(f"{param.opts[-1]} {shown(','.join(values))}: compare runs one clip, read one way, with "
                            f"one character; give {param.opts[-1]} one value (and compare the settings of the run)")
    fixed += [word for param, values in lists if len(values) == 1 for word in (param.opts[-1], values[0])]
    if not varying:
        repeated = [f"{param.opts[-1]} {shown(str(options.get(param.name)))}" for param, values in lists
                    if "," in str(options.get(param.name))]  # (a list of one value said again: 2,2)
        said = f"{', '.join(repeated)} gives one value; " if repeated else ""
        raise UserError(f"nothing to compare: {said}give an option a comma-separated list of different values, "
                        "e.g. --omega 2,4,6 or --preset subtle,cartoon,looney")
    count = 1
    for _, values in varying:
        count *= len(values)
    if count > MAX_CELLS:
        raise UserError(f"{count} settings to compare; at most {MAX_CELLS} (each is a run of the pipeline)")
    cells = []
    for combination in itertools.product(*(values for _, values in varying)):
        words = [word for (param, _), value in zip(varying, combination) for word in (param.opts[-1], value)]
        argv = words + fixed
        try:
            context = _settings.make_context("compare", list(argv))
        except click.UsageError as error:
            raise UserError(f"{' '.join(words)}: {error.format_message()}") from None
        try:
            _, config = config_from_options(context.params)
        except MocapError as error:  # the cell's words named: which value of which list
            raise UserError(f"{' '.join(words)}: {error}") from None
        label = ", ".join(f"{param.opts[-1].lstrip('-')} {value}" for (param, _), value in zip(varying, combination))
        cells.append(Cell(label, tuple(argv), config))
    return cells, len(varying[-1][1]), fixed


def _compare_options(func):
    """The run's options (`_settings`) on ``compare``, as `_as_list` makes them (click's own way of adding
    a parameter: the command reads ``__click_params__`` in reverse)."""
    params = func.__dict__.setdefault("__click_params__", [])
    for param in reversed([p for p in _settings.params if isinstance(p, click.Option)]):
        params.append(_as_list(param))
    return func


@cli.command()
@click.argument("input_path", metavar="IN.bvh", type=FilePath(path_type=Path, allow_dash=True))
@click.option("-o", "--output", required=True, type=FilePath(path_type=Path),
              help="File to write: .png (still frames), .gif or .mp4 (animated; .mp4 needs ffmpeg) or .html (a page).")
@click.option("--frames", "count", type=click.IntRange(1, 8), default=3, show_default=True,
              help="How many evenly spaced frames each cell of a .png shows.")
@picture_options
@_compare_options
@verbosity_options
@fail_cleanly
def compare(input_path: Path, output: Path, count: int, start: float, seconds: float | None, overwrite: bool,
            **options) -> None:
    """Run one clip with lists of settings and draw every run side by side, the captured motion first.

    Any option of 'exaggerate' that takes one value takes a comma-separated list here; every
    combination is run in memory (no files per run) and drawn in one grid, one camera and one
    scale for all, each run labelled with its settings and figures (its longest limb over its
    rest length, its jerk over the capture's, how much the speed limit took). Then the command
    line of each run is printed.

    \b
    Examples:
      mocap-exaggerate compare sample_data/cmu_09_01_run_daz.bvh -o grid.png --sigma 0.1s,0.2s,0.3s --omega 2,4,6
      mocap-exaggerate compare sample_data/cmu_09_01_run_daz.bvh -o presets.gif --preset subtle,cartoon,looney
      mocap-exaggerate compare sample_data/cmu_09_01_run_daz.bvh -o omega.html --omega 2,5,8
    """
    from mocap_exaggerate.viz.compare import write_compare

    cells, columns, _ = cells_of(options)
    from_stdin = str(input_path) == "-"
    _, ran = write_compare(sys.stdin.buffer if from_stdin else input_path, output, cells, columns=columns,
                           frames=count, start=start, seconds=seconds, overwrite=overwrite,
                           label="<stdin>" if from_stdin else None,
                           protect=(options["config_file"],) if options.get("config_file") is not None else ())
    if not quiet():
        click.echo(printable(f"wrote {output}"), err=True)
    clip = "-" if from_stdin else str(input_path)
    for r in ran:
        f = r.figures
        emit(f"# {r.cell.label}: stretch {f['stretch']}, jerk {f['jerk']}, speed limit took {f['limit']}")
        emit(shlex.join(["mocap-exaggerate", "exaggerate", clip, "-o", "out", *r.cell.words]))
