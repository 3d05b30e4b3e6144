"""How the command line tells the user about many files: progress, one line per file, a summary.

On a terminal, a progress bar (files done, frames/s, time left) with failures
printed above it as they happen; otherwise one plain line per file, which a
log file or a farm's console keeps. ``--json`` adds one JSON line per file on
stdout. Only reporting lives here; the work is `mocap_exaggerate.jobs.batch`.
"""

from __future__ import annotations

import logging
import os
import sys
import time
from typing import TextIO

import click

from mocap_exaggerate.core.errors import printable
from mocap_exaggerate.jobs.batch import FileResult

log = logging.getLogger("mocap_exaggerate")


def _terminal_width(stream: TextIO) -> int:
    """Columns of the terminal ``stream`` writes to; 0 when it is not one (a file, a pipe, a sizeless pty)."""
    try:
        size = os.get_terminal_size(stream.fileno()) if stream.isatty() else None
        return size.columns if size is not None and size.lines > 0 else 0
    except (OSError, ValueError, AttributeError):
        return 0


def _said(result: FileResult) -> str:
    """The error without the file name repeated ("a.bvh:3: ..." already names it)."""
    error = result.error or ""
    return error if error.startswith(result.input) else f"{result.input}: {error}"


def _echo(line: str, stream: TextIO) -> None:
    """A line about files, their names' control characters escaped (`printable`): a clip named with a
    terminal's escape sequence, or a newline, is shown, not obeyed."""
    click.echo(printable(line), file=stream)


class OutputClosed(KeyboardInterrupt):
    """The reader of ``--json`` went away (``| head``): the batch stops as Ctrl-C stops it (the clips being
    converted finish, no more start), and says so."""


class Progress:
    """Called with each `FileResult` as it finishes."""

    def __init__(self, total: int, *, quiet: bool = False, as_json: bool = False, stream: TextIO | None = None,
                 bar: bool | None = None) -> None:
        self.total, self.quiet, self.as_json = total, quiet, as_json
        self.stream = stream or sys.stderr
        self.count = 0
        self.frames = 0
        self.closed = False  # standard output went away (`OutputClosed`)
        self.started = time.perf_counter()
        use_bar = bar if bar is not None else (not quiet and total > 1 and _terminal_width(self.stream) >= 40)
        self.bar = None
        if use_bar:
            from tqdm import tqdm

            self.bar = tqdm(total=total, unit="file", file=self.stream, dynamic_ncols=True, leave=True,
                            bar_format="{l_bar}{bar}| {n_fmt}/{total_fmt} files [{elapsed}<{remaining}{postfix}]")

    def __call__(self, result: FileResult) -> None:
        closed = self.closed
        if self.as_json and not closed:
            try:
                click.echo(result.to_json())  # stdout: one line per file, for farm tooling
            except BrokenPipeError:
                self.closed = True
                nothing = os.open(os.devnull, os.O_WRONLY)
                os.dup2(nothing, sys.stdout.fileno())  # (nothing more to say there)
                os.close(nothing)
        try:
            self._say(result)
        finally:
            if self.closed and not closed:
                raise OutputClosed

    def _say(self, result: FileResult) -> None:
        self.count += 1
        if result.status == "converted":
            self.frames += result.frames or 0
        said = [f"warning: {result.input}: {w}" for w in result.warnings if log.isEnabledFor(logging.WARNING)]
        said += [f"{result.input}: {n}" for n in result.notes if log.isEnabledFor(logging.INFO)]
        for line in said:
            if self.bar is not None:
                self.bar.write(printable(line), file=self.stream)
            else:
                _echo(line, self.stream)
        if self.bar is not None:
            if result.status == "failed":
                self.bar.write(printable(f"failed: {_said(result)}"), file=self.stream)
            elapsed = max(time.perf_counter() - self.started, 1e-9)
            self.bar.set_postfix_str(f"{self.frames / elapsed:,.0f} frames/s", refresh=False)
            self.bar.update(1)
            return
        if self.quiet:  # the summary lists the failures
            return
        if result.status == "failed":
            _echo(f"[{self.count}/{self.total}] failed: {_said(result)}", self.stream)
        else:
            detail = (f"{result.frames} frames, max link stretch {result.max_link_stretch:.2f}x, {result.seconds:.2f} s"
                      if result.status == "converted" else result.error)
            _echo(f"[{self.count}/{self.total}] {result.status} {result.input} ({detail})", self.stream)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


def summary(results: list[FileResult], seconds: float, *, workers: int | str, pending: int = 0,
            quiet: bool = False, stream: TextIO | None = None, report: str | None = None) -> None:
    """The table at the end: converted, skipped, failed (with reasons), frames, time.

    workers : how many worker processes ran, or what ran the clips (``Dask at tcp://...``)
    report : the report page written, if any
    """
    stream = stream or sys.stderr
    counts = {status: sum(r.status == status for r in results) for status in ("converted", "skipped", "failed")}
    frames = sum(r.frames or 0 for r in results if r.status == "converted")
    failed = [r for r in results if r.status == "failed"]
    if quiet:
        for result in failed:
            _echo(f"failed: {_said(result)}", stream)
        return
    files = len(results) + pending
    rate = f", {frames / seconds:,.0f} frames/s" if seconds > 0 and frames else ""
    engine = f"with {workers} worker(s)" if isinstance(workers, int) else f"on {workers}"
    click.echo("", file=stream)
    _echo(f"{files} file(s) in {seconds:.1f} s {engine}: {frames:,} frames converted{rate}", stream)
    click.echo(f"  converted  {counts['converted']:>6}", file=stream)
    click.echo(f"  skipped    {counts['skipped']:>6}", file=stream)
    click.echo(f"  failed     {counts['failed']:>6}", file=stream)
    if pending:
        click.echo(f"  not done   {pending:>6}  (interrupted: run again with --resume to finish them)", file=stream)
    skipped = [r for r in results if r.status == "skipped" and r.error and "complete" not in r.error]
    for result in skipped:
        _echo(f"skipped: {_said(result)}", stream)
    for result in failed:
        _echo(f"failed: {_said(result)}", stream)
    if report:
        _echo(f"report: {report}", stream)
