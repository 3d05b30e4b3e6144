"""Safe file writing: whole files or nothing, a set of files together, never over an input."""

from __future__ import annotations

import errno
import glob
import hashlib
import io
import os
import secrets
import stat
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..core.errors import InputError, MocapError

__all__ = ["OutputExistsError", "OutputSet", "atomic_write", "write_files", "same_file", "remove_stale_temporaries",
           "digest_of", "digest_of_file", "read_limited", "read_stream", "regular_file", "write_all", "not_a_folder",
           "LIMITS"]

#: The largest file of each kind read, in bytes: a clip (a 500,000-frame take of a 100-joint rig is about
#: 0.6 GB of text), a character (a skin, a glTF), and any small text (a pipeline file, a joint map, a
#: trails file, a manifest, MakeHuman's weights). Past it, one line and nothing read: a file of zeros or a
#: zip bomb once read until memory ran out.
LIMITS = {"clip": 1 << 30, "character": 1 << 30, "text": 64 << 20}


def _size(count: int) -> str:
    return f"{count / (1 << 30):.3g} GiB" if count >= 1 << 30 else f"{count / (1 << 20):.3g} MiB"


def regular_file(path: str | os.PathLike, *, what: str, label: str | None = None) -> os.stat_result:
    """The ``os.stat`` of ``path`` (links followed) when it is a regular file; InputError naming what it is
    otherwise (a folder, a FIFO, a device: reading a FIFO or /dev/zero blocks or never ends). OSError
    (no such file, permission) as ``os.stat`` raises it."""
    info = os.stat(path)
    if not stat.S_ISREG(info.st_mode):
        kind = ("a folder" if stat.S_ISDIR(info.st_mode) else "a FIFO" if stat.S_ISFIFO(info.st_mode)
                else "a device" if stat.S_ISCHR(info.st_mode) or stat.S_ISBLK(info.st_mode)
                else "a socket" if stat.S_ISSOCK(info.st_mode) else "not a regular file")
        raise InputError(f"is {kind}, not a {what}", source=label or str(path))
    return info


def read_limited(path: str | os.PathLike, *, limit: int, what: str, label: str | None = None) -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes (`regular_file`); InputError past it."""
    label = label or str(path)
    info = regular_file(path, what=what, label=label)
    if info.st_size > limit:
        raise InputError(f"is {_size(info.st_size)}; a {what} is read up to {_size(limit)}", source=label)
    with open(path, "rb") as stream:
        return read_stream(stream, limit=limit, what=what, label=label, expected=info.st_size)


#: What `read_stream` asks a stream for at a time when it does not know the size.
READ_PIECE = 16 << 20


def read_stream(stream, *, limit: int, what: str, label: str, expected: int | None = None) -> bytes:
    """At most ``limit`` bytes of a binary stream (standard input); InputError when there are more.

    Read a piece at a time (first ``expected`` bytes and one more, for a file whose size is known): a
    stream asked for ``limit`` bytes at once is given a buffer that size before anything is read, 1 GiB
    for every clip, which a machine that does not overcommit memory refuses (MemoryError).
    """
    pieces: list[bytes] = []
    total = 0
    want = min(limit, expected if expected is not None else READ_PIECE) + 1
    while True:
        piece = stream.read(want)
        if piece is None:  # a non-blocking stream with nothing yet: what was read is not the whole
            raise InputError(f"could not be read whole (a non-blocking stream gave nothing after {total} bytes)",
                             source=label)
        if isinstance(piece, str):
            piece = piece.encode("utf-8")
        if not piece:
            break
        pieces.append(piece)
        total += len(piece)
        if total > limit:
            raise InputError(f"is over {_size(limit)}; a {what} is read up to {_size(limit)}", source=label)
        want = min(limit + 1 - total, READ_PIECE)
    return b"".join(pieces)


def digest_of(data: bytes | list[bytes]) -> str:
    """``sha256:<hex>`` of bytes, or of a list of pieces taken as one file."""
    digest = hashlib.sha256()
    for piece in [data] if isinstance(data, (bytes, bytearray, memoryview)) else data:
        digest.update(piece)
    return "sha256:" + digest.hexdigest()


def digest_of_file(path: str | os.PathLike) -> str:
    """``sha256:<hex>`` of a file's bytes, read in pieces (a long clip is not held twice); OSError as opening raises
    it, and for what is not a regular file (a FIFO would block, a device never end)."""
    import errno

    if not stat.S_ISREG(os.stat(path).st_mode):
        raise OSError(errno.EINVAL, "not a regular file", str(path))
    with open(path, "rb") as stream:
        return "sha256:" + hashlib.file_digest(stream, "sha256").hexdigest()


class OutputExistsError(MocapError, FileExistsError):
    """The output file is there already and overwriting was not allowed."""

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        super().__init__(f"{path} exists")


def write_all(stream, data: bytes) -> None:
    """Write all of ``data`` to a binary stream, or raise OSError.

    A buffered stream writes everything or raises; a raw one (``sys.stdout.buffer`` under
    ``python -u`` or ``PYTHONUNBUFFERED``, as containers and CI often set) may write part and say
    how much: on a full disk the rest was lost and the command ended well. Here the rest is
    written again, and the disk's own error comes with it.
    """
    written = stream.write(data)
    if not isinstance(stream, io.RawIOBase):  # buffered, or a file-like object of the caller's: it took it all
        return
    view = memoryview(data)
    while True:
        if written is None or written <= 0:  # (a non-blocking stream that would block; or nothing taken)
            raise OSError(errno.EAGAIN if written is None else errno.EIO, "the output stream took no more")
        if written >= len(view):
            return
        view = view[written:]
        written = stream.write(view)


def not_a_folder(folder: str | os.PathLike) -> str | None:
    """Why outputs cannot go into ``folder``, in a line, when it or a folder above it exists and is not a
    folder (a file, a link to nothing); None when they can. A file on the way (``-o afile/sub``) is then
    refused as the folder itself is, before any work (it was "Not a directory" from the write, exit 1,
    after the whole run)."""
    folder = Path(folder)
    for path in (folder, *folder.parents):
        if path.exists() and path.is_dir():
            return None
        if path.exists() or path.is_symlink():
            return f"{folder}: exists and is not a folder" if path == folder else f"{folder}: {path} exists and is not a folder"
    return None


def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """Whether two paths name one file: the same path, a link to it, or a hard link."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return Path(a).resolve() == Path(b).resolve()


