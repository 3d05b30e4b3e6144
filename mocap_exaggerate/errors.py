"""Errors the library raises for bad input or bad settings.

Each carries a one-line message that names the file (and line) or the
setting at fault, so the command line can print it as it is.
"""

from __future__ import annotations

__all__ = ["MocapError", "InputError", "ConfigError"]


class MocapError(Exception):
    """Base of the errors a user can cause and fix."""


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
