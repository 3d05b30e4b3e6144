"""The command group and how every command reports: one line per error, an exit code that says whose.

Exit codes: 0 done; 1 a file could not be read or written for a reason outside the
options (or some of several clips failed); 2 bad input, a bad option or a refusal;
3 an internal error (a bug: one line saying so, the traceback with ``-vv``). Every
path ends here: the commands' bodies, the option callbacks and click's own parsing.
"""

from __future__ import annotations

import errno
import functools
import logging
import re
import sys
from collections.abc import Callable
from typing import Any

import click

# Only light modules at import time: `--help` must not wait for SciPy, trimesh or pygltflib.
from mocap_exaggerate import __version__
from mocap_exaggerate.core.errors import MocapError, printable
from mocap_exaggerate.io.files import OutputExistsError

__all__ = ["cli", "UserError", "INTERNAL_ERROR", "fail_cleanly", "verbosity_options", "quiet", "shown", "one_line",
           "printable", "emit"]

log = logging.getLogger("mocap_exaggerate")

#: The exit code of an internal error: neither the input, the options nor the disk, but a bug.
INTERNAL_ERROR = 3
#: Characters of a usage error's message shown before it is cut short (click quotes a bad value whole).
_LONGEST_USAGE = 300
#: Characters of any other error's message shown before it is cut short.
_LONGEST_MESSAGE = 500
#: A run of digits past this many is shown as its first 20 and its length (a 309-digit integer says nothing more);
#: not one inside a name (after a letter, an underscore, a dot or a slash): a file is named as it is.
_LONG_NUMBER = re.compile(r"(?<![\w./\\])\d{40,}")


class UserError(click.ClickException):
    """A mistake in the input or the options: one line, exit code 2."""

    exit_code = 2


def fail_cleanly(func: Callable) -> Callable:
    """Turn library errors into one-line messages; never a traceback for a user mistake.

    Exit codes: 2 for bad input or settings (and refusals), 1 for a failed
    write or read the user did not cause by a setting. Anything else is a bug,
    reported by the group (`INTERNAL_ERROR`).
    """

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except OutputExistsError as error:
            raise UserError(f"{error}; pass --overwrite to replace it") from None
        except MocapError as error:
            raise UserError(str(error)) from None
        except BrokenPipeError:
            raise  # the reader went away (`| head`): click exits quietly
        except OSError as error:
            where = f"{error.filename}: " if getattr(error, "filename", None) else ""
            if error.errno == errno.ENAMETOOLONG:  # a path given in an option: the user's to shorten
                raise UserError(f"{where}{error.strerror}") from None
            raise click.ClickException(f"{where}{error.strerror or error}") from None

    return wrapper


def shown(text: str, most: int = 80) -> str:
    """``text`` quoted for a message, cut short when it is long."""
    return repr(text) if len(text) <= most else repr(text[:most]) + f"... ({len(text)} characters)"


def emit(text: str, *, nl: bool = True) -> None:
    """Write ``text`` to standard output for another program (a job list, a command to run): piped, its
    bytes exactly (click's echo would strip what looks like a terminal's escape sequence, and a clip
    named with one would become another clip's command); on a terminal, its control characters escaped
    (`printable`), so a name cannot drive the terminal."""
    shown_text = printable(text, keep=" \0") if click.get_text_stream("stdout").isatty() else text
    click.echo(shown_text, nl=nl, color=True)


def one_line(message: str, most: int = _LONGEST_MESSAGE) -> str:
    """``message`` as one printable line: line breaks, control characters and undecodable bytes
    escaped as Python writes them (``\\n``, ``\\udcff``), cut short past ``most`` characters."""
    text = _LONG_NUMBER.sub(lambda m: f"{m.group(0)[:20]}... ({len(m.group(0))} digits)", printable(message))
    return text if len(text) <= most else f"{text[:most]}... ({len(text)} characters)"


