"""The options shared by the commands, how they are read, and the settings they make.

One set of option decorators is reused by ``exaggerate``, ``batch``, ``plan`` and
``preview``. The options that set a setting are not written here: each setting declares
its flag and help beside its default (`mocap_exaggerate.core.settings.Flag`), and
`setting_option` makes the option from that. Each value is checked in its callback or by
the config, before any file is looked at.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import click

from mocap_exaggerate.config import (
    DEFAULT_PRESET,
    PipelineConfig,
    config_preset,
    merge_tables,
    preset_names,
    read_config_text,
    resolve_config,
)
from mocap_exaggerate.core.settings import Flag, flagged_settings
from mocap_exaggerate.jobs.discovery import DEFAULT_GLOB

from .app import shown

__all__ = ["FilePath", "pipeline_options", "output_options", "character_options", "folder_arguments",
           "setting_option", "setting_param", "settings_given", "config_from_options", "given_options",
           "joint_map_of", "parsed_each", "parse_settings", "run_options_command",
           "picture_options"]


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


def parsed_one(parse: Callable[[str], Any]) -> Callable:
    """A callback for an option of one value: the value through ``parse`` (None stays None)."""
    each = parsed_each(parse)

    def callback(ctx, param, value: str | None):
        return None if value is None else each(ctx, param, (value,))[0]

    return callback


def parse_settings(ctx, param, values: tuple[str, ...]) -> dict[str, Any]:
    """``--set block.key=value`` pairs as a nested table (`settings_table`), their words kept."""
    _keep_raw(ctx, param, values)
    return settings_table(values)


def settings_table(values) -> dict[str, Any]:
    """``block.key=value`` pairs as a nested table: each value TOML (``3``, ``true``, ``[1, 2]``) or plain
    text (``0.2s``, ``looney``); the config checks the keys and values. ``click.BadParameter`` otherwise."""
    import tomllib

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


# ---------------------------------------------------------------------------- shared options


def setting_option(block: str, key: str, flag: Flag) -> Callable:
    """The click option a setting declares (`mocap_exaggerate.core.settings.Flag`).

    Its parameter is named ``block_key`` (`setting_param`); its value reaches the setting
    through `settings_given`. A choice is checked by click; every other value by the
    setting's own block, as a pipeline file's would be.
    """
    name = setting_param(block, key)
    if flag.sets is not None:  # a lone flag: --no-subjoints
        return click.option(flag.option, name, is_flag=True, default=False, help=flag.help)
    if "/" in flag.option:  # a switch: --correct/--no-correct
        return click.option(flag.option, name, default=None, help=flag.help)
    extra: dict[str, Any] = {}
    if flag.choices is not None:
        extra["type"] = click.Choice(list(flag.choices))
    elif flag.path:
        extra["type"] = FilePath(dir_okay=False, path_type=Path)
    elif flag.parse is not None:
        extra["callback"] = parsed_each(flag.parse) if flag.multiple else parsed_one(flag.parse)
    elif not flag.multiple:
        extra["type"] = _setting_type(block, key)
    return click.option(flag.option, name, default=None, multiple=flag.multiple, metavar=flag.metavar,
                        help=flag.help, **extra)


def setting_param(block: str, key: str) -> str:
    """The parameter name of the option that sets ``block.key`` (``extrapolate_sigma``; ``stretch`` for a list)."""
    return f"{block}_{key}" if block else key


def _setting_type(block: str, key: str) -> type | None:
    """The Python type a setting's field declares, when it is a plain number (for click to read it)."""
    import typing

    cls = next(f.default_factory for f in dataclasses.fields(PipelineConfig) if f.name == block)
    hint = typing.get_type_hints(cls)[key]
    return hint if hint in (int, float) else float if hint == float | None else None


#: The blocks in the order ``--help`` lists their options: the exaggeration first, how the
#: clip is read last, the GLB's with the other outputs (`output_options`).
_HELP_ORDER = ("extrapolate", "correct", "subjoints", "springs", "output", "", "auto_stretch", "contacts", "input")


def _declared(blocks: set[str]) -> list[tuple[str, str, Flag]]:
    found = [item for item in flagged_settings(PipelineConfig) if item[0] in blocks]
    return sorted(found, key=lambda item: _HELP_ORDER.index(item[0]) if item[0] in _HELP_ORDER else len(_HELP_ORDER))


