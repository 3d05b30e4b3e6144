"""The compiled loops, where setup.py built them.

``kernels`` is ``core/_kernels.c`` (`io/bvh.py` takes ``io/_formatting.c`` itself, by `compiled`),
None where it was not built or where ``MOCAP_EXAGGERATE_NUMPY_ONLY`` is set in the environment (to
anything but 0 or nothing). Every module with a compiled loop runs its NumPy code where the loop is
None: the same bits, which the tests check loop by loop and, for whole jobs, by running the command
with the variable set (`tests/test_native.py`). The variable runs the NumPy code as an install
without a C compiler does: to check it, or to tell whether a fault is in the compiled code.
"""

from __future__ import annotations

import os
import threading

__all__ = ["ENABLED", "NUMPY_ONLY", "kernels", "frame_halves", "on_both_cores", "by_frame_halves"]

#: The environment variable that turns the compiled loops off for a process (read at import).
NUMPY_ONLY = "MOCAP_EXAGGERATE_NUMPY_ONLY"
#: Whether the compiled loops may be used (the variable is not set).
ENABLED = os.environ.get(NUMPY_ONLY, "") in ("", "0")

kernels = None
if ENABLED:
    try:
        from . import _kernels as kernels
    except ImportError:  # pragma: no cover - an install without a C compiler
        kernels = None


#: Frames below which a compiled loop is not shared between two threads (starting one costs more).
SHARE_FROM = 4096
_helper = None
#: Set on a thread while it runs a part of `on_both_cores`: a part asking to share again runs whole
#: (the one helper thread is busy with the other part; waiting for it there would never end).
_sharing = threading.local()


def _forget_helper() -> None:
    """In a child made by fork: the parent's helper thread was not copied, so its executor would take work
    and never do it (a worker forked from a process that had converted a long clip hung)."""
    global _helper
    _helper = None


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_helper)


def frame_halves(frames: int, *, per_item: int = 1) -> list[slice]:
    """``range(frames)`` as two halves where a second core can take one (a long clip), else as one slice.
    ``per_item``: how many frames' work each item is (for items that are not frames)."""
    if frames < 2 or frames * per_item < SHARE_FROM or (os.cpu_count() or 1) < 2 or getattr(_sharing, "on", False):
        return [slice(0, frames)]
    middle = frames // 2
    return [slice(0, middle), slice(middle, frames)]


def on_both_cores(run, parts: list[slice]) -> None:
    """``run(part)`` for each part, the last on this thread and the others on a helper thread at once.

    For the compiled loops, which let go of the GIL, work frame by frame, and write each frame where
    only that frame's call writes: the same bits as one call, in about half the time on two cores.
    """
    global _helper
    if len(parts) < 2:
        for part in parts:
            run(part)
        return
    if _helper is None:
        from concurrent.futures import ThreadPoolExecutor

        _helper = ThreadPoolExecutor(max_workers=1, thread_name_prefix="mocap-kernels")
    pending = [_helper.submit(_shared, run, part) for part in parts[:-1]]
    try:
        _shared(run, parts[-1])
    finally:
        for job in pending:
            job.result()


def _shared(run, part: slice) -> None:
    _sharing.on = True
    try:
        run(part)
    finally:
        _sharing.on = False


def by_frame_halves(make, frames: int, *, per_item: int = 1):
    """``make(slice(0, frames))``, made as its two halves at once where `frame_halves` splits the frames.

    For NumPy code whose every output frame is made from the same frame of its inputs alone
    (element-wise operations and reductions within a frame): NumPy lets go of the GIL inside its
    loops, so two threads share the work, and each frame's numbers are the ones a single call
    makes. ``make`` returns an array whose first axis is the frames, or dicts, tuples and lists of
    them (joined key by key, item by item).
    """
    parts = frame_halves(frames, per_item=per_item)
    if len(parts) < 2:
        return make(parts[0])
    made: dict[int, object] = {}
    on_both_cores(lambda part: made.__setitem__(part.start, make(part)), parts)
    return _joined([made[part.start] for part in parts])


def _joined(pieces: list):
    first = pieces[0]
    if isinstance(first, dict):
        return {key: _joined([piece[key] for piece in pieces]) for key in first}
    if isinstance(first, (tuple, list)):
        return type(first)(_joined(list(items)) for items in zip(*pieces))
    import numpy as np

    return np.concatenate(pieces)