class _Printable(logging.Formatter):
    """Log lines one to a line, escaped (`printable`): a warning quoting a name shows it, not obeys it."""

    def format(self, record: logging.LogRecord) -> str:
        text = super().format(record)
        head, _, tail = text.partition("\nTraceback")  # -vv's traceback keeps its lines
        return printable(head) + (f"\nTraceback{tail}" if tail else "")


def _set_verbosity(ctx: click.Context, param: click.Parameter, value: Any) -> None:
    """``-v``/``-q`` may stand before or after the subcommand; both places add up."""
    root = ctx.find_root()
    state = root.meta.setdefault("mocap_exaggerate.verbosity", {"verbose": 0, "quiet": False})
    if param.name == "verbose":
        state["verbose"] += value or 0
    elif value:
        state["quiet"] = True
    level = logging.ERROR if state["quiet"] else (logging.WARNING, logging.INFO, logging.DEBUG)[min(state["verbose"], 2)]
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_Printable("%(levelname)s: %(message)s"))
    logging.basicConfig(level=level, handlers=[handler], force=True)


def verbosity_options(func: Callable) -> Callable:
    """``-v``/``-q``, read before the other options (eager), so that ``-vv`` also shows the
    traceback of an error in another option's callback."""
    func = click.option("-q", "--quiet", is_flag=True, expose_value=False, callback=_set_verbosity, is_eager=True,
                        help="Only errors on stderr.")(func)
    return click.option("-v", "--verbose", count=True, expose_value=False, callback=_set_verbosity, is_eager=True,
                        help="More detail on stderr (-vv for debugging).")(func)


def quiet() -> bool:
    """Whether ``-q`` was given (before or after the subcommand)."""
    ctx = click.get_current_context(silent=True)
    return bool(ctx and ctx.find_root().meta.get("mocap_exaggerate.verbosity", {}).get("quiet"))


def _say(message: str, code: int) -> None:
    click.echo(f"Error: {message}", err=True)
    sys.exit(code)


class _Commands(click.Group):
    """click's group, with every error reported in one line: usage mistakes, the commands'
    refusals, and exceptions nobody expected (from a command, an option's callback or click)."""

    def main(self, *args: Any, **kwargs: Any) -> Any:
        standalone = kwargs.pop("standalone_mode", True)
        try:
            return super().main(*args, standalone_mode=False, **kwargs)
        except click.exceptions.UsageError as error:
            if not standalone:
                raise
            if type(error).__name__ == "NoArgsIsHelpError":  # bare command: the help is the answer
                error.show()
                sys.exit(error.exit_code)
            where = f" (see '{error.ctx.command_path} --help')" if error.ctx is not None else ""
            _say(one_line(error.format_message().rstrip("."), _LONGEST_USAGE) + where, error.exit_code)
        except click.ClickException as error:
            if not standalone:
                raise
            _say(one_line(error.format_message()), error.exit_code)
        except click.exceptions.Abort as error:
            if not standalone:
                raise
            click.echo("Aborted!", err=True)
            sys.exit(130 if isinstance(error.__cause__, KeyboardInterrupt) else 1)  # Ctrl-C: as a shell says it
        except Exception as error:  # a bug: said in one line; the traceback is for -vv
            if not standalone:
                raise
            log.debug("the internal error's traceback:", exc_info=error)
            what = one_line(f"{type(error).__name__}: {error}" if str(error) else type(error).__name__, 200)
            _say(f"internal error ({what}): a bug in mocap-exaggerate, not a mistake in the input or the options; "
                 f"-vv shows the traceback (please report it)", INTERNAL_ERROR)


@click.group(cls=_Commands, context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(__version__, prog_name="mocap-exaggerate")
@verbosity_options
def cli() -> None:
    """Turn motion capture (BVH) into cartoon-style motion.

    \b
    Example:
      mocap-exaggerate exaggerate sample_data/cmu_09_01_run_daz.bvh -o out/ --sigma 0.2s --omega 5
      mocap-exaggerate info sample_data/cmu_09_01_run_daz.bvh --limbs
    """
