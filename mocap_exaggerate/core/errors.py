"""Errors the library raises for bad input or bad settings.

Each carries a one-line message that names the file (and line) or the
setting at fault, so the command line can print it as it is.
"""

from __future__ import annotations

__all__ = ["MocapError", "InputError", "ConfigError", "check_number", "check_flag", "check_choice", "printable"]


class MocapError(Exception):
    """Base of the errors a user can cause and fix."""


def printable(text: str, keep: str = " ") -> str:
    """``text`` with control characters (a terminal's escape sequences) and undecodable bytes escaped as
    Python writes them (``\\x1b``, ``\\udcff``): a joint or file name cannot drive what shows it."""
    return "".join(c if c.isprintable() or c in keep else repr(c)[1:-1] for c in str(text))


class InputError(MocapError, ValueError):
    """An input file is malformed. ``str()`` gives ``file:line: what is wrong``."""

    def __init__(self, message: str, *, source: str = "<input>", line: int | None = None) -> None:
        self.message = message
        self.source = source
        self.line = line
        where = f"{source}:{line}" if line is not None else source
        super().__init__(f"{where}: {message}")


class ConfigError(MocapError, ValueError):
    """A setting is invalid. The message names the setting."""


def check_number(where: str, value: object, low: float, high: float, *, low_open: bool = False) -> None:
    """Raise a ConfigError naming ``where`` unless ``value`` is a finite number in the range.

    The range is ``[low, high]``, or ``(low, high]`` with ``low_open``.
    """
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if number and value == value and (low < value if low_open else low <= value) and value <= high:
        return
    bracket = "(" if low_open else "["
    raise ConfigError(f"{where} must be a number in {bracket}{low:g}, {high:g}], got {value!r}")


def check_flag(where: str, value: object) -> None:
    """Raise a ConfigError naming ``where`` unless ``value`` is true or false."""
    if not isinstance(value, bool):
        raise ConfigError(f"{where} must be true or false, got {value!r}")


def check_choice(where: str, value: object, choices: tuple[str, ...], *, error=None) -> str:
    """``value`` if it is one of ``choices``, else an error naming ``where`` and the choices.

    error : makes the exception from the message (default `ConfigError`), for the few places
        that raise another kind (the reader's `InputError`, a programmer's `ValueError`)

    >>> check_choice("input.up", "w", ("auto", "x", "y", "z"))
    Traceback (most recent call last):
    mocap_exaggerate.core.errors.ConfigError: input.up must be one of auto, x, y, z, got 'w'
    """
    try:
        if value in choices:
            return value
    except TypeError:  # an unhashable or odd value is simply not one of them
        pass
    message = f"{where} must be one of {', '.join(choices)}, got {value!r:.60}"
    raise (error or ConfigError)(message)

