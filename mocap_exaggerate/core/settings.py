"""How a setting is declared: its default, its TOML key, and its command-line flag, in one place.

Every block's settings are a frozen dataclass (`mocap_exaggerate.config`); a field
is a setting, its name the TOML key. A field made with `setting` can also carry
a `Flag`: the option that sets it from the command line, with its help; the TOML
reader and writer take each value by the field's declared type. The CLI
builds its options from these declarations (`mocap_exaggerate_cli.options`), and
the settings reference lists them (`mocap_exaggerate_cli.reference`), so a new
setting with a flag is one field, and nothing about it is written twice.

This module holds plain data only: it knows nothing of click.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

__all__ = ["Flag", "setting", "flag_of", "flagged_settings"]


@dataclass(frozen=True)
class Flag:
    """The command-line option that sets one setting.

    option : its name: ``--sigma``; a switch ``--correct/--no-correct``; a lone
        ``--no-subjoints`` (which sets ``sets``)
    help : one or two sentences for ``--help``
    metavar : the value's placeholder in ``--help`` (default: from the type)
    choices : the words it takes; a mapping gives each word's setting value
        (``--contacts auto`` sets ``enabled = true``)
    parse : one word to the setting's value (raises `MocapError`), when the word is
        not the value itself (``--stretch LIMB:A-B:S``)
    multiple : repeatable; the values given are a tuple
    path : the value is a file's path
    sets : for a lone flag, the value it sets when given
    adds : its values are added to the list the preset and ``--config`` give, rather
        than replacing it
    """

    option: str
    help: str
    metavar: str | None = None
    choices: tuple[str, ...] | Mapping[str, Any] | None = None
    parse: Callable[[str], Any] | None = None
    multiple: bool = False
    path: bool = False
    sets: Any = None
    adds: bool = False


def setting(default: Any = dataclasses.MISSING, *, flag: Flag | None = None, table: bool = False,
            default_factory: Any = dataclasses.MISSING) -> Any:
    """A dataclass field that is a setting, with the flag that sets it (or none).

    table : the value, ``(name, number)`` pairs, is a TOML table of ``name = number``
        (``[extrapolate.weights]``) rather than an array
    """
    metadata = {"flag": flag} if flag else {}
    if table:
        metadata["table"] = True
    return field(default=default, default_factory=default_factory, metadata=metadata)


def flag_of(item: dataclasses.Field) -> Flag | None:
    """The `Flag` a field declares, or None."""
    return item.metadata.get("flag")


def flagged_settings(config: type) -> Iterator[tuple[str, str, Flag]]:
    """``(block, key, flag)`` for every setting with a flag in a config of blocks, in declaration order.

    A field of ``config`` that is itself a dataclass is a block (``extrapolate``) and its
    fields its keys; any other field of ``config`` with a flag is a top-level list
    (``stretch``), given as ``("", key, flag)``.
    """
    for block in dataclasses.fields(config):
        flag = flag_of(block)
        if flag is not None:
            yield "", block.name, flag
            continue
        kind = block.default_factory if block.default_factory is not dataclasses.MISSING else None
        if kind is None or not dataclasses.is_dataclass(kind):
            continue
        for item in dataclasses.fields(kind):
            flag = flag_of(item)
            if flag is not None:
                yield block.name, item.name, flag
