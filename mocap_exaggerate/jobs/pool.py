"""Running a batch's clips on this machine: one after another here (`run_serial`), or in worker
processes (`run_pool`) that pay the imports once.

Each worker is a `ProcessPoolExecutor` of one process, handed one clip at a
time. A worker that dies (out of memory, killed) then fails the one clip it
held, not every clip in a shared pool, and is replaced; the clip's
temporaries are removed. The worker's pid comes back from a first task
(`os.getpid`), so that a second Ctrl-C can end it through
`multiprocessing.active_children`, without reaching into the executor.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, CancelledError, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager

from .batch_types import BatchOptions, Clip, FileResult
from .discovery import largest_first
from .task import clear_temporaries, convert_file

__all__ = ["run_serial", "run_pool", "default_jobs", "one_thread_per_worker", "ctrl_c_held"]

#: Modules a worker imports once, before its first clip.
_PRELOAD = ["mocap_exaggerate.jobs.job", "mocap_exaggerate.jobs.task", "mocap_exaggerate.pipeline",
            "mocap_exaggerate.jobs.outputs", "mocap_exaggerate.io.gltf", "mocap_exaggerate.rig.body",
            "mocap_exaggerate.rig.skinning"]
#: Seconds a second Ctrl-C waits for a worker still starting to say its pid.
_STARTING = 30.0

Finished = Callable[[Clip, FileResult], None]


def default_jobs() -> int:
    """The worker processes a batch uses by default: the cores this process may run on."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except AttributeError:  # not Linux
        return max(os.cpu_count() or 1, 1)


@contextmanager
def one_thread_per_worker() -> Iterator[None]:
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


def run_serial(clips: list[Clip], out_dir: str | os.PathLike, options: BatchOptions, parameters: str, *,
               finished: Finished) -> None:
    """Convert ``clips`` one after another in this process, each result to ``finished`` as it comes.
    Ctrl-C stops the clip in hand (its temporaries removed) and is raised."""
    for clip in clips:
        finished(clip, convert_file(clip, out_dir, options, parameters))


def run_pool(clips: list[Clip], out_dir: str | os.PathLike, options: BatchOptions, parameters: str, *,
             jobs: int, finished: Finished) -> None:
    """Convert ``clips`` in ``jobs`` worker processes, the largest first; each result to ``finished``
    as it comes (in the order they finish).

    A worker that dies fails its clip ("its worker process died") and is replaced; the
    batch goes on. Ctrl-C (KeyboardInterrupt) lets the clips being converted finish,
    starts no more, and is raised again; a second Ctrl-C ends the workers at once.
    """
    context = _worker_context()
    queue = largest_first(clips)
    queue.reverse()  # pop() from the end
    with one_thread_per_worker():
        workers: list[_Worker] = []
        running: dict[Future, _Worker] = {}

        def hand_out() -> None:  # one clip per worker at a time: Ctrl-C then has only those to wait for
            for index, worker in enumerate(workers):
                if queue and worker.clip is None:
                    clip = queue.pop()
                    try:
                        future = worker.submit(convert_file, clip, out_dir, options, parameters)
                    except BrokenProcessPool:  # it died idle: a new one takes the clip
                        worker.close()
                        worker = workers[index] = _Worker(context)
                        future = worker.submit(convert_file, clip, out_dir, options, parameters)
                    worker.clip = clip
                    running[future] = worker

        def collect(future: Future) -> None:
            worker = running.pop(future)
            clip, worker.clip = worker.clip, None
            try:
                result = future.result()
            except BrokenProcessPool:
                result = FileResult(str(clip.source), "failed",
                                    error="its worker process died while converting it (out of memory, or killed)")
                clear_temporaries(clip, out_dir, options)
                worker.close()
                workers.remove(worker)
                if queue:
                    workers.append(_Worker(context))
            finished(clip, result)

        def drain() -> None:  # collect what finishes, handing out the queue (empty after Ctrl-C)
            hand_out()
            while running:
                for future in wait(list(running), return_when=FIRST_COMPLETED)[0]:
                    # Whole or not at all: a Ctrl-C between taking a finished clip off `running` and
                    # reporting it lost the clip (its outputs complete, the batch said "not done").
                    with ctrl_c_held():
                        collect(future)
                hand_out()

        try:
            # The forkserver and the workers start with Ctrl-C held back (blocked: the mask passes through
            # exec and fork), so that one pressed while they import prints no traceback of theirs; the
            # batch hears it when they are started, as it would while they work, and ends them cleanly.
            with ctrl_c_held():
                workers.extend(_Worker(context) for _ in range(min(jobs, len(clips))))
            drain()
        except KeyboardInterrupt:
            queue.clear()
            try:  # the clips in hand finish (the workers ignore Ctrl-C); a second Ctrl-C ends them
                drain()
            except KeyboardInterrupt:
                for worker in workers:
                    worker.kill()
            for worker in workers:
                worker.close()
            for worker in running.values():  # ended mid-clip: what they were writing goes
                clear_temporaries(worker.clip, out_dir, options)
            raise
        for worker in workers:
            worker.close()


