"""Whole folders of clips: find them, convert each in a worker process, resume, report per file.

`find_clips` walks a folder for clips; `run_batch` converts them with `convert`
(in this process, in a pool of worker processes that pay the imports once, or
on Dask) and hands each file's `FileResult` to a callback as it finishes; a
farm task calls `convert_file` on one clip. Nothing here stops at a bad file: it
is reported (status ``failed`` with the reason) and the rest go on. Every
output set is written the way `convert` writes it (temporary files renamed into
place, the manifest last), so a killed run leaves no half-written file, and
``resume`` redoes only the clips whose output set is not complete for the same
input bytes and the same parameters.

This module is the batch's public face: `run_batch`, and the names of the
modules it is made of, each holding one part:

- `batch_types`: the data (`Clip`, `BatchOptions`, `FileResult`, `BatchInterrupted`)
- `discovery`: finding the clips (`find_clips`, `glob_regex`, `check_folders`, `is_output`)
- `resume`: which outputs can be kept (`is_complete`)
- `task`: one clip, never raising (`convert_file`)
- `pool`: the executors on this machine (`run_serial`, `run_pool`)
- `on_dask`: the executor on Dask distributed (`run_on_dask`, `connect_dask`)

Example::

    from mocap_exaggerate import load_preset
    from mocap_exaggerate.jobs.batch import BatchOptions, find_clips, run_batch

    clips, problems = find_clips("mocap/")
    results = run_batch(clips, "out/", BatchOptions(load_preset("cartoon")), jobs=2)
    [r.input for r in results if r.status == "failed"]
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from ..core.errors import ConfigError
from .batch_types import BatchInterrupted, BatchOptions, Clip, FileResult
from .discovery import DEFAULT_GLOB, check_folders, clashes, find_clips, foreign_clips, glob_regex, is_output, same_outputs
from .on_dask import WAIT_FOR_WORKERS, SchedulerLost, check_scheduler, connect_dask, run_on_dask
from .pool import default_jobs, run_pool, run_serial
from .resume import batch_parameters, is_complete
from .task import convert_file

__all__ = ["Clip", "BatchOptions", "FileResult", "BatchInterrupted", "find_clips", "glob_regex", "convert_file",
           "run_batch", "run_on_dask", "connect_dask", "check_scheduler", "is_complete", "is_output", "same_outputs",
           "check_folders", "clashes", "default_jobs", "DEFAULT_GLOB", "WAIT_FOR_WORKERS"]


def run_batch(clips: list[Clip], out_dir: str | os.PathLike, options: BatchOptions, *, jobs: int = 1,
              on_result: Callable[[FileResult], None] | None = None,
              scheduler: str | None = None) -> list[FileResult]:
    """Convert ``clips`` into ``out_dir``; the results in the clips' order.

    ``jobs`` > 1 converts in that many worker processes (`run_pool`); ``on_result``
    hears about each file as it finishes (in the order they finish). ``scheduler``
    runs the clips on Dask distributed instead (`run_on_dask`). The outputs are
    the same bytes whichever way they ran. A clip whose name no output can have,
    or whose outputs would replace another clip or its outputs, fails alone before
    anything runs. Ctrl-C (KeyboardInterrupt) lets the clips being converted
    finish, starts no more, and raises `BatchInterrupted`; so does a lost scheduler. A second batch
    into the same folder while this one runs is refused (`batch_lock`).
    """
    with batch_lock(out_dir) as lock:
        return _run_batch(clips, out_dir, options, jobs, on_result, scheduler, lock)


def _run_batch(clips, out_dir, options, jobs, on_result, scheduler, lock=None) -> list[FileResult]:
    from .job import check_name

    parameters = batch_parameters(options)
    order = {clip: index for index, clip in enumerate(clips)}
    done: dict[Clip, FileResult] = {}

    def finished(clip: Clip, result: FileResult) -> None:
        done[clip] = result
        if lock is not None:
            try:
                lock.hold_folder()  # (the first clip has made the folder: hold it as itself)
            except ConfigError:
                pass  # (another batch took it first; its temporary folder differs, or it would not have begun)
        if on_result is not None:
            on_result(result)

    def waiting() -> list[Clip]:
        return [clip for clip in clips if clip not in done]

    def in_order() -> list[FileResult]:
        return [done[clip] for clip in sorted(done, key=order.__getitem__)]

    try:  # (from the first result said: a reader of them that goes away stops the batch as Ctrl-C does)
        for clip in clips:  # a name no output can have fails that clip alone
            try:
                check_name(clip.name)
            except ConfigError as error:
                finished(clip, FileResult(str(clip.source), "failed", error=f"{clip.source}: {error}"))
        for clip, other in clashes(waiting(), out_dir).items():  # never write over a clip of the batch
            finished(clip, FileResult(str(clip.source), "failed", error=f"its outputs would replace the input {other}; "
                                                                        "choose an output folder apart from the clips"))
        for clip, other in foreign_clips(waiting(), out_dir).items():  # nor a clip outside the batch
            finished(clip, FileResult(str(clip.source), "failed", error=f"its BVH would replace {other}, a clip this "
                                      "tool did not write (no manifest or pipeline file of ours beside it); move it, "
                                      "or choose another output folder"))
        for clip, other in same_outputs(waiting()).items():  # nor one clip's over another's
            finished(clip, FileResult(str(clip.source), "failed", error=f"its outputs would be those of {other.source}"))
        todo = waiting()
        if scheduler is not None:
            run_on_dask(todo, out_dir, options, parameters, scheduler=scheduler, jobs=jobs, finished=finished)
        elif jobs <= 1 or len(todo) <= 1:
            run_serial(todo, out_dir, options, parameters, finished=finished)
        else:
            run_pool(todo, out_dir, options, parameters, jobs=jobs, finished=finished)
    except KeyboardInterrupt:
        raise BatchInterrupted(in_order(), waiting()) from None
    except SchedulerLost as lost:
        raise BatchInterrupted(in_order(), waiting(), reason=str(lost)) from None
    return in_order()


class _FolderLock:
    """The output folder held by a batch (`batch_lock`): a lock file in the temporary folder, and the
    folder's own lock once it exists (seen by a batch whose temporary folder is another: TMPDIR)."""

    def __init__(self, out_dir: str | os.PathLike, handle) -> None:
        self.out_dir = out_dir
        self.real = os.path.realpath(out_dir)
        self.handle = handle
        self.folder: int | None = None

    def hold_folder(self) -> None:
        """Take the output folder's own lock where it exists and is not held yet; a ConfigError when
        another batch holds it."""
        import fcntl

        if self.folder is not None or not os.path.isdir(self.real):
            return
        try:
            folder = os.open(self.real, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
        except OSError:
            return
        try:
            fcntl.flock(folder, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(folder)
            raise _busy(self.out_dir) from None
        except OSError:  # (a file system without locks on folders: the temporary folder's lock stands alone)
            os.close(folder)
            return
        self.folder = folder

    def release(self) -> None:
        if self.folder is not None:
            os.close(self.folder)  # (closing releases the lock)
            self.folder = None
        self.handle.close()


def _busy(out_dir) -> ConfigError:
    return ConfigError(f"{out_dir}: another batch is writing into this folder; wait for it to end, or choose "
                       "another output folder")


@contextmanager
def batch_lock(out_dir: str | os.PathLike) -> Iterator[_FolderLock]:
    """Hold the output folder for this batch: a second batch into the same folder (by its real path) is
    refused in one line while the first runs (each clears the other's temporaries as an earlier run's
    leftovers otherwise). Two locks: a file in the system's temporary folder, and the output folder's
    own once it exists (taken at the start, or by `_FolderLock.hold_folder` as soon as the first clip
    made it), which a batch whose temporary folder is another (TMPDIR) sees too; both are released
    when the batch ends or its process does. Batches on other machines sharing the folder are not seen."""
    import fcntl
    import hashlib
    import tempfile

    real = os.path.realpath(out_dir)
    name = hashlib.sha256(os.fsencode(real)).hexdigest()[:24]
    path = Path(tempfile.gettempdir()) / f"mocap-exaggerate-batch-{name}.lock"
    handle = open(path, "a+b")
    lock = _FolderLock(out_dir, handle)
    try:
        try:
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise _busy(out_dir) from None
        lock.hold_folder()
        yield lock
    finally:
        lock.release()
