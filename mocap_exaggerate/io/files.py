"""Safe file writing: whole files or nothing, a set of files together, never over an input."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from ..errors import MocapError

__all__ = ["OutputExistsError", "atomic_write", "write_files", "same_file"]


class OutputExistsError(MocapError, FileExistsError):
    """The output file is there already and overwriting was not allowed."""

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        super().__init__(f"{path} exists")


def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """Whether two paths name one file: the same path, a link to it, or a hard link."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return Path(a).resolve() == Path(b).resolve()


def _temporary(path: Path, data: bytes) -> str:
    folder = path.parent if str(path.parent) else Path(".")
    folder.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=folder)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.chmod(tmp, 0o644)
    except BaseException:
        _remove(tmp)
        raise
    return tmp


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


def write_files(files: list[tuple[Path, bytes]], *, overwrite: bool = False) -> None:
    """Write several files as one set: every one to a temporary file first, then all renamed, in order.

    If any write fails (full disk, permissions) nothing is renamed and the
    temporary files are removed, so the folder keeps what it had. Put the
    file that marks the set complete (a manifest) last.
    """
    files = [(Path(path), data) for path, data in files]
    if not overwrite:
        for path, _ in files:
            if path.exists():
                raise OutputExistsError(path)
    written: list[tuple[str, Path]] = []
    path = files[0][0] if files else Path(".")
    try:
        for path, data in files:
            written.append((_temporary(path, data), path))
        for number, (tmp, path) in enumerate(written):
            os.replace(tmp, path)
            written[number] = ("", path)
    except OSError as error:
        # Name the file the user asked for, not our temporary one.
        raise OSError(error.errno, error.strerror or str(error), str(path)) from None
    finally:
        for tmp, _ in written:
            if tmp:
                _remove(tmp)