def pipeline_options(func: Callable) -> Callable:
    """The options that set the pipeline, shared by every command that runs it: ``--preset``,
    ``--config``, every setting that declares a flag (but the GLB's, `output_options`) and ``--set``."""
    blocks = {block for block, _, _ in flagged_settings(PipelineConfig)} - {"glb"}
    options = [
        click.option("--preset", default=None, metavar="NAME",
                     help=f"Starting point: {', '.join(preset_names())} (default: the one the --config file names, "
                          f"else {DEFAULT_PRESET})."),
        click.option("--config", "config_file", type=FilePath(dir_okay=False, path_type=Path), default=None,
                     help="Pipeline TOML file (a run's OUT/<name>.pipeline.toml rebuilds that run, from any "
                          "folder); overrides the preset, overridden by flags."),
        *(setting_option(block, key, flag) for block, key, flag in _declared(blocks)),
        click.option("--set", "settings", multiple=True, callback=parse_settings, metavar="KEY=VALUE",
                     help="Any setting of a pipeline file by its key, e.g. extrapolate.max_speed=2 or "
                          "springs.blend=0.3 (docs/reference/config.md lists them); the value is read as TOML, "
                          "else as text. Repeatable; the flags above win over it."),
    ]
    for option in reversed(options):
        func = option(func)
    return func


def output_options(func: Callable) -> Callable:
    """What a conversion writes besides the BVH, shared by ``exaggerate``, ``batch`` and ``plan``:
    ``--overwrite`` and the ``[glb]`` block's flags (not given, the preset's or ``--config``'s hold)."""
    options = [click.option("--overwrite", is_flag=True, help="Replace outputs that exist already."),
               *(setting_option(block, key, flag) for block, key, flag in _declared({"glb"}))]
    for option in reversed(options):
        func = option(func)
    return func


def character_options(func: Callable) -> Callable:
    """``--skin`` and ``--joint-map`` alone (``preview`` draws the character but writes no GLB)."""
    for block, key, flag in reversed(_declared({"glb"})):
        if flag.path:
            func = setting_option(block, key, flag)(func)
    return func


def folder_arguments(func: Callable) -> Callable:
    """IN_DIR, OUT_DIR and --glob, shared by ``batch`` and ``plan``."""
    func = click.option("--glob", "pattern", default=DEFAULT_GLOB, show_default=True,
                        help="Which files under IN_DIR, by their path under it (case-insensitive; ** is any "
                             "folders).")(func)
    func = click.argument("out_dir", metavar="OUT_DIR", callback=folder_argument)(func)
    return click.argument("in_dir", metavar="IN_DIR", callback=folder_argument)(func)


def settings_given(p: dict[str, Any]) -> dict[str, Any]:
    """The settings the options given set, as nested tables: ``--set`` first, the flags over it.

    A command without one of the options (``preview`` writes no GLB) leaves its setting alone;
    lists the flags add to (``--stretch``) are not here (`config_from_options` adds them).
    """
    flags: dict[str, dict[str, Any]] = {}
    for block, key, flag in flagged_settings(PipelineConfig):
        value = p.get(setting_param(block, key))
        if flag.adds or value is None or value == () or (flag.sets is not None and not value):
            continue
        if flag.sets is not None:
            value = flag.sets
        elif isinstance(flag.choices, Mapping):
            value = flag.choices[value]
        elif flag.path:
            value = str(value)
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
    config = resolve_config(preset, text, settings_given(p), config_source=source,
                            config_folder=config_file.parent if config_file is not None else None)
    for block, key, flag in flagged_settings(PipelineConfig):
        if flag.adds and p.get(setting_param(block, key)):
            config = dataclasses.replace(config, **{key: getattr(config, key) + p[setting_param(block, key)]})
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


def run_options_command() -> click.Command:
    """A command of a run's options alone (`pipeline_options` and `character_options`), as ``exaggerate``
    reads them: ``compare`` parses each cell's words with it, ``tune`` each preset's."""
    @click.command()
    @pipeline_options
    @character_options
    def run_options(**options) -> None:
        """A run's options."""

    return run_options


def picture_options(func: Callable) -> Callable:
    """``--start``, ``--seconds`` and ``--overwrite``, shared by ``preview`` and ``compare``."""
    for option in reversed([
            click.option("--start", type=click.FloatRange(min=0.0), default=0.0, show_default=True, metavar="SECONDS",
                         help="Show the motion from this many seconds in."),
            click.option("--seconds", type=click.FloatRange(min=0.0, min_open=True), default=None, metavar="SECONDS",
                         help="Show this many seconds [default: all; an animation stops at 10]."),
            click.option("--overwrite", is_flag=True, help="Replace the file if it exists.")]):
        func = option(func)
    return func
