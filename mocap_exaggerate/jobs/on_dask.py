"""Running a batch's clips on Dask distributed: a `LocalCluster` (``--scheduler local``) or a
running scheduler (``--scheduler tcp://host:8786``), one task per clip.

Dask is optional (the ``dask`` extra): `check_scheduler` refuses an address, or
a missing Dask, before any work; `connect_dask` refuses a scheduler that cannot
be reached or has no workers; `run_on_dask` hands each clip's `FileResult` on
as its task comes back. A task that fails (its worker died too often) fails
its clip; a scheduler that goes away stops the batch (`SchedulerLost`).
"""

from __future__ import annotations

import os
import re
import time
from collections.abc import Callable
from pathlib import Path

from ..core.errors import ConfigError
from .batch_types import BatchOptions, Clip, FileResult
from .discovery import largest_first, source_size
from .memory import malloc_thresholds
from .pool import ctrl_c_held, one_thread_per_worker
from .task import clear_temporaries, convert_file

__all__ = ["check_scheduler", "connect_dask", "run_on_dask", "convert_on_worker", "malloc_thresholds", "SchedulerLost",
           "WAIT_FOR_WORKERS"]

#: Seconds a batch waits for a Dask scheduler without workers to get one.
WAIT_FOR_WORKERS = 30.0


class SchedulerLost(Exception):
    """The Dask scheduler went away mid-batch: the clips whose tasks had not come back are not done."""


def check_scheduler(scheduler: str) -> None:
    """Refuse (ConfigError) a ``scheduler`` that is neither ``local`` nor a Dask address this command can reach
    (a host and a port over tcp, ws or wss; tls only with Dask's TLS settings configured), or Dask missing."""
    shown = repr(scheduler) if len(scheduler) <= 80 else f"{scheduler[:80]!r}... ({len(scheduler)} characters)"
    if scheduler != "local":
        found = re.fullmatch(r"(tcp|tls|ws|wss|inproc|ucx)://(\[[0-9A-Fa-f:.]+\]|[^\s/:\[\]]+):(\d{1,5})/?", scheduler)
        if found is None or not 0 < int(found.group(3)) < 65536:
            raise ConfigError(f"--scheduler {shown}: give 'local' or a Dask scheduler's address with its port, "
                              "such as tcp://host:8786")
        if found.group(1) == "inproc":
            raise ConfigError(f"--scheduler {shown}: an inproc:// scheduler lives in another process's memory; "
                              "give its tcp:// address")
        if found.group(1) == "ucx":
            raise ConfigError(f"--scheduler {shown}: ucx:// needs UCX, which this command does not set up; "
                              "give the scheduler's tcp:// address")
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise ConfigError("--scheduler needs Dask distributed: pip install 'mocap-exaggerate[dask]'") from None
    if scheduler.startswith("tls://"):
        import dask

        if not dask.config.get("distributed.comm.tls.client.cert", None):
            raise ConfigError(f"--scheduler {shown}: tls:// needs Dask's TLS certificates configured "
                              "(distributed.comm.tls.client.cert and .key; see Dask's security docs)")


