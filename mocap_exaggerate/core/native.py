"""The compiled loops, where setup.py built them, and the second core.

``kernels`` is ``core/_kernels.c`` (`io/bvh.py` takes ``io/_formatting.c`` itself, by `compiled`),
None where it was not built or where ``MOCAP_EXAGGERATE_NUMPY_ONLY`` is set in the environment (to
anything but 0 or nothing). Every module with a compiled loop runs its NumPy code where the loop is
None: the same bits, which the tests check loop by loop and, for whole jobs, by running the command
with the variable set (`tests/test_native.py`). The variable runs the NumPy code as an install
without a C compiler does: to check it, or to tell whether a fault is in the compiled code.

A long clip's frames are shared between two threads (`on_both_cores`, `by_frame_halves`) by the
compiled loops, which let go of the GIL, and by NumPy code that makes each frame from that frame
alone (NumPy lets go of it inside its loops): each frame's numbers are a single call's.
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


#: Frames below which work is not shared between two threads (starting one costs more).
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
    """``range(frames)`` as two halves where a second core can take one (a long clip), else as one slice
    (also inside a part of `on_both_cores`: the helper thread is busy with the other part).
    ``per_item``: how many frames' work each item is (for items that are not frames)."""
    if frames < 2 or frames * per_item < SHARE_FROM or (os.cpu_count() or 1) < 2 or getattr(_sharing, "on", False):
        return [slice(0, frames)]
    middle = frames // 2
    return [slice(0, middle), slice(middle, frames)]


def on_both_cores(run, parts: list[slice]) -> None:
    """``run(part)`` for each part, the last on this thread and the others on a helper thread at once.

    For work that lets go of the GIL (the compiled loops, NumPy's), is done frame by frame, and writes
    each frame where only that frame's call writes: the same bits as one call, in about half the
    time on two cores. Inside a part of another call the parts run one after the other on this
    thread (the one helper thread is busy with that call's other part: waiting for it would never end).
    """
    global _helper
    if len(parts) < 2 or getattr(_sharing, "on", False):
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
    """``run(part)`` as a part of `on_both_cores` (`_sharing` set meanwhile, and then as it was)."""
    was = getattr(_sharing, "on", False)
    _sharing.on = True
    try:
        run(part)
    finally:
        _sharing.on = was


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
        joined = [_joined(list(items)) for items in zip(*pieces)]
        return type(first)(*joined) if hasattr(first, "_fields") else type(first)(joined)  # (a NamedTuple too)
    import numpy as np

    return np.concatenate(pieces)
