"""Whole folders of clips: find them, convert each in a worker process, resume, report per file.

`find_clips` walks a folder for clips; `run_batch` converts them with `convert`
(in this process, or in a pool of worker processes that pay the imports once)
and hands each file's `FileResult` to a callback as it finishes; a farm task
calls `convert_file` on one clip. Nothing here stops at a bad file: it is
reported (status ``failed`` with the reason) and the rest go on. Every output
set is written the way `convert` writes it (temporary files renamed into
place, the manifest last), so a killed run leaves no half-written file, and
``resume`` redoes only the clips whose output set is not complete for the same
input bytes and the same parameters.

Example::

    from mocap_exaggerate import load_preset
    from mocap_exaggerate.jobs.batch import BatchOptions, find_clips, run_batch

    clips, problems = find_clips("mocap/")
    results = run_batch(clips, "out/", BatchOptions(load_preset("cartoon")), jobs=2)
    [r.input for r in results if r.status == "failed"]
"""

from __future__ import annotations

import json
import os
import re
import signal
import threading
import time
from collections.abc import Callable, Iterable
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path

from ..config import PipelineConfig
from ..core.errors import ConfigError, MocapError
from ..io.files import OutputExistsError

__all__ = ["Clip", "BatchOptions", "FileResult", "BatchInterrupted", "find_clips", "glob_regex", "convert_file",
           "run_batch", "run_on_dask", "connect_dask", "check_scheduler", "is_complete", "is_output", "same_outputs",
           "check_folders", "DEFAULT_GLOB"]

#: Which files a batch takes: every .bvh at any depth (matched without regard to case).
DEFAULT_GLOB = "**/*.bvh"

#: Modules a worker imports once, before its first clip.
_PRELOAD = ["mocap_exaggerate.jobs.job", "mocap_exaggerate.pipeline", "mocap_exaggerate.jobs.outputs",
            "mocap_exaggerate.io.gltf", "mocap_exaggerate.rig.body", "mocap_exaggerate.rig.skinning"]


@dataclass(frozen=True)
class Clip:
    """One input of a batch.

    source : the file
    relative : where it sits under the input folder; its outputs sit at the same
        place under the output folder (``walk/a.bvh`` -> ``OUT/walk/a.bvh``, ``.glb``, ...)
    """

    source: Path
    relative: Path

    @property
    def name(self) -> str:
        return self.relative.stem


@dataclass(frozen=True)
class BatchOptions:
    """What every clip of a batch is converted with (`convert`'s options).

    resume : keep the clips whose output set is complete and was made from the same
        input bytes with the same parameters; redo the rest (replacing what they left)
    overwrite : replace existing outputs; without it (or resume) a clip whose outputs
        exist fails, saying so
    report : also draw each clip's pictures for the batch's report (`mocap_exaggerate.viz.report`)
    """

    config: PipelineConfig
    preset: str | None = None
    overwrite: bool = False
    resume: bool = False
    glb: bool = True
    skin: str | None = None
    joint_map: dict | None = None
    units: str = "auto"
    influences: int = 4
    report: bool = False


@dataclass
class FileResult:
    """What happened to one file: ``converted``, ``skipped`` or ``failed`` (with ``error``).

    warnings : what the reader noticed in the input (extra lines, a frame rate overridden)
    notes : what the pipeline did worth hearing (rest frames, strikes found), and why
        ``resume`` redid the clip
    """

    input: str
    status: str
    outputs: dict[str, str] = field(default_factory=dict)
    frames: int | None = None
    seconds: float = 0.0
    max_link_stretch: float | None = None
    error: str | None = None
    warnings: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def to_json(self) -> str:
        """One line of JSON (``batch --json``)."""
        return json.dumps({**asdict(self), "seconds": round(self.seconds, 4)})


class BatchInterrupted(Exception):
    """A batch stopped before its end: the files that finished (``results``) and those not done (``pending``).

    reason : None after Ctrl-C; what stopped it otherwise (the Dask scheduler was lost)
    """

    def __init__(self, results: list[FileResult], pending: list[Clip], reason: str | None = None) -> None:
        super().__init__(reason or f"interrupted: {len(results)} file(s) finished, {len(pending)} not started")
        self.results = results
        self.pending = pending
        self.reason = reason