def connect_dask(scheduler: str, jobs: int = 1):
    """A Dask ``(client, cluster)``: ``local`` starts a `LocalCluster` of ``jobs`` one-thread worker
    processes (``cluster`` is then to be closed after the client), an address (``tcp://host:8786``)
    connects to a running scheduler (``cluster`` None). ConfigError when Dask is missing or the
    scheduler cannot be reached."""
    import logging

    check_scheduler(scheduler)
    from distributed import Client, LocalCluster

    if scheduler == "local":
        import dask

        try:
            # Dask's nanny starts each worker with MALLOC_TRIM_THRESHOLD_=65536, which turns glibc's
            # adaptive thresholds off: every large NumPy temporary became fresh pages from the kernel and
            # each clip took 1.9-2.0x as long as in the pool. Unset, the workers allocate as -j does.
            settings = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
                        "distributed.worker.profile.enabled": False,
                        # Dask's event loops wake less often (its health tick every 20 ms, its system and
                        # memory monitors): with no dashboard to feed, each wake took the GIL from a clip's
                        # threads (the GLB built beside the BVH) and a core from the workers. The 22 clips'
                        # time on the workers, summed: 10.2-10.9 s -> 9.6-10.3 s (the pool's: 8.9-9.4 s).
                        "distributed.admin.tick.interval": "1s",
                        "distributed.admin.system-monitor.interval": "5s",
                        "distributed.worker.memory.monitor-interval": "500ms"}
            settings.update(_fork_workers())
            cluster = client = None
            # The terminal's Ctrl-C is the batch's to handle, not the workers' (each printed a traceback):
            # SIGINT is blocked while the cluster and its client start, so Dask's threads, and the workers
            # they start (now and on a restart), never hear it; one pressed meanwhile is acted on when they
            # are up. (Pressed while Dask's client waits on its loop, Dask's own cancel failed and printed a
            # traceback: distributed 2026.8, sync's callback reading a future not yet made.)
            with one_thread_per_worker(), dask.config.set(settings), ctrl_c_held():
                cluster = LocalCluster(n_workers=max(jobs, 1), threads_per_worker=1, processes=True,
                                       dashboard_address=None, silence_logs=logging.ERROR)
                client = Client(cluster)
        except BaseException as error:
            if client is not None:
                client.close()
            if cluster is not None:
                cluster.close()
            if not isinstance(error, Exception):  # Ctrl-C
                raise
            # Dask's own failures to start (a port, a worker that did not come up)
            raise ConfigError(f"--scheduler local: the local Dask cluster did not start: "
                              f"{type(error).__name__}: {error}") from None
        return client, cluster
    if scheduler.startswith("tcp://"):
        _speaks_dask(scheduler)
    try:
        client = Client(scheduler, timeout=10)
    except (OSError, TimeoutError) as error:
        raise ConfigError(f"--scheduler {scheduler}: cannot reach the Dask scheduler: {error}") from None
    except Exception as error:  # what it sent was not Dask's (a struct or msgpack error from deep in Dask), or
        # a scheduler of another version
        raise ConfigError(f"--scheduler {scheduler}: connecting as a Dask client failed ({type(error).__name__}: "
                          f"{str(error)[:120]}); not a Dask scheduler, or not of this Dask's version") from None
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


#: Seconds a scheduler has to greet a connection, as a Dask scheduler does at once.
GREETING = 8.0
#: The most bytes a Dask scheduler's greeting (its handshake) is taken to be.
_GREETING_MOST = 1 << 20


def _speaks_dask(scheduler: str) -> None:
    """Refuse (ConfigError) a tcp:// address where nothing listens or what listens does not greet a connection
    within `GREETING` seconds as a Dask scheduler does (its handshake comes first): Dask's own client waits on
    such a port for ever (a web server, a database)."""
    import socket

    host, port = scheduler[len("tcp://"):].rstrip("/").rsplit(":", 1)
    host = host.strip("[]")
    import time

    first = b""
    try:
        with socket.create_connection((host, int(port)), timeout=GREETING) as probe:
            deadline = time.monotonic() + GREETING
            while len(first) < 16:  # the greeting's first two numbers (its size, its frames)
                probe.settimeout(max(deadline - time.monotonic(), 0.001))
                more = probe.recv(16 - len(first))
                if not more:
                    break
                first += more
    except TimeoutError:
        raise ConfigError(f"--scheduler {scheduler}: what listens there did not answer as a Dask scheduler "
                          f"within {GREETING:g} s") from None
    except OSError as error:
        raise ConfigError(f"--scheduler {scheduler}: cannot reach the Dask scheduler: "
                          f"{error.strerror or error}") from None
    if len(first) < 16:
        raise ConfigError(f"--scheduler {scheduler}: what listens there closed the connection; not a Dask scheduler")
    # A Dask message starts with its size and its count of frames (distributed.comm.tcp): a handshake is a few
    # hundred bytes in a few frames. Anything else (a flood of bytes, a size of 2**62) is not Dask's.
    size, frames = int.from_bytes(first[:8], "little"), int.from_bytes(first[8:], "little")
    if not (16 <= size <= _GREETING_MOST and 1 <= frames <= 64):
        raise ConfigError(f"--scheduler {scheduler}: what listens there does not speak Dask's protocol; "
                          f"not a Dask scheduler")


