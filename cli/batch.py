"""``mocap-exaggerate batch``: every clip under a folder, mirrored into another; and how a run of
several clips is set up and reported (``exaggerate`` with several files uses it too)."""

from __future__ import annotations

import dataclasses
import logging
from pathlib import Path
from typing import Any

import click

from mocap_exaggerate.core.errors import MocapError

from .app import UserError, cli, fail_cleanly, quiet, shown, verbosity_options
from .options import config_from_options, folder_arguments, given_options, joint_map_of, output_options, pipeline_options

__all__ = ["batch", "batch_options", "run_reported", "find_batch_clips"]

log = logging.getLogger("mocap_exaggerate")


def batch_options(options: dict[str, Any], *, overwrite: bool, resume: bool):
    """The `BatchOptions` the options given make, checked once (a bad unit, skin or joint map
    would fail every clip alike): the config resolved, its files' paths made absolute (workers
    may run elsewhere: a Dask cluster)."""
    from mocap_exaggerate.io.skin import load_skin
    from mocap_exaggerate.jobs.batch import BatchOptions

    preset, config = config_from_options(options)
    settings = config.glb
    joint_map_of(config)  # read once: a bad line is said before any clip runs
    if settings.skin and settings.enabled:
        load_skin(settings.skin)  # parsed once: the digest and the clips run here reuse it

    def absolute(path: str) -> str:
        return str(Path(path).resolve()) if path else ""

    glb = dataclasses.replace(settings, skin=absolute(settings.skin), joint_map=absolute(settings.joint_map))
    config_file = options.get("config_file")
    return BatchOptions(dataclasses.replace(config, glb=glb), preset=preset, overwrite=overwrite, resume=resume,
                        protect=(absolute(str(config_file)),) if config_file is not None else ())


def run_reported(clips, out_dir: Path, options, *, jobs: int, as_json: bool, problems=(),
                 scheduler: str | None = None, settings: str = "") -> int:
    """Run a batch with progress and a summary (and the report page when the options ask for it);
    the exit code (0 all done, 1 some failed, 130 interrupted)."""
    import time

    from mocap_exaggerate.jobs.batch import BatchInterrupted, run_batch

    from .report import OutputClosed, Progress, summary

    is_quiet = quiet()
    progress = Progress(len(clips) + len(problems), quiet=is_quiet, as_json=as_json)
    started = time.perf_counter()
    if scheduler is None:
        workers: int | str = min(jobs, max(len(clips), 1))
    else:
        workers = f"a local Dask cluster of {jobs} worker(s)" if scheduler == "local" else f"Dask at {scheduler}"
    pending, reason = [], None
    try:
        for problem in problems:
            progress(problem)
        results = run_batch(clips, out_dir, options, jobs=jobs, on_result=progress, scheduler=scheduler)
    except OutputClosed:  # (while the files met on the way were said: no clip has begun)
        results, pending = [], list(clips)
    except BatchInterrupted as stop:
        results, pending, reason = stop.results, stop.pending, stop.reason
    finally:
        progress.close()
    if progress.closed:
        reason = "standard output closed (the reader of --json went away)"
    if reason:
        log.error("%s; %d file(s) not done (--resume finishes them)", reason, len(pending))
    results = list(problems) + results
    report = None
    if options.report:
        from mocap_exaggerate.viz.report import write_report

        try:
            report = str(write_report(out_dir, results, pending=pending, title=f"Batch report: {out_dir}",
                                      settings=settings))
        except OSError as error:
            log.error("%s: the report could not be written: %s", out_dir / "index.html", error.strerror or error)
    summary(results, time.perf_counter() - started, workers=workers, pending=len(pending), quiet=is_quiet,
            report=report)
    if pending:
        return 1 if reason else 130
    return 1 if any(r.status == "failed" for r in results) else 0


def find_batch_clips(in_dir: Path, out_dir: Path, pattern: str):
    """The clips a batch or plan takes, and what was met on the way; a usage error when none match."""
    from mocap_exaggerate.jobs.batch import check_folders, find_clips

    check_folders(in_dir, out_dir, pattern)
    clips, problems = find_clips(in_dir, pattern, exclude=[out_dir])
    if not clips:
        for problem in problems:  # -v: what was met on the way; the error is that nothing matched
            log.info("%s: %s", problem.input, problem.error)
        raise UserError(f"{in_dir}: no file matches {shown(pattern)} (see --glob)")
    return clips, problems


