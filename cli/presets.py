"""``mocap-exaggerate presets``: the shipped presets and what they do."""

from __future__ import annotations

import click

from mocap_exaggerate.config import DEFAULT_PRESET, preset_description, preset_names

from .app import cli, verbosity_options


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