# ---------------------------------------------------------------------------- finding clips


def glob_regex(pattern: str) -> re.Pattern:
    """A compiled regex for a ``/``-separated glob over relative paths, case-insensitive.

    ``*`` and ``?`` stay inside one folder name, ``[...]`` is a character set
    (``[!...]`` its complement), a ``**`` segment matches any number of folders,
    none included.

    >>> bool(glob_regex("**/*.bvh").fullmatch("walk/fast/A.BVH")), bool(glob_regex("*.bvh").fullmatch("walk/a.bvh"))
    (True, False)
    """
    parts = pattern.replace("\\", "/").strip("/").split("/")
    out = []
    for index, part in enumerate(parts):
        last = index == len(parts) - 1
        if part == "**":
            out.append(".*" if last else "(?:[^/]+/)*")
            continue
        piece, i = [], 0
        while i < len(part):
            c = part[i]
            if c == "*":
                piece.append("[^/]*")
            elif c == "?":
                piece.append("[^/]")
            elif c == "[":
                start = i + 1 + (part[i + 1:i + 2] == "!")
                end = part.find("]", start + 1)  # a "]" first in the set is one of its characters
                if end < 0:
                    piece.append(re.escape(c))
                else:
                    body = part[start:end].replace("\\", "\\\\").replace("^", "\\^")
                    piece.append(f"[{'^' if start > i + 1 else ''}{body}]")
                    i = end
            else:
                piece.append(re.escape(c))
            i += 1
        out.append("".join(piece) + ("" if last else "/"))
    return re.compile("".join(out), re.IGNORECASE | re.DOTALL)


def find_clips(folder: str | os.PathLike, pattern: str = DEFAULT_GLOB, *,
               exclude: Iterable[str | os.PathLike] = ()) -> tuple[list[Clip], list[FileResult]]:
    """The clips under ``folder`` whose relative path matches ``pattern``, sorted by that path.

    Folders reached through symbolic links are followed once: a link back to a
    folder already walked (a loop) is reported and not entered. A folder that
    cannot be listed is reported; so are two clips whose outputs would be the
    same files (``a.bvh`` and ``a.BVH``). ``exclude``: folders not to walk (the
    output folder, when it is inside the input folder).

    Returns the clips and the problems (`FileResult` with status ``failed`` or,
    for loops, ``skipped``).
    """
    top = Path(folder)
    regex = glob_regex(pattern)
    problems: list[FileResult] = []
    skip = set()
    for path in exclude:
        try:
            st = os.stat(path)
            skip.add((st.st_dev, st.st_ino))
        except OSError:
            pass
    st = os.stat(top)
    seen = {(st.st_dev, st.st_ino)}

    def unlistable(error: OSError) -> None:
        problems.append(FileResult(str(error.filename), "failed", error=f"cannot list the folder: {error.strerror}"))

    found: list[Clip] = []
    for here, folders, files in os.walk(top, followlinks=True, onerror=unlistable):
        keep = []
        for name in sorted(folders):
            path = os.path.join(here, name)
            try:
                st = os.stat(path)
            except OSError as error:  # a link to nowhere, a folder gone meanwhile
                problems.append(FileResult(path, "failed", error=f"cannot open: {error.strerror}"))
                continue
            key = (st.st_dev, st.st_ino)
            if key in skip:
                continue
            if key in seen:
                problems.append(FileResult(path, "skipped", error="a link to a folder already walked (a loop?): "
                                                                  "not entered"))
                continue
            seen.add(key)
            keep.append(name)
        folders[:] = keep
        for name in files:
            path = Path(here) / name
            relative = path.relative_to(top)
            if regex.fullmatch(relative.as_posix()) and not is_output(path):
                found.append(Clip(path, relative))
    found.sort(key=lambda clip: clip.relative.as_posix())
    taken = same_outputs(found)
    problems += [FileResult(str(clip.source), "failed", error=f"its outputs would be those of {other.source}; rename one")
                 for clip, other in taken.items()]
    return [clip for clip in found if clip not in taken], problems