def _writable(folder: Path) -> None:
    """Make ``folder`` and check a file can be written there, before any clip is worked on."""
    import tempfile

    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as error:
        raise UserError(f"{folder}: cannot write there ({error.strerror or error})") from None


@cli.command()
@folder_arguments
@click.option("-j", "--jobs", type=click.IntRange(1, 512), default=None,
              help="Worker processes, 1 to 512 (default: one per core).")
@click.option("--resume", is_flag=True,
              help="Keep clips whose outputs are complete and made from the same input and options; redo the rest.")
@click.option("--json", "as_json", is_flag=True,
              help="Print one JSON line per file on stdout (input, outputs, status, frames, seconds, "
                   "max_link_stretch, error).")
@click.option("--report", "write_report", is_flag=True,
              help="Also write OUT_DIR/index.html: each clip's poses and its fastest end effector's path, captured "
                   "and exaggerated, with its figures and links (the pictures go under OUT_DIR/report/).")
@click.option("--scheduler", metavar="ADDRESS", default=None,
              help="Run the clips on Dask distributed: 'local' (a LocalCluster of -j workers) or a scheduler "
                   "address such as tcp://host:8786 (the folders must be at the same paths on its workers). "
                   "Needs the dask extra (from a checkout: pip install '.[dask]').")
@output_options
@pipeline_options
@verbosity_options
@fail_cleanly
def batch(in_dir: Path, out_dir: Path, pattern: str, jobs: int | None, resume: bool, as_json: bool,
          write_report: bool, scheduler: str | None, overwrite: bool, **options) -> None:
    """Exaggerate every clip under IN_DIR into OUT_DIR, mirroring its folders.

    A bad file is reported and the rest go on; exit 0 when every file was
    converted (or kept by --resume), 1 when some failed, 2 for a usage
    mistake, 130 when stopped with Ctrl-C (clips being converted finish).

    \b
    Examples:
      mocap-exaggerate batch mocap/ out/ --preset looney -j 2
      mocap-exaggerate batch mocap/ out/ --resume --json > results.jsonl
      mocap-exaggerate batch mocap/ out/ --glob 'walk*/**/*.bvh' --no-glb
      mocap-exaggerate batch mocap/ out/ --report        (then open out/index.html)
      mocap-exaggerate batch /shared/mocap /shared/out --scheduler tcp://farm:8786
    """
    import shlex

    from mocap_exaggerate.jobs.batch import check_scheduler, default_jobs

    run_options = dataclasses.replace(batch_options(options, overwrite=overwrite, resume=resume), report=write_report)
    if scheduler is not None:
        if scheduler != "local" and jobs is not None:
            raise UserError("-j sets the size of --scheduler local; a Dask scheduler has the workers it has")
        check_scheduler(scheduler)  # imports Dask, which logs its own way: said with -vv (we say what matters)
        verbose = click.get_current_context().find_root().meta.get("mocap_exaggerate.verbosity", {}).get("verbose", 0)
        _dask_logs(logging.INFO if verbose >= 2 else logging.CRITICAL)
    clips, problems = find_batch_clips(in_dir, out_dir, pattern)
    created = not out_dir.exists()
    _writable(out_dir)
    try:
        if write_report:
            from mocap_exaggerate.viz.report import check_report

            check_report(out_dir)
        given = given_options(click.get_current_context(), exclude=set())
        settings = shlex.join(["mocap-exaggerate", "batch", str(in_dir), str(out_dir), *given])
        code = run_reported(clips, out_dir, run_options, jobs=jobs or default_jobs(), as_json=as_json,
                            problems=problems, scheduler=scheduler, settings=settings)
    except (UserError, MocapError):  # refused before any clip ran: leave no empty folder of ours behind
        if created:
            try:
                out_dir.rmdir()
            except OSError:
                pass
        raise
    if code:
        click.get_current_context().exit(code)


def _dask_logs(level: int) -> None:
    """Dask's loggers, and those of tornado, its event loop, at ``level``: each of its own (Dask's config sets
    some, ``distributed.client`` at warning) as well as the parents. Dask logged a lost scheduler as a traceback
    of its reconnecting; the batch says it in one line (-vv shows Dask's lines)."""
    names = [name for name in logging.root.manager.loggerDict if name.split(".")[0] in ("distributed", "tornado")]
    for name in {"distributed", "tornado", *names}:
        logging.getLogger(name).setLevel(level)
