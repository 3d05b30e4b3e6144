"""``mocap-exaggerate tune``: a page on localhost whose sliders re-run the clip as you move them."""

from __future__ import annotations

from pathlib import Path

import click

from .app import cli, fail_cleanly, printable, quiet, verbosity_options
from .options import FilePath, character_options, config_from_options, given_options, pipeline_options


@cli.command()
@click.argument("input_path", metavar="IN.bvh", type=FilePath(path_type=Path, dir_okay=False))
@click.option("--port", type=click.IntRange(0, 65535), default=0, show_default=True,
              help="Port on 127.0.0.1 to serve on (0: one that is free).")
@character_options
@pipeline_options
@verbosity_options
@fail_cleanly
@click.pass_context
def tune(ctx: click.Context, input_path: Path, port: int, **options) -> None:
    """Tune a clip in the browser: sliders for the preset, sigma, omega and the other settings re-run it.

    Serves a page on 127.0.0.1 (never the network) that plays the captured and the exaggerated
    body; each slider change re-runs the clip in memory and shows the new motion. 'copy command'
    gives the exact 'exaggerate' command (and 'copy TOML' the pipeline file) that writes what the
    page shows. The options given (a --skin, --fps, a --config) hold for every run. Ctrl-C stops it.

    \b
    Examples:
      mocap-exaggerate tune sample_data/cmu_09_01_run_daz.bvh
      mocap-exaggerate tune sample_data/cmu_09_01_run_daz.bvh --preset looney --port 8765
    """
    from click.core import ParameterSource

    from mocap_exaggerate.config import PipelineConfig
    from mocap_exaggerate.core.settings import flagged_settings
    from mocap_exaggerate.viz.preview import clip_and_character
    from mocap_exaggerate.viz.tune import TUNED, Tuner, bind_port, serve, slider_values

    from .options import run_options_command, setting_param

    preset, config = config_from_options(options)
    server = bind_port(port)  # the port first: a taken one is said before the clip is read
    # The clip, and the character it is tuned on (a glTF's own mesh where none is named), as a preview's.
    motion, skin, _ = clip_and_character(input_path, {}, config)
    # The options given, but the sliders' own (their values start the sliders; the command sets them with --set).
    tuned = {slider.key for slider in TUNED}
    sliders = {setting_param(block, key): f"{block}.{key}" for block, key, _ in flagged_settings(PipelineConfig)
               if f"{block}.{key}" in tuned}
    base = given_options(ctx, exclude={"preset", "port", "settings", *sliders})
    raw = ctx.meta.get("mocap_exaggerate.raw", {}).get("settings", [])
    base += [word for item in raw if item.partition("=")[0].strip() not in tuned for word in ("--set", item)]
    # The sliders' settings the command line gave: where they start, set in every run of the first preset.
    given = {key for name, key in sliders.items() if ctx.get_parameter_source(name) == ParameterSource.COMMANDLINE}
    given |= {item.partition("=")[0].strip() for item in raw} & tuned
    start = {key: value for key, value in slider_values(config, motion.frame_time).items() if key in given}
    command = run_options_command()

    def configure(name: str):
        return config_from_options(command.make_context("tune", ["--preset", name, *base]).params)[1]

    tuner = Tuner(str(input_path), motion, preset, configure, tuple(base), start, skin, config.glb.units)

    def ready(url: str) -> None:
        if not quiet():
            click.echo(printable(f"tuning {input_path} at {url} (Ctrl-C stops)"), err=True)

    serve(server, tuner, ready)
    if not quiet():
        click.echo("stopped", err=True)