def same_outputs(clips: list[Clip]) -> dict[Clip, Clip]:
    """Clips whose outputs would be the files of an earlier clip in the list (``a.bvh`` and
    ``a.BVH``, or one file given twice): clip -> that earlier clip."""
    owners: dict[tuple[str, str], Clip] = {}
    out = {}
    for clip in clips:
        key = (clip.relative.parent.as_posix().casefold(), clip.name.casefold())
        if key in owners:
            out[clip] = owners[key]
        else:
            owners[key] = clip
    return out


def check_folders(in_dir: str | os.PathLike, out_dir: str | os.PathLike, pattern: str = DEFAULT_GLOB) -> None:
    """Refuse (ConfigError) an input and output folder a batch cannot use safely.

    The input must be a folder; the output not a file, not the input folder,
    and, when inside the input folder, holding no clips (this tool's outputs
    aside), which outputs could replace.
    """
    in_dir, out_dir = Path(in_dir), Path(out_dir)
    if not in_dir.exists():
        raise ConfigError(f"{in_dir}: no such folder")
    if not in_dir.is_dir():
        raise ConfigError(f"{in_dir}: is a file; give the folder it is in (or use 'exaggerate' for files)")
    if out_dir.exists() and not out_dir.is_dir():
        raise ConfigError(f"{out_dir}: exists and is not a folder")
    if out_dir.resolve() == in_dir.resolve():
        raise ConfigError(f"{out_dir}: is the input folder; the outputs would sit among the clips")
    if out_dir.is_dir() and out_dir.resolve().is_relative_to(in_dir.resolve()):
        held, _ = find_clips(out_dir, pattern)
        if held:
            raise ConfigError(f"{out_dir}: is inside {in_dir} and holds clips ({held[0].source}); outputs could "
                              f"replace them: choose an output folder outside {in_dir}, or a new one")


def _manifest(path: Path) -> dict | None:
    """The manifest at ``path`` as data; None when there is none or it does not read as one."""
    try:
        if path.stat().st_size > 50_000_000:
            return None
        info = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return info if isinstance(info, dict) and info.get("tool") == "mocap_exaggerate" else None