def run_on_dask(clips: list[Clip], out_dir: str | os.PathLike, options: BatchOptions, parameters: str, *,
                scheduler: str, jobs: int = 1, finished: Callable[[Clip, FileResult], None]) -> None:
    """Convert ``clips`` on Dask distributed: one task per clip, the largest first, each result
    to ``finished`` as it comes back.

    The workers read the clips and write the outputs themselves, by absolute path:
    on a cluster the input and output folders must be at the same paths on every
    worker (a shared mount). Results and manifests name the files as given here,
    so the outputs are the bytes a serial run writes. Ctrl-C (KeyboardInterrupt)
    cancels the tasks not back yet and is raised again; `SchedulerLost` when the
    scheduler goes away.
    """
    client, cluster = connect_dask(scheduler, jobs)
    out_abs = Path(os.path.abspath(out_dir))  # absolute, links not followed: messages name what was given
    futures = {}
    try:
        from distributed import as_completed

        for index, clip in enumerate(largest_first(clips)):
            task = Clip(Path(os.path.abspath(clip.source)), clip.relative)
            future = client.submit(convert_on_worker, task, out_abs, options, parameters, str(clip.source),
                                   pure=False, priority=source_size(clip),
                                   key=f"mocap-exaggerate-{index}-{os.getpid()}-{time.monotonic_ns()}")
            futures[future] = clip
        try:
            # Waiting for the next future is waiting on a condition, where a Ctrl-C is a KeyboardInterrupt
            # and no more. Its result is fetched with Ctrl-C held: one pressed inside Dask's sync, before its
            # coroutine started, made Dask's loop print a traceback of its own (distributed 2026.8: its
            # cancel read a future not yet made); held, it is raised here once the result is in. (Results
            # fetched on Dask's loop, as_completed's with_results, were tried: a fetch that fails otherwise
            # than by cancelling, the scheduler lost meanwhile, left the batch waiting for ever.)
            for future in as_completed(list(futures)):
                clip = futures.pop(future)
                try:
                    with ctrl_c_held():
                        result = future.result()
                except Exception as error:
                    if future.cancelled() or client.status != "running":  # not this clip's doing: the scheduler went
                        raise SchedulerLost(f"lost the Dask scheduler at {scheduler}") from None
                    # The task failed: its worker died (out of memory, killed) too often, say.
                    result = FileResult(str(clip.source), "failed",
                                        error=f"its Dask task failed: {type(error).__name__}: {error}")
                    clear_temporaries(clip, out_abs, options)
                result.outputs = {kind: _given(path, out_abs, out_dir) for kind, path in result.outputs.items()}
                finished(clip, result)
        except KeyboardInterrupt:
            client.cancel(list(futures))
            raise
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
            for clip in futures.values():  # ended mid-clip with their workers: what they were writing goes
                clear_temporaries(clip, out_abs, options)


def _fork_workers() -> dict:
    """Dask's setting that starts the local cluster's workers by ``fork`` (Linux, where the user did not choose
    a method themselves): a worker is then a copy of this process, with distributed, NumPy and the
    library already imported, instead of a fresh interpreter that imports them (``spawn``, Dask's
    default): the cluster up in 0.08 s instead of 0.4 and closed in 0.03 instead of 0.12."""
    import sys

    import dask

    # Dask's config already holds a method set in its files or environment; "spawn" set on purpose is told
    # from the default by its variable.
    chosen = dask.config.get("distributed.worker.multiprocessing-method", "spawn")
    said = "DASK_DISTRIBUTED__WORKER__MULTIPROCESSING_METHOD" in os.environ
    if not sys.platform.startswith("linux") or chosen != "spawn" or said:
        return {}
    return {"distributed.worker.multiprocessing-method": "fork"}


def convert_on_worker(*args) -> FileResult:
    """`convert_file` on a Dask worker, glibc's memory thresholds first set for the worker's process where
    its nanny turned them off (`malloc_thresholds`): a cluster this tool did not start runs at the pool's speed."""
    malloc_thresholds()
    return convert_file(*args)


def _given(path: str, out_abs: Path, out_dir) -> str:
    """An output path a worker wrote by its absolute name, named under the output folder as given."""
    try:
        return str(Path(out_dir) / Path(path).relative_to(out_abs))
    except ValueError:
        return path
