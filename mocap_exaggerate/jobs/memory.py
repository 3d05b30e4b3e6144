"""How this process's memory allocator treats the large NumPy arrays of a long clip (glibc only).

A clip of 100,000 frames makes temporaries of hundreds of MB, each over glibc's largest
``mmap`` threshold (32 MiB): every one came as fresh pages from the kernel, zeroed and
faulted in, and went back when freed. That was 12.5 s of kernel time in a 45 s job.
`keep_freed_memory` has such blocks come from the heap and stay there for the next one
(37 s, 4.3 s in the kernel, the same peak). The command line sets it for its own process
and for its workers; a library user may call it. `malloc_thresholds` undoes what Dask's
nanny sets in its workers.

Neither does anything but on glibc (Linux), nor where the user set glibc's ``MALLOC_*_``
variables themselves.
"""

from __future__ import annotations

import os

__all__ = ["keep_freed_memory", "malloc_thresholds"]

#: glibc's ``mallopt`` parameters.
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD, _M_MMAP_MAX, _M_ARENA_MAX = -1, -3, -4, -8
#: The thresholds glibc's adaptive rule reaches at most on 64 bits: memory under 32 MiB comes from
#: the heap and is kept, up to 64 MiB free at its top.
_MMAP_MOST, _TRIM_MOST = 32 << 20, 64 << 20
#: Free memory at the heap's top that `keep_freed_memory` keeps (returned past it): 2 GiB, the most
#: ``mallopt``'s C int holds.
_KEEP = (1 << 31) - 1
_VARIABLES = ("MALLOC_TRIM_THRESHOLD_", "MALLOC_MMAP_THRESHOLD_", "MALLOC_MMAP_MAX_", "MALLOC_TOP_PAD_", "MALLOC_ARENA_MAX")
_DONE: dict[str, bool] = {}


def _mallopt(*pairs: tuple[int, int]) -> bool:
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt.argtypes = [ctypes.c_int, ctypes.c_int]  # (a value past a C int is refused, not cut short)
        return all(bool(libc.mallopt(parameter, value)) for parameter, value in pairs)
    except (OSError, AttributeError):  # not glibc
        return False


def _user_set() -> bool:
    """Whether the user set glibc's allocator themselves (its variables, or its tunables)."""
    return any(name in os.environ for name in _VARIABLES) or "glibc.malloc." in os.environ.get("GLIBC_TUNABLES", "")


def keep_freed_memory() -> bool:
    """Large blocks from the heap (no ``mmap``), and freed memory kept for the next (up to 2 GiB free at the
    heap's top): a long clip's temporaries reuse pages instead of faulting in fresh ones. Threads started
    later share the one heap (a thread's own would keep what it freed from the others: the GLB, built
    beside the BVH, raised a 100,000-frame job's peak by 0.47 GB). For a process that does one job, or a
    batch's worker (which keeps its largest clip's pages for the next; `tune` keeps its clip's);
    whether it was set."""
    if "keep" not in _DONE:
        _DONE["keep"] = not _user_set() and _mallopt(
            (_M_MMAP_MAX, 0), (_M_TRIM_THRESHOLD, _KEEP), (_M_ARENA_MAX, 1))
    return _DONE["keep"]


def malloc_thresholds() -> bool:
    """Where ``MALLOC_TRIM_THRESHOLD_`` (or ``MALLOC_MMAP_THRESHOLD_``) fixed glibc's thresholds for this
    process (Dask's nanny sets 65536), set them once to the most its adaptive rule would reach, so that
    large temporaries reuse the heap instead of faulting in fresh pages; whether they were set. Not
    glibc (or not Linux): nothing."""
    if "thresholds" not in _DONE:
        _DONE["thresholds"] = any(name in os.environ for name in _VARIABLES[:2]) and _mallopt(
            (_M_MMAP_THRESHOLD, _MMAP_MOST), (_M_TRIM_THRESHOLD, _TRIM_MOST))
    return _DONE["thresholds"]