class OutputSet:
    """Files written as one set: each to a temporary file beside its target, all renamed on `commit`.

    Until the commit the targets are untouched; `abort` (or leaving the
    ``with`` block by an exception) removes the temporary files, so a failure
    leaves every folder as it was. Renames happen in the order files were
    added: add the file that marks the set complete (a manifest) last.
    A file's data is bytes or an iterable of byte pieces (streamed to disk as
    they come, so a long clip's text need not be held in memory).
    """

    def __init__(self, *, overwrite: bool = False) -> None:
        self.overwrite = overwrite
        self.pending: list[tuple[str, Path]] = []
        self.created: list[Path] = []  # folders made for the set, removed again by abort
        self.live: list[int] = []  # locks on the temporary files, held until the set is in place (`_live`)
        self.unwritten: dict[str, int] = {}  # temporary -> its descriptor, for files reserved and not yet written
        self.written: set[str] = set()  # temporaries whose data is all written

    def add(self, path: str | os.PathLike, data) -> str:
        """Write ``data`` to a temporary file for ``path``; its ``sha256:<hex>`` digest."""
        return self.reserve(path)(data)

    def reserve(self, path: str | os.PathLike) -> Callable[[Any], str]:
        """A temporary file for ``path``, its place among the renames taken now; the function that writes
        ``data`` into it and returns its digest, once. It touches only its own file and entries: it may run
        on another thread (the job writes the GLB on the thread that built it while the BVH is written), as
        long as that thread is done before the set is committed. A file reserved and never written (or
        whose writing failed) is not renamed onto its target, and its temporary is removed."""
        path = Path(path)
        if path.exists() and not self.overwrite:
            raise OutputExistsError(path)
        folder = path.parent if str(path.parent) else Path(".")
        try:
            missing = [f for f in (folder, *folder.parents) if not f.exists()]
            folder.mkdir(parents=True, exist_ok=True)
            self.created.extend(reversed(missing))
            # Locked before it has a temporary's name (`_live`): another run clearing leftovers never sees
            # it unheld, even in the moment between making it and locking it.
            fd, new = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".new", dir=folder)
            self.live.append(_hold(fd))
            tmp = new[: -len(".new")] + ".tmp"
            try:
                os.rename(new, tmp)
            except OSError:
                _remove(new)
                os.close(fd)
                raise
        except OSError as error:
            raise OSError(error.errno, error.strerror or str(error), str(path)) from None
        self.pending.append((tmp, path))
        self.unwritten[tmp] = fd

        def write(data) -> str:
            digest = hashlib.sha256()
            try:
                with os.fdopen(self.unwritten.pop(tmp), "wb") as handle:
                    for piece in [data] if isinstance(data, (bytes, bytearray, memoryview)) else data:
                        handle.write(piece)
                        digest.update(piece)
                    handle.flush()
                    os.fsync(handle.fileno())
                os.chmod(tmp, 0o644)
            except OSError as error:
                # Name the file the user asked for, not our temporary one.
                raise OSError(error.errno, error.strerror or str(error), str(path)) from None
            self.written.add(tmp)
            return "sha256:" + digest.hexdigest()

        return write

    def commit(self, *, retire_first: list[Path] = (), late: list[Path] = ()) -> None:
        """Rename every temporary file onto its target, in order.

        retire_first : files taken away before anything is renamed (moved aside, deleted once the set
            is in place): the old manifest (so that while the renames run no manifest can vouch for
            a half-replaced set) and old outputs this set no longer has.
        late : targets renamed after the others but before the last one added (the manifest)
        """
        for tmp, path in [item for item in self.pending if item[0] not in self.written]:  # reserved, never written
            fd = self.unwritten.pop(tmp, None)  # (None: its writer took it and failed)
            if fd is not None:
                os.close(fd)
            _remove(tmp)  # (before it leaves the list abort clears, so it is never left behind)
            self.pending.remove((tmp, path))
        if late and len(self.pending) > 1:
            last = self.pending[-1]
            late_set = {Path(path) for path in late}
            self.pending = ([item for item in self.pending[:-1] if item[1] not in late_set]
                            + [item for item in self.pending[:-1] if item[1] in late_set] + [last])
        # The files the set replaces are kept aside, by a hard link (each stays in place), and the ones it
        # retires are moved aside, until every rename is done: a rename that fails (an immutable file, say)
        # puts them all back, so the folder is as it was, instead of holding a new BVH beside the old GLB
        # and no manifest. The kept copies have a temporary's name, so a run killed meanwhile leaves what
        # the next run clears (as the retired files were deleted before). Where the file system has no
        # hard links, a replaced file is not kept: a live output is never moved away.
        kept: list[tuple[str, Path]] = []
        placed: list[Path] = []
        replaced: list[Path] = []
        unkept: set[Path] = set()
        retired = 0
        try:
            for old in retire_first:
                _keep_aside(Path(old), kept, move=True)
            retired = len(kept)
            for _, path in self.pending:
                if not _keep_aside(path, kept, move=False):
                    unkept.add(path)
            while self.pending:
                tmp, path = self.pending[0]
                placed.append(path)  # (before: a Ctrl-C just after the rename is undone too)
                try:
                    os.replace(tmp, path)
                except OSError as error:
                    raise OSError(error.errno, error.strerror or str(error), str(path)) from None
                replaced.append(path)
                self.pending.pop(0)
        except BaseException:
            had = {path for _, path in kept} | unkept  # (a file replaced with no copy kept stays: the new one)
            for path in placed:
                if path not in had:
                    try:
                        _remove(str(path))
                    except OSError:
                        pass
            # A file replaced with no copy kept cannot go back: then the old manifest must not come back to
            # vouch for a set half replaced (it stays retired, as it was before copies were kept).
            restore = kept if not unkept.intersection(replaced) else kept[retired:]
            for backup, path in reversed(restore):
                try:
                    os.replace(backup, path)
                    _remove(backup)  # (a link to the file still in place: renaming onto itself does nothing)
                except OSError:  # (what cannot be put back stays under its temporary's name)
                    pass
            for backup, _ in kept[: len(kept) - len(restore)]:  # the retired ones not put back
                try:
                    _remove(backup)
                except OSError:
                    pass
            raise
        self.created.clear()
        for backup, _ in kept:
            try:
                _remove(backup)
            except OSError:  # (the next run clears it: a temporary's name)
                pass
        self._let_go()

    def _let_go(self) -> None:
        """Release the temporary files' locks (each now a target, or removed)."""
        for tmp in list(self.unwritten):  # (a writer still running on its thread may take its own meanwhile)
            fd = self.unwritten.pop(tmp, None)
            if fd is not None:
                os.close(fd)
        for live in self.live:
            os.close(live)  # (closing releases the lock)
        self.live.clear()

    def abort(self) -> None:
        """Remove the temporary files not yet renamed."""
        for tmp, _ in self.pending:
            _remove(tmp)
        for folder in reversed(self.created):  # only ones we made, and only while empty
            try:
                folder.rmdir()
            except OSError:
                break
        self.pending.clear()
        self.created.clear()
        self._let_go()

    def __enter__(self) -> OutputSet:
        return self

    def __exit__(self, *exc) -> None:
        self.abort()