def is_output(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a BVH this tool wrote: the manifest beside it names it as its output.

    A batch does not take its own (or an earlier run's) outputs for clips.
    """
    path = Path(path)
    info = _manifest(path.with_suffix(".json"))
    outputs = info.get("outputs") if info else None
    return isinstance(outputs, dict) and outputs.get("bvh") == path.name


def clashes(clips: list[Clip], out_dir: str | os.PathLike) -> dict[Clip, str]:
    """Clips whose outputs would land on another clip of the batch (an output folder that
    overlaps the input folder): clip -> the clip it would replace."""
    from .job import output_paths

    sources = {os.path.realpath(clip.source): clip for clip in clips}
    out = {}
    for clip in clips:
        for target in output_paths(Path(out_dir) / clip.relative.parent, clip.name).values():
            other = sources.get(os.path.realpath(target))
            if other is not None:
                out[clip] = str(other.source)
                break
    return out


# ---------------------------------------------------------------------------- one file


def is_complete(clip: Clip, out_dir: str | os.PathLike, options: BatchOptions, parameters: str | None = None) -> bool:
    """Whether ``clip``'s output set under ``out_dir`` is complete and was made from these input
    bytes with these parameters (`parameters_digest`; computed when not given)."""
    return _not_complete(clip, out_dir, options, parameters) is None


def _not_complete(clip: Clip, out_dir, options: BatchOptions, parameters: str | None) -> str | None:
    """Why ``clip`` must be (re)done under ``out_dir``; None when its outputs can be kept.

    The cheap reasons first (no manifest, other options, another input), the
    hashing of every output last.
    """
    from .job import check_output_set, parameters_digest
    from .outputs import file_digest

    manifest = Path(out_dir) / clip.relative.parent / f"{clip.name}.json"
    info = _manifest(manifest)
    if info is None:
        return "no outputs yet" if not manifest.exists() else "outputs incomplete (the manifest does not read)"
    if parameters is None:
        parameters = parameters_digest(options.config, preset=options.preset, glb=options.glb, units=options.units,
                                       influences=options.influences, skin=options.skin, joint_map=options.joint_map)
    if info.get("parameters") != parameters:
        return "made with other options"
    try:
        if file_digest(clip.source.read_bytes()) != (info.get("input") or {}).get("hash"):
            return "the input changed"
    except OSError:
        return "the input cannot be read"
    problems = check_output_set(manifest)
    if problems:
        return f"outputs incomplete ({problems[0]})"
    if options.report:
        from ..viz.report import pictures_current

        if not pictures_current(out_dir, manifest):
            return "its report pictures are missing or were drawn from other outputs"
    return None


def _kept(label: str, clip: Clip, out_dir, started: float) -> FileResult:
    """The result of a clip whose complete outputs are kept (``resume``): what its manifest says."""
    from .job import output_paths

    folder = Path(out_dir) / clip.relative.parent
    info = _manifest(folder / f"{clip.name}.json") or {}
    listed = info.get("outputs") or {}
    outputs = {kind: str(path) for kind, path in output_paths(folder, clip.name).items()
               if kind in listed or kind == "manifest"}
    stretch = (info.get("result") or {}).get("max_link_stretch")
    return FileResult(label, "skipped", outputs=outputs, frames=(info.get("result") or {}).get("frames"),
                      seconds=time.perf_counter() - started, max_link_stretch=stretch,
                      error="outputs complete, from the same input and parameters")


def convert_file(clip: Clip, out_dir: str | os.PathLike, options: BatchOptions,
                 parameters: str | None = None, label: str | None = None) -> FileResult:
    """Convert one clip of a batch into ``out_dir/<its folder>/``; never raises for a bad file.

    Whatever goes wrong (a malformed or unreadable file, outputs that exist, a
    full disk, a bug) is the returned result's ``error``, in one line.
    label : how the manifest and the result name the input (default: ``clip.source``)
    """
    from .job import convert

    started = time.perf_counter()
    label = label if label is not None else str(clip.source)

    def failed(message: str) -> FileResult:
        return FileResult(label, "failed", seconds=time.perf_counter() - started, error=message)

    redo = None
    try:
        if options.resume:
            redo = _not_complete(clip, out_dir, options, parameters)
            if redo is None:
                return _kept(label, clip, out_dir, started)
        record = convert(clip.source, Path(out_dir) / clip.relative.parent, options.config, preset=options.preset,
                         name=clip.name, label=label, overwrite=options.overwrite or options.resume, glb=options.glb,
                         skin=options.skin, joint_map=options.joint_map, units=options.units,
                         influences=options.influences,
                         parameters=parameters)
    except OutputExistsError as error:
        return failed(f"{error}; --overwrite replaces it (batch --resume keeps finished clips, redoes the rest)")
    except MocapError as error:
        return failed(str(error))
    except OSError as error:
        where = f"{error.filename}: " if getattr(error, "filename", None) else ""
        return failed(f"{where}{error.strerror or error}")
    except MemoryError:
        return failed("out of memory")
    except Exception as error:  # a bug: reported with the file, and the rest go on
        return failed(f"internal error, please report it: {type(error).__name__}: {error}")
    notes = ([f"redone: {redo}"] if redo and redo != "no outputs yet" else []) + list(record.notes)
    if options.report:
        from ..viz.report import write_pictures

        warnings = list(record.warnings)
        try:  # the outputs are written and sound: a picture that cannot be drawn is a warning, not a failure
            write_pictures(record, out_dir, options.config)
        except OSError as error:
            where = f"{error.filename}: " if getattr(error, "filename", None) else ""
            warnings.append(f"no report pictures: {where}{error.strerror or error}")
        except Exception as error:
            warnings.append(f"no report pictures: {type(error).__name__}: {error}")
        record.warnings = warnings
    return FileResult(label, "converted", outputs={kind: str(path) for kind, path in record.outputs.items()},
                      frames=record.frames, seconds=time.perf_counter() - started,
                      max_link_stretch=round(record.max_link_stretch, 6), warnings=list(record.warnings),
                      notes=notes)


# ---------------------------------------------------------------------------- many files


def _worker_start(batch_pid: int) -> None:
    """In each worker: Ctrl-C is the batch's to handle (it lets running clips finish), and the
    worker ends itself when the batch process is gone (killed with SIGKILL, say), instead of
    waiting for work forever and holding the batch's stdout open."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    import importlib
    import threading

    for module in _PRELOAD:
        importlib.import_module(module)

    def watch() -> None:
        while True:
            time.sleep(0.5)
            try:
                os.kill(batch_pid, 0)
            except ProcessLookupError:
                os._exit(1)
            except PermissionError:  # alive, only not ours to signal
                pass

    threading.Thread(target=watch, name="batch-watch", daemon=True).start()


@contextmanager
def _one_thread_per_worker():
    """Workers use one BLAS thread each: N workers on N cores, not N x N threads."""
    names = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
    before = {name: os.environ.get(name) for name in names}
    for name in names:
        os.environ.setdefault(name, "1")
    try:
        yield
    finally:
        for name, value in before.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def default_jobs() -> int:
    """The worker processes a batch uses by default: the cores this process may run on."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except AttributeError:  # not Linux
        return max(os.cpu_count() or 1, 1)


def run_batch(clips: list[Clip], out_dir: str | os.PathLike, options: BatchOptions, *, jobs: int = 1,
              on_result: Callable[[FileResult], None] | None = None,
              scheduler: str | None = None) -> list[FileResult]:
    """Convert ``clips`` into ``out_dir``; the results in the clips' order.

    ``jobs`` > 1 converts in that many worker processes; ``on_result`` hears
    about each file as it finishes (in the order they finish). ``scheduler``
    runs the clips on Dask distributed instead (`run_on_dask`). The outputs are
    the same bytes whichever way they ran. Ctrl-C (KeyboardInterrupt) lets the
    clips being converted finish, starts no more, and raises `BatchInterrupted`.
    """
    from .job import parameters_digest

    parameters = parameters_digest(options.config, preset=options.preset, glb=options.glb, units=options.units,
                                   influences=options.influences, skin=options.skin, joint_map=options.joint_map)
    order = {clip: index for index, clip in enumerate(clips)}
    done: dict[Clip, FileResult] = {}

    def finished(clip: Clip, result: FileResult) -> None:
        done[clip] = result
        if on_result is not None:
            on_result(result)

    from .job import check_name

    for clip in clips:  # a name no output can have fails that clip alone
        try:
            check_name(clip.name)
        except ConfigError as error:
            finished(clip, FileResult(str(clip.source), "failed", error=f"{clip.source}: {error}"))
    clips = [clip for clip in clips if clip not in done]
    for clip, other in clashes(clips, out_dir).items():  # never write over a clip of the batch
        finished(clip, FileResult(str(clip.source), "failed", error=f"its outputs would replace the input {other}; "
                                                                    "choose an output folder apart from the clips"))
    for clip, other in same_outputs([c for c in clips if c not in done]).items():  # nor one clip's over another's
        finished(clip, FileResult(str(clip.source), "failed", error=f"its outputs would be those of {other.source}"))
    clips = [clip for clip in clips if clip not in done]

    if scheduler is not None:
        run_on_dask(clips, out_dir, options, parameters, scheduler=scheduler, jobs=jobs, on_result=finished,
                    order=order, done=done)
        return _in_order(done, order)
    if jobs <= 1 or len(clips) <= 1:
        for clip in clips:
            try:
                finished(clip, convert_file(clip, out_dir, options, parameters))
            except KeyboardInterrupt:
                raise BatchInterrupted(_in_order(done, order), [c for c in clips if c not in done]) from None
        return _in_order(done, order)

    import multiprocessing

    if "forkserver" in multiprocessing.get_all_start_methods():
        # Workers fork from a server that has imported the pipeline once: each starts warm.
        context = multiprocessing.get_context("forkserver")
        context.set_forkserver_preload(_PRELOAD)
    else:
        context = multiprocessing.get_context("spawn")
    # The largest files first, so that no worker is left with a long one at the end while the others wait.
    queue = sorted(clips, key=lambda clip: (-_size(clip.source), order[clip]))
    queue.reverse()  # pop() from the end
    workers = min(jobs, len(clips))
    with _one_thread_per_worker():
        pool = ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=_worker_start,
                                   initargs=(os.getpid(),))
        running: dict = {}

        def hand_out() -> None:  # one clip per worker at a time: Ctrl-C then has only those to wait for
            while queue and len(running) < workers:
                clip = queue.pop()
                running[pool.submit(convert_file, clip, out_dir, options, parameters)] = clip

        def collect(future) -> None:
            clip = running.pop(future)
            try:
                result = future.result()
            except BrokenProcessPool:
                result = FileResult(str(clip.source), "failed", error="its worker process died (out of memory, or killed)")
            finished(clip, result)

        def drain() -> None:  # collect what finishes, handing out the queue (empty after Ctrl-C)
            hand_out()
            while running:
                for future in wait(list(running), return_when=FIRST_COMPLETED)[0]:
                    collect(future)
                hand_out()

        # The forkserver and the workers start with Ctrl-C ignored (the disposition passes through
        # exec and fork): one pressed while they are still importing would otherwise print their
        # tracebacks. The batch itself hears it as soon as they are started.
        before = signal.signal(signal.SIGINT, signal.SIG_IGN) if threading.current_thread() is threading.main_thread() else None
        try:
            hand_out()
        finally:
            if before is not None:
                signal.signal(signal.SIGINT, before)
        try:
            drain()
        except KeyboardInterrupt:
            queue.clear()
            try:  # the clips in hand finish (the workers ignore Ctrl-C); a second Ctrl-C stops them
                drain()
            except KeyboardInterrupt:
                for process in list(getattr(pool, "_processes", {}).values()):
                    process.terminate()
            pool.shutdown(wait=True, cancel_futures=True)
            raise BatchInterrupted(_in_order(done, order), [c for c in clips if c not in done]) from None
        pool.shutdown(wait=True)
    return _in_order(done, order)


def check_scheduler(scheduler: str) -> None:
    """Refuse (ConfigError) a ``scheduler`` that is neither ``local`` nor a Dask address, or Dask missing."""
    if scheduler != "local" and not re.fullmatch(r"(tcp|tls|ws|wss|inproc|ucx)://\S+", scheduler):
        shown = repr(scheduler) if len(scheduler) <= 80 else f"{scheduler[:80]!r}... ({len(scheduler)} characters)"
        raise ConfigError(f"--scheduler {shown}: give 'local' or a Dask scheduler's address such as tcp://host:8786")
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise ConfigError("--scheduler needs Dask distributed: pip install 'mocap-exaggerate[dask]'") from None


def connect_dask(scheduler: str, jobs: int = 1):
    """A Dask ``(client, cluster)``: ``local`` starts a `LocalCluster` of ``jobs`` one-thread worker
    processes (``cluster`` is then to be closed after the client), an address (``tcp://host:8786``)
    connects to a running scheduler (``cluster`` None). ConfigError when Dask is missing or the
    scheduler cannot be reached."""
    import logging

    check_scheduler(scheduler)
    from distributed import Client, LocalCluster

    if scheduler == "local":
        try:
            with _one_thread_per_worker():
                cluster = LocalCluster(n_workers=max(jobs, 1), threads_per_worker=1, processes=True,
                                       dashboard_address=None, silence_logs=logging.ERROR)
        except (KeyboardInterrupt, BatchInterrupted):
            raise
        except Exception as error:  # Dask's own failures to start (a port, a worker that did not come up)
            raise ConfigError(f"--scheduler local: the local Dask cluster did not start: "
                              f"{type(error).__name__}: {error}") from None
        try:
            return Client(cluster), cluster
        except BaseException:
            cluster.close()
            raise
    try:
        client = Client(scheduler, timeout=10)
    except (OSError, TimeoutError) as error:
        raise ConfigError(f"--scheduler {scheduler}: cannot reach the Dask scheduler: {error}") from None
    try:
        client.wait_for_workers(1, timeout=WAIT_FOR_WORKERS)
    except TimeoutError:
        client.close()
        raise ConfigError(f"--scheduler {scheduler}: the scheduler has no workers (waited {WAIT_FOR_WORKERS:g} s); "
                          f"start some: dask worker {scheduler} --nthreads 1") from None
    except BaseException:
        client.close()
        raise
    return client, None


#: Seconds a batch waits for a Dask scheduler without workers to get one.
WAIT_FOR_WORKERS = 30.0


def run_on_dask(clips: list[Clip], out_dir: str | os.PathLike, options: BatchOptions, parameters: str, *,
                scheduler: str, jobs: int = 1, on_result: Callable[[Clip, FileResult], None],
                order: dict[Clip, int], done: dict[Clip, FileResult]) -> None:
    """`run_batch` on Dask distributed: one task per clip, each result handed on as it comes back.

    The workers read the clips and write the outputs themselves, by absolute path:
    on a cluster the input and output folders must be at the same paths on every
    worker (a shared mount). Results and manifests name the files as given here,
    so the outputs are the bytes a serial run writes.
    """
    try:
        client, cluster = connect_dask(scheduler, jobs)
    except KeyboardInterrupt:  # Ctrl-C while the cluster starts: nothing ran
        raise BatchInterrupted(_in_order(done, order), [c for c in clips if c not in done]) from None
    out_abs = Path(os.path.abspath(out_dir))  # absolute, links not followed: messages name what was given
    futures = {}
    try:
        from distributed import as_completed

        for clip in sorted(clips, key=lambda clip: (-_size(clip.source), order[clip])):  # largest first
            task = Clip(Path(os.path.abspath(clip.source)), clip.relative)
            future = client.submit(convert_file, task, out_abs, options, parameters, str(clip.source),
                                   pure=False, priority=_size(clip.source), key=f"mocap-exaggerate-{order[clip]}-"
                                   f"{os.getpid()}-{time.monotonic_ns()}")
            futures[future] = clip
        try:
            for future in as_completed(list(futures)):
                clip = futures[future]
                try:
                    result = future.result()
                except Exception as error:
                    if future.cancelled() or client.status != "running":  # not this clip's doing: the scheduler went
                        raise BatchInterrupted(_in_order(done, order), [c for c in clips if c not in done],
                                               reason=f"lost the Dask scheduler at {scheduler}") from None
                    # The task failed: its worker died (out of memory, killed) too often, say.
                    result = FileResult(str(clip.source), "failed",
                                        error=f"its Dask task failed: {type(error).__name__}: {error}")
                result.outputs = {kind: _given(path, out_abs, out_dir) for kind, path in result.outputs.items()}
                on_result(clip, result)
        except KeyboardInterrupt:
            client.cancel([future for future, clip in futures.items() if clip not in done])
            raise BatchInterrupted(_in_order(done, order), [c for c in clips if c not in done]) from None
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _given(path: str, out_abs: Path, out_dir) -> str:
    """An output path a worker wrote by its absolute name, named under the output folder as given."""
    try:
        return str(Path(out_dir) / Path(path).relative_to(out_abs))
    except ValueError:
        return path


def _size(path: Path) -> int:
    try:
        return path.stat().st_size
    except OSError:
        return 0


def _in_order(done: dict[Clip, FileResult], order: dict[Clip, int]) -> list[FileResult]:
    return [done[clip] for clip in sorted(done, key=order.__getitem__)]
