"""Safe file writing: whole files or nothing, never over an input."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from ..errors import MocapError

__all__ = ["OutputExistsError", "atomic_write"]


class OutputExistsError(MocapError, FileExistsError):
    """The output file is there already and overwriting was not allowed."""


def atomic_write(path: Path, data: bytes, *, overwrite: bool = False) -> None:
    """Write ``data`` to ``path`` through a temporary file in the same folder.

    A reader sees either the old file or the whole new one; a crash or a full
    disk leaves no partial file behind.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise OutputExistsError(f"{path} exists; pass --overwrite to replace it")
    folder = path.parent if str(path.parent) else Path(".")
    folder.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=folder)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