def _hold(fd: int) -> int:
    """A second descriptor of a new temporary file, holding a lock on it until it is closed: the file is
    being written (`_live`). Where the system has no such locks, a descriptor that holds nothing."""
    live = os.dup(fd)
    try:
        import fcntl

        fcntl.flock(live, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except (ImportError, OSError):
        pass
    return live


def _live(path: Path) -> bool:
    """Whether another run is writing the temporary file at ``path`` now (it holds its lock, `_hold`)."""
    try:
        import fcntl
    except ImportError:
        return False
    try:
        probe = os.open(path, os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(probe, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    except OSError:
        return False
    finally:
        os.close(probe)
    return False


def remove_stale_temporaries(path: str | os.PathLike, *, keep: list[Path] = ()) -> list[Path]:
    """Delete temporary files that an interrupted write of ``path`` left beside it; the ones removed.

    Only names this module makes (``.<name>.<random>.tmp`` in the same
    folder) are touched: nothing else in the folder is, nor a temporary file another run is writing
    now (it holds a lock on it until its set is in place: two runs into one folder, a farm's retry
    beside its first try, once took each other's live files for a killed run's and deleted them).
    """
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    removed = []
    if folder.is_dir():
        # (".new": a file killed in the moment before it got its temporary's name; a live one is that
        # young, so only an old one is cleared)
        old = time.time() - 600.0
        for stale in [*folder.glob(f".{glob.escape(path.name)}.*.tmp"), *folder.glob(f".{glob.escape(path.name)}.*.new")]:
            if (stale.is_file() and not stale.is_symlink() and not any(same_file(stale, k) for k in keep)
                    and (stale.suffix == ".tmp" or stale.stat().st_mtime < old) and not _live(stale)):
                _remove(str(stale))
                removed.append(stale)
    return removed


def _keep_aside(path: Path, kept: list[tuple[str, Path]], *, move: bool) -> bool:
    """Keep the file at ``path`` (if any) under a temporary's name beside it, noted in ``kept``: moved
    there with ``move``, else linked (it stays in place); False where a file is there that could not be
    linked (a file system without hard links): it is not kept."""
    if not (path.exists() or path.is_symlink()) or (path.is_dir() and not path.is_symlink()):
        return True  # nothing to keep (a folder in the way is not the set's: renaming onto it fails, as it should)
    backup = str(path.parent / f".{path.name}.{secrets.token_hex(6)}.kept.tmp")
    try:
        if move:
            os.rename(path, backup)
        else:
            os.link(path, backup, follow_symlinks=False)
    except FileNotFoundError:
        return True
    except OSError as error:
        if not move:  # no hard links here (or none to this file): replaced without a copy kept, as before
            return False
        raise OSError(error.errno, error.strerror or str(error), str(path)) from None
    kept.append((backup, path))
    return True


def _remove(path: str) -> None:
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass


def atomic_write(path: str | os.PathLike, data: bytes, *, overwrite: bool = False) -> None:
    """Write ``data`` to ``path`` through a temporary file in the same folder.

    A reader sees either the old file or the whole new one; a crash or a full
    disk leaves no partial file behind.
    """
    write_files([(Path(path), data)], overwrite=overwrite)


def write_files(files, *, overwrite: bool = False) -> None:
    """Write ``(path, data)`` pairs as one `OutputSet`: all of them, or (on any error) none."""
    files = [(Path(path), data) for path, data in files]
    if not overwrite:
        for path, _ in files:
            if path.exists():
                raise OutputExistsError(path)
    with OutputSet(overwrite=True) as output:
        for path, data in files:
            output.add(path, data)
        output.commit()