class _Worker:
    """One worker process, as a pool of one: a death costs the clip it holds and no other.

    pid : a future of the process's pid, the first task it runs
    clip : the clip it is converting, None when idle
    """

    def __init__(self, context) -> None:
        self.pool = ProcessPoolExecutor(max_workers=1, mp_context=context, initializer=_worker_start,
                                        initargs=(os.getpid(),))
        self.pid = self.pool.submit(os.getpid)  # also starts the process now, not at its first clip
        self.clip: Clip | None = None

    def submit(self, function, *args) -> Future:
        return self.pool.submit(function, *args)

    def kill(self) -> None:
        """End the process now, mid-clip (a second Ctrl-C)."""
        try:
            pid = self.pid.result(timeout=_STARTING)
        except (BrokenProcessPool, CancelledError, TimeoutError):  # never started, or dead already
            return
        # The processes this one started, so never another that took a freed pid.
        for process in multiprocessing.active_children():
            if process.pid == pid:
                process.terminate()

    def close(self) -> None:
        """Wait for the process to end (after its clip, when it holds one). A process still starting
        is let start first: it reads its queue's semaphores, which the executor's shutdown removes."""
        try:
            self.pid.result(timeout=_STARTING)
        except (BrokenProcessPool, CancelledError, TimeoutError):  # never started, or dead already
            pass
        self.pool.shutdown(wait=True, cancel_futures=True)


def _worker_context():
    """Workers fork from a server that has imported the pipeline once, so each starts warm
    (``spawn`` where there is no forkserver)."""
    if "forkserver" in multiprocessing.get_all_start_methods():
        context = multiprocessing.get_context("forkserver")
        context.set_forkserver_preload(_PRELOAD)
        return context
    return multiprocessing.get_context("spawn")


@contextmanager
def ctrl_c_held() -> Iterator[None]:
    """A Ctrl-C pressed while the block runs is held back and acted on when it ends, not lost.

    Processes started in the block never hear the terminal's Ctrl-C, which is the batch's to handle:
    SIGINT is blocked in this thread, and the mask passes through fork and exec (their imports print
    no traceback). Where another thread of this process takes the signal instead, a handler notes it
    (not where the handler was installed by C code, which Python cannot put back).
    """
    from multiprocessing import resource_tracker

    if threading.current_thread() is not threading.main_thread():  # no signals here: nothing to hold
        yield
        return
    # Started first: starting it unblocks SIGINT in this thread (resource_tracker.ensure_running).
    resource_tracker.ensure_running()
    pressed: list[bool] = []
    before_handler = signal.getsignal(signal.SIGINT)
    noting = before_handler is not None
    if noting:
        signal.signal(signal.SIGINT, lambda *_: pressed.append(True))
    before = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        try:
            if signal.SIGINT not in before:
                signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})  # one pressed meanwhile arrives now
        finally:
            if noting:
                signal.signal(signal.SIGINT, before_handler)  # (which first runs the handlers of signals arrived)
    if pressed:
        if callable(before_handler):
            before_handler(signal.SIGINT, None)  # Python's own raises KeyboardInterrupt
        elif before_handler == signal.SIG_DFL:
            os.kill(os.getpid(), signal.SIGINT)  # what it would have done: end the process


def _ended(pid: int) -> bool:
    """Whether process ``pid`` has ended and waits to be reaped (a zombie; Linux's ``/proc`` tells, elsewhere
    False): a caller that reads the batch's output to its end before reaping it would wait for ever on the
    workers, who hold the batch's stdout and stderr."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as stat:
            return stat.read().rpartition(b")")[2].split()[0] in (b"Z", b"X")
    except (OSError, IndexError):
        return False


def _worker_start(batch_pid: int) -> None:
    """In each worker: Ctrl-C is the batch's to handle (it lets running clips finish), and the
    worker ends itself when the batch process is gone (killed with SIGKILL, say), instead of
    waiting for work forever and holding the batch's stdout open."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    import importlib

    from .memory import keep_freed_memory

    keep_freed_memory()

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
            if _ended(batch_pid):  # a zombie still takes signals: killed, not yet reaped by whoever started it
                os._exit(1)

    threading.Thread(target=watch, name="batch-watch", daemon=True).start()
