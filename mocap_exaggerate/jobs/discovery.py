"""Finding a batch's clips: walk a folder, match a glob, refuse what a batch cannot take safely.

`find_clips` walks the input folder (links followed once, loops reported) for
the files `glob_regex` matches, leaving out this tool's own outputs
(`is_output`) and reporting two clips whose outputs would be the same files
(`same_outputs`). `check_folders` refuses an input and output folder a batch
cannot use safely; `clashes` finds clips whose outputs would land on another
clip.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Iterable
from pathlib import Path

from ..core.errors import ConfigError
from .batch_types import Clip, FileResult

__all__ = ["DEFAULT_GLOB", "glob_regex", "find_clips", "same_outputs", "clashes", "foreign_clips", "check_folders", "is_output",
           "read_manifest", "source_size", "largest_first"]

#: Which files a batch takes: every .bvh at any depth (matched without regard to case).
DEFAULT_GLOB = "**/*.bvh"


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


def read_manifest(path: str | os.PathLike) -> dict | None:
    """The manifest at ``path`` as data; None when there is none or it does not read as one."""
    from ..io.files import LIMITS, read_limited

    try:  # (a FIFO named <clip>.json blocked; a manifest nested a million deep stopped a whole batch)
        info = json.loads(read_limited(path, limit=LIMITS["text"], what="manifest").decode("utf-8"))
    except (OSError, ValueError, RecursionError):  # (InputError is a ValueError)
        return None
    return info if isinstance(info, dict) and info.get("tool") == "mocap_exaggerate" else None


def is_output(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a BVH this tool wrote: the manifest beside it names it as its output.

    A batch does not take its own (or an earlier run's) outputs for clips.
    """
    path = Path(path)
    info = read_manifest(path.with_suffix(".json"))
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


def foreign_clips(clips: list[Clip], out_dir: str | os.PathLike) -> dict[Clip, Path]:
    """Clips whose BVH would replace one this tool did not write: clip -> that BVH.

    A BVH at the target with no manifest naming it and no pipeline file beside it (which a run renames
    before its BVH) is a clip, even outside the batch's folder (``batch in . --overwrite`` beside a
    capture of the same name): no clip is ever written over.
    """
    from .job import output_paths

    out = {}
    for clip in clips:
        targets = output_paths(Path(out_dir) / clip.relative.parent, clip.name)
        bvh = targets["bvh"]
        if not bvh.is_file() or is_output(bvh):
            continue
        # The pipeline file, which every run writes and renames before its BVH, tells a set a kill cut short;
        # not a .glb or a .json, which a capture folder may hold beside its clips (another tool's exports).
        if not targets["pipeline"].exists():
            out[clip] = bvh
    return out


def source_size(clip: Clip) -> int:
    """Bytes of ``clip``'s file; 0 when it cannot be read (its conversion says why)."""
    try:
        return clip.source.stat().st_size
    except OSError:
        return 0


def largest_first(clips: list[Clip]) -> list[Clip]:
    """``clips`` from the largest file down, in their given order where sizes are equal: no worker
    is then left with a long clip at the end while the others wait."""
    return sorted(clips, key=lambda clip: -source_size(clip))
