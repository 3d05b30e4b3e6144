"""BVH reading and writing.

The header (a few hundred lines) is parsed token by token with line numbers
kept for error messages. The MOTION block, which is nearly all of a file, is
never walked line by line in Python: its bytes are classified with NumPy to
count the values on each line, and the numbers are converted in one call.
Writing formats whole blocks of frames with one ``%`` operation.

Position channels replace the joint's OFFSET (the convention of bvhio,
Blender, MotionBuilder and most readers) or add to it (Reallusion/iClone and
MakeHuman exports): ``root_offset="auto"`` tells the two apart on reading
(`position_mode`), and the skeleton remembers which (``Skeleton.positions``).
The writer writes the standard convention, replacing, whatever the input used
(``positions="standard"``), so every reader puts the joints where we computed
them; ``positions="input"`` writes the input's own convention back (adding,
for re-import into iClone). Joints without position channels use the OFFSET.
"""

from __future__ import annotations

import io
import logging
import os
import re
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import BinaryIO

import numpy as np

from ..core.errors import InputError, check_choice
from ..core.motion import Motion
from ..core.native import ENABLED as _NATIVE
from ..core.rotations import euler_blocks, quat_from_joint_euler
from ..core.skeleton import POSITION_CHANNELS, ROTATION_CHANNELS, Skeleton
from .files import atomic_write, write_all

__all__ = ["BVHReport", "read_bvh", "read_source", "load_bvh", "save_bvh", "format_bvh", "iter_bvh", "format_fixed",
           "motion_channels", "BVH_POSITIONS", "check_bvh_positions", "written_positions"]

log = logging.getLogger(__name__)

_CHANNEL_NAMES = {c.lower(): c for c in POSITION_CHANNELS + ROTATION_CHANNELS}

try:  # optional: setup.py builds it where there is a C compiler (the motion lines read and written)
    from . import _formatting as _compiled
except ImportError:  # pragma: no cover - the NumPy code reads the same values and writes the same bytes
    _compiled = None
if not _NATIVE:  # MOCAP_EXAGGERATE_NUMPY_ONLY (core/native.py)
    _compiled = None

_WHITESPACE = np.zeros(256, dtype=bool)
_WHITESPACE[[9, 10, 11, 12, 13, 32]] = True

#: A number as BVH exporters write it (no digit separators, hex or words); nan/inf are caught apart.
_NUMBER_RE = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$", re.ASCII)
_WHOLE_RE = re.compile(r"^[+-]?[0-9]+$")
#: Largest magnitude accepted for an offset or a channel value: far beyond any capture
#: (a kilometre in millimetres is 1e6), small enough that squares and sums stay finite.
MAX_VALUE = 1e9
#: Frame rates accepted, from the header or given: slower than 1 fps or faster than
#: 10,000 fps is a wrong header, not a clip.
FPS_RANGE = (1.0, 10000.0)
#: Deepest hierarchy and most joints read: deeper chains are not skeletons, and every
#: stage's cost grows with them. A character with a face and fingers has a few hundred; a
#: 2,000-joint star converts in about 6 s (10,000 took 30 s, and before issue 28 never ended).
MAX_DEPTH = 1000
MAX_JOINTS = 2000
#: Most frames read: 500,000 is 69 minutes at 120 fps, past any take; a run holds 17-20 kB a frame
#: of a 31-joint rig at its peak, so a longer clip is cut into takes first (refused in one line before any work).
MAX_FRAMES = 500_000
#: Most joints times frames read: a run holds about 0.45 kB a joint a frame at its peak (0.6 kB resident, with the
#: default sub-joints; more sub-joints a link cost more), so
#: 30 million (500,000 frames of 60 joints, 15,000 of 2,000) is about 18 GB; more is cut into takes first.
MAX_JOINT_FRAMES = 30_000_000

#: How position channels are read (see `read_bvh`), and the up axes one can give.
ROOT_OFFSET_MODES = ("auto", "replace", "add")
UP_AXES = ("auto", "x", "y", "z")
#: How the writer writes position channels: ``standard`` replaces the OFFSET (what Blender,
#: bvhio and MotionBuilder read), ``input`` in the convention the clip was read in.
BVH_POSITIONS = ("standard", "input")

_MOTION_RE = re.compile(rb"^[ \t]*MOTION[ \t]*\r?$", re.MULTILINE | re.IGNORECASE)
_FRAMES_RE = re.compile(r"^\s*Frames\s*:\s*(\S*)\s*$", re.IGNORECASE)
_FRAME_TIME_RE = re.compile(r"^\s*Frame\s+Time\s*:\s*(\S*)\s*$", re.IGNORECASE)


@dataclass
class BVHReport:
    """What the reader noticed while reading one file.

    ``declared_frames`` is the header's ``Frames:``; ``data_lines`` the number
    of non-empty motion lines found; ``header_fps`` the rate the header states.
    """

    source: str
    declared_frames: int = 0
    data_lines: int = 0
    header_fps: float = 0.0
    root_offset: str = "replace"
    warnings: list[str] = field(default_factory=list)


# ---------------------------------------------------------------------------- reading


def read_bvh(
    source: str | os.PathLike | bytes | BinaryIO,
    *,
    name: str | None = None,
    fps: float | None = None,
    root_offset: str = "auto",
    up: str = "auto",
) -> tuple[Motion, BVHReport]:
    """Read a BVH clip.

    Parameters
    ----------
    source : path, ``"-"`` for standard input, raw bytes, or a binary file
    name : how to call the source in messages (defaults to the path)
    fps : frame rate that overrides the header's ``Frame Time`` (some
        exporters write a wrong one)
    root_offset : ``replace``: position channels replace the joint's OFFSET;
        ``add``: they add to it; ``auto``: `position_mode` decides
    up : ``x``, ``y`` or ``z``: the axis the body stands along; ``auto``:
        worked out from the rest pose (`Skeleton.up_axis`)

    Returns
    -------
    motion : Motion
    report : BVHReport with the counts and warnings

    Raises
    ------
    InputError
        with ``file:line: problem`` for anything malformed.
    """
    check_choice("root_offset", root_offset, ROOT_OFFSET_MODES, error=lambda m: InputError(m, source="root_offset"))
    check_choice("up", up, UP_AXES, error=lambda m: InputError(m, source="up"))
    data, label = read_source(source, name)
    report = BVHReport(source=label)
    if b"\x00" in data[:4096]:
        raise InputError("not a BVH file (binary data)", source=label, line=1)
    if b"\r" in data and data.count(b"\r") != data.count(b"\r\n"):
        # Old Mac line ends (CR alone): read them as LF; CRLF stays as it is.
        data = data.replace(b"\r\n", b"\n").replace(b"\r", b"\n")

    motion_match = _MOTION_RE.search(data)
    if motion_match is None:
        last_line = data.rstrip().count(b"\n") + 1
        if not data.strip():
            raise InputError("file is empty", source=label, line=1)
        try:
            _parse_header(_decode(data, label), label)  # reports the first header fault, if any
        except InputError as error:
            if error.line != last_line or "file ends" in error.message:
                raise
            # A fault on the last line of a file with no MOTION: the file stops inside the hierarchy.
            raise InputError(f"{error.message}; the file ends on this line, inside the hierarchy (truncated?)",
                             source=label, line=last_line) from None
        raise InputError("no MOTION section after the hierarchy", source=label, line=last_line)
    header_text = _decode(data[: motion_match.start()], label)
    skeleton = _parse_header(header_text, label)
    motion_line = data.count(b"\n", 0, motion_match.start()) + 1

    # "Frames:" and "Frame Time:" on the next non-blank lines.
    pos = _line_end(data, motion_match.end())
    line_no = motion_line
    declared_frames = frame_time = None
    for what in ("Frames", "Frame Time"):
        while True:
            if pos >= len(data):
                raise InputError(f"missing '{what}:' line after MOTION", source=label, line=line_no)
            end = _line_end(data, pos)
            line_no += 1
            line = _decode(data[pos:end], label)
            pos = end
            if line.strip():
                break
        if what == "Frames":
            m = _FRAMES_RE.match(line)
            if not m:
                raise InputError(f"expected 'Frames: <count>', found {line.strip()!r}", source=label, line=line_no)
            count = m.group(1)
            if not _WHOLE_RE.match(count):  # (plain digits: Python's int() also takes 1_000 and other scripts' digits)
                raise InputError(f"frame count {count[:20]!r} is not a whole number", source=label, line=line_no)
            declared_frames = int(count) if len(count) <= 18 else MAX_FRAMES + 1
            if declared_frames < 0:
                raise InputError(f"frame count {declared_frames} is negative", source=label, line=line_no)
            if declared_frames > MAX_FRAMES:
                shown = _short_number(count)
                raise InputError(f"'Frames: {shown}': at most {MAX_FRAMES:,} frames are read (cut the take into "
                                 f"shorter clips)", source=label, line=line_no)
            if declared_frames * skeleton.num_joints > MAX_JOINT_FRAMES:
                raise InputError(f"'Frames: {declared_frames}' of {skeleton.num_joints} joints: at most "
                                 f"{MAX_JOINT_FRAMES:,} joints times frames are read (cut the take into shorter clips)",
                                 source=label, line=line_no)
            frames_line = line_no
        else:
            m = _FRAME_TIME_RE.match(line)
            if not m:
                raise InputError(f"expected 'Frame Time: <seconds>', found {line.strip()!r}", source=label, line=line_no)
            if not _NUMBER_RE.match(m.group(1)):  # (a plain decimal, as every other number in the file)
                raise InputError(f"frame time {m.group(1)[:20]!r} is not a number", source=label, line=line_no)
            frame_time = float(m.group(1))
            if fps is None and not (np.isfinite(frame_time) and FPS_RANGE[0] <= 1.0 / max(frame_time, 1e-300) <= FPS_RANGE[1]):
                raise InputError(
                    f"frame time {m.group(1)} is not a frame rate between {FPS_RANGE[0]:g} and {FPS_RANGE[1]:g} fps "
                    "(give the frame rate, fps, to read it)",
                    source=label,
                    line=line_no,
                )
    report.declared_frames = declared_frames
    report.header_fps = 1.0 / frame_time if frame_time and frame_time > 0 else 0.0
    if declared_frames == 0:
        raise InputError("'Frames: 0': the clip has no frames", source=label, line=frames_line)

    values = _parse_motion(
        data[pos:], skeleton.num_channels, declared_frames, first_line=line_no + 1, label=label, report=report
    )

    if fps is not None:
        check_fps(fps, label)
        if report.header_fps and abs(report.header_fps - fps) > 1e-6 * fps:
            report.warnings.append(f"frame rate set to {fps:g} fps (header says {report.header_fps:g})")
        frame_time = 1.0 / fps
    if up != "auto":
        skeleton = replace(skeleton, up="xyz".index(up))
    if root_offset == "auto":
        root_offset = position_mode(skeleton, values)
    if root_offset != skeleton.positions:
        skeleton = replace(skeleton, positions=root_offset)
    report.root_offset = root_offset
    motion = _motion_from_channels(skeleton, values, frame_time)
    return motion, report


def position_mode(skeleton: Skeleton, values: np.ndarray) -> str:
    """``add`` when the position channels of a clip (``values``, ``(F, C)``) are displacements
    from the joints' OFFSETs, ``replace`` when they are the positions themselves.

    Two signatures of ``add``. Joints below the root with position channels whose
    values stay small beside their OFFSETs (MakeHuman writes six channels on every
    joint, mostly zeros): replaced, every such bone would shrink to nothing. And a
    root OFFSET of about the hips' height with root channels near zero (Reallusion):
    replaced, the body stands about its hip height below the floor; added, on it.
    """
    columns = _position_columns(skeleton)
    if not columns:
        return "replace"
    height = skeleton.height()
    below = [j for j in columns if j != 0 and np.linalg.norm(skeleton.offsets[j]) > 1e-3 * height]
    if below:
        small = [np.median(np.linalg.norm(_filled(values, columns[j]), axis=1)) < 0.25 * np.linalg.norm(skeleton.offsets[j])
                 for j in below]
        return "add" if sum(small) * 2 > len(small) else "replace"
    if 0 not in columns:
        return "replace"
    up = skeleton.up_axis()
    lift = skeleton.offsets[0, up]
    if abs(lift) < 0.25 * height:
        return "replace"
    frames = np.unique(np.linspace(0, len(values) - 1, min(len(values), 64)).astype(int))
    sample = _motion_from_channels(replace(skeleton, positions="replace"), values[frames], 1.0)
    floor = float(np.median(sample.world_positions()[..., up].min(axis=1)))  # where the feet are, replaced
    return "add" if abs(floor + lift) < abs(floor) else "replace"


def _position_columns(skeleton: Skeleton) -> dict[int, list[tuple[int, int]]]:
    """For each joint with position channels, its (column, axis) pairs."""
    columns: dict[int, list[tuple[int, int]]] = {}
    column = 0
    for j, names in enumerate(skeleton.channels):
        for name in names:
            if name in POSITION_CHANNELS:
                columns.setdefault(j, []).append((column, "XYZ".index(name[0])))
            column += 1
    return columns


def _filled(values: np.ndarray, pairs: list[tuple[int, int]]) -> np.ndarray:
    """``(F, 3)`` the channel values of one joint's position channels, 0 on axes it has none for."""
    out = np.zeros((len(values), 3))
    for column, axis in pairs:
        out[:, axis] = values[:, column]
    return out


def check_fps(fps: float, source: str = "fps") -> None:
    """InputError unless ``fps`` is a frame rate within `FPS_RANGE`."""
    if not (isinstance(fps, (int, float)) and FPS_RANGE[0] <= fps <= FPS_RANGE[1]):
        raise InputError(f"fps must be between {FPS_RANGE[0]:g} and {FPS_RANGE[1]:g}, got {fps!r}", source=source)


def load_bvh(path: str | os.PathLike | BinaryIO, *, fps: float | None = None) -> Motion:
    """Read a BVH clip and log the reader's warnings. See `read_bvh`."""
    motion, report = read_bvh(path, fps=fps)
    for warning in report.warnings:
        log.warning("%s: %s", report.source, warning)
    return motion


def read_source(source, name: str | None = None) -> tuple[bytes, str]:
    """The bytes of a path, ``"-"`` (standard input), bytes or a binary stream, and how to name it in messages."""
    if isinstance(source, (bytes, bytearray)):
        return bytes(source), name or "<bytes>"
    from .files import LIMITS, read_limited, read_stream

    if hasattr(source, "read"):
        label = name or getattr(source, "name", "<stream>")
        return read_stream(source, limit=LIMITS["clip"], what="clip", label=str(label)), label
    if str(source) == "-":
        label = name or "<stdin>"
        return read_stream(sys.stdin.buffer, limit=LIMITS["clip"], what="clip", label=label), label
    path = Path(source)
    label = name or str(path)
    try:
        return read_limited(path, limit=LIMITS["clip"], what="BVH file", label=label), label
    except IsADirectoryError:
        raise InputError("is a folder, not a BVH file", source=label) from None
    except FileNotFoundError:
        if path.is_symlink():
            raise InputError(f"a link to {os.readlink(path)}, which does not exist", source=label) from None
        raise InputError("no such file", source=label) from None
    except PermissionError:
        raise InputError("permission denied", source=label) from None


def _decode(data: bytes, label: str) -> str:
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        text = data.decode("latin-1")
    return text.lstrip("\ufeff")


def _short_number(text: str) -> str:
    """A whole number as an error quotes it: its first 20 digits and how many there are, past 20."""
    return text if len(text) <= 20 else f"{text[:20]}... ({len(text)} digits)"


def _line_end(data: bytes, pos: int) -> int:
    """Index just past the newline that ends the line containing ``pos``."""
    end = data.find(b"\n", pos)
    return len(data) if end < 0 else end + 1


class _Tokens:
    """Header tokens with their line numbers, read one at a time; names keep their inner spaces.

    Lazily: a hostile header (50 million numbers on one OFFSET line) costs the text it is and no more,
    and is refused at its first wrong token (split into a list, it took 60 times its size).
    """

    _WORD = re.compile(r"\S+")

    def __init__(self, text: str, label: str) -> None:
        self.label = label
        self.text = text
        self._words = self._WORD.finditer(text)
        self._counted = 0  # newlines are counted up to here
        self._line = 1  # the line at ``_counted``
        self._ahead: tuple[str, int] | None = None
        self._last = 1  # the line of the last token taken (or 1)
        self._advance()

    def _advance(self) -> None:
        match = next(self._words, None)
        if match is None:
            self._ahead = None
            return
        self._line += self.text.count("\n", self._counted, match.start())
        self._counted = match.start()
        self._ahead = (match.group(), self._line)

    def error(self, message: str, line: int | None = None) -> InputError:
        if line is None:
            line = self._ahead[1] if self._ahead is not None else self._last
        return InputError(message, source=self.label, line=line)

    def peek(self) -> str | None:
        return self._ahead[0] if self._ahead is not None else None

    def on_line(self, line: int) -> bool:
        """Whether the next token is on ``line``."""
        return self._ahead is not None and self._ahead[1] == line

    def next(self, what: str) -> tuple[str, int]:
        if self._ahead is None:
            raise self.error(f"file ends where {what} was expected", self._last)
        token, line = self._ahead
        self._last = line
        self._advance()
        return token, line

    def rest_of_line(self) -> tuple[list[str], int]:
        """The remaining tokens on the next token's line (at most a joint name's words)."""
        if self._ahead is None:
            return [], self._last
        line = self._ahead[1]
        out = []
        while self.on_line(line):
            out.append(self.next("")[0])
            if len(out) > _MAX_NAME_WORDS:
                raise self.error(f"more than {_MAX_NAME_WORDS} words where a joint's name was expected", line)
        return out, line

    def numbers(self, count: int, what: str) -> np.ndarray:
        values = []
        for _ in range(count):
            token, line = self.next(what)
            if not _NUMBER_RE.match(token):
                raise self.error(f"{what}: {token[:40]!r} is not a number", line)
            value = float(token)
            if not abs(value) <= MAX_VALUE:
                raise self.error(f"{what}: {token[:40]} is out of range (at most {MAX_VALUE:g} in size)", line)
            values.append(value)
        return np.array(values)


#: The most words a joint's name (or what follows a CHANNELS line's names) may have.
_MAX_NAME_WORDS = 64


def _parse_header(text: str, label: str) -> Skeleton:
    tokens = _Tokens(text, label)
    first = tokens.peek()
    if first is None:
        raise InputError("file is empty", source=label, line=1)
    token, line = tokens.next("HIERARCHY")
    if token.upper() != "HIERARCHY":
        raise tokens.error(f"not a BVH file: expected 'HIERARCHY', found {token[:40]!r}", line)
    token, line = tokens.next("ROOT")
    if token.upper() != "ROOT":
        raise tokens.error(f"expected 'ROOT', found {token[:40]!r}", line)

    names: list[str] = []
    parents: list[int] = []
    offsets: list[np.ndarray | None] = []
    channels: list[tuple[str, ...]] = []
    end_sites: list[np.ndarray] = []
    seen: dict[str, int] = {}

    def open_joint(parent: int, keyword_line: int) -> int:
        words, line = tokens.rest_of_line()
        brace_on_line = bool(words) and words[-1] == "{"
        if brace_on_line:
            words = words[:-1]
        if not words:
            raise tokens.error("joint has no name", keyword_line)
        name = " ".join(words)
        if name in seen:
            raise tokens.error(f"joint name {name!r} is used twice (first on line {seen[name]})", line)
        seen[name] = line
        if not brace_on_line:
            token, brace_line = tokens.next("'{'")
            if token != "{":
                raise tokens.error(f"expected '{{' after joint {name!r}, found {token[:40]!r}", brace_line)
        names.append(name)
        parents.append(parent)
        offsets.append(None)
        channels.append(())
        end_sites.append(np.full(3, np.nan))
        return len(names) - 1

    stack = [open_joint(-1, line)]
    while stack:
        joint = stack[-1]
        token, line = tokens.next(f"'}}' closing joint {names[joint]!r}")
        keyword = token.upper()
        if keyword == "OFFSET":
            if offsets[joint] is not None:
                raise tokens.error(f"joint {names[joint]!r} has a second OFFSET", line)
            offsets[joint] = tokens.numbers(3, "OFFSET")
        elif keyword == "CHANNELS":
            if channels[joint]:
                raise tokens.error(f"joint {names[joint]!r} has a second CHANNELS line", line)
            count_token, _ = tokens.next("channel count")
            if not _WHOLE_RE.match(count_token):  # (plain digits: int() also takes 0_3 and other scripts' digits)
                raise tokens.error(f"CHANNELS count {count_token[:40]!r} is not a whole number", line)
            count = int(count_token) if len(count_token) <= 18 else 7  # (past 6 either way; int() stops at 4300 digits)
            if not 0 <= count <= 6:
                shown = _short_number(count_token)
                raise tokens.error(f"CHANNELS count {shown} is not between 0 and 6", line)
            listed = []
            for _ in range(count):
                name_token, name_line = tokens.next("channel name")
                if name_line != line:
                    raise tokens.error(f"CHANNELS says {count} but lists {len(listed)}", line)
                if name_token.lower() not in _CHANNEL_NAMES:
                    raise tokens.error(f"unknown channel {name_token[:40]!r}", name_line)
                listed.append(_CHANNEL_NAMES[name_token.lower()])
            if len(set(listed)) != len(listed):
                raise tokens.error(f"channel listed twice on joint {names[joint]!r}", line)
            extra = 0
            while tokens.on_line(line) and extra <= _MAX_NAME_WORDS:  # (counted, not kept: a line may be long)
                tokens.next("")
                extra += 1
            if extra:
                listed = count + extra if extra <= _MAX_NAME_WORDS else f"more than {count + _MAX_NAME_WORDS}"
                raise tokens.error(f"CHANNELS says {count} but lists {listed}", line)
            channels[joint] = tuple(listed)
        elif keyword == "JOINT":
            if offsets[joint] is None:
                raise tokens.error(f"joint {names[joint]!r} has no OFFSET before its children", line)
            if len(stack) >= MAX_DEPTH:
                raise tokens.error(f"the hierarchy is more than {MAX_DEPTH} joints deep", line)
            if len(names) >= MAX_JOINTS:
                raise tokens.error(f"the hierarchy has more than {MAX_JOINTS} joints", line)
            stack.append(open_joint(joint, line))
        elif keyword == "END":
            if not np.isnan(end_sites[joint][0]):
                raise tokens.error(f"joint {names[joint]!r} has a second End Site", line)
            site, site_line = tokens.next("'Site'")
            if site.upper() != "SITE":
                raise tokens.error(f"expected 'End Site', found 'End {site[:40]}'", site_line)
            brace, brace_line = tokens.next("'{'")
            if brace != "{":
                raise tokens.error(f"expected '{{' after End Site, found {brace[:40]!r}", brace_line)
            offset_token, offset_line = tokens.next("OFFSET")
            if offset_token.upper() != "OFFSET":
                raise tokens.error(f"End Site needs an OFFSET, found {offset_token[:40]!r}", offset_line)
            end_sites[joint] = tokens.numbers(3, "End Site OFFSET")
            close, close_line = tokens.next("'}'")
            if close != "}":
                raise tokens.error(f"expected '}}' closing End Site, found {close[:40]!r}", close_line)
        elif token == "}":
            if offsets[joint] is None:
                raise tokens.error(f"joint {names[joint]!r} (line {seen[names[joint]]}) has no OFFSET", line)
            stack.pop()
        elif keyword == "ROOT":
            raise tokens.error("a second ROOT inside the hierarchy (unclosed '{' above?)", line)
        else:
            raise tokens.error(f"unexpected {token[:40]!r} in joint {names[joint]!r}", line)

    leftover = tokens.peek()
    if leftover is not None:
        _, line = tokens.next("")
        if leftover.upper() == "ROOT":
            raise tokens.error("several ROOT hierarchies in one file are not supported", line)
        raise tokens.error(f"unexpected {leftover[:40]!r} after the hierarchy (unbalanced '}}'?)", line)
    return Skeleton(tuple(names), np.array(parents), np.array(offsets), tuple(channels), np.array(end_sites))


def _parse_motion(
    block: bytes, num_channels: int, declared: int, *, first_line: int, label: str, report: BVHReport,
    compiled: bool = True,
) -> np.ndarray:
    """Frame values ``(F, C)`` from the bytes after ``Frame Time:``.

    ``compiled``: a well-formed block is read in one pass by ``io/_formatting.c`` where it was built (the
    same values; a sixth of the time); a block it does not take as it is, and every fault, the NumPy code
    below reads and names.
    """
    # (Each value takes two bytes at least, a digit and a space or LF: a header that declares more than
    # the block can hold is left to the NumPy code, which says so before it allocates anything.)
    if compiled and _compiled is not None and 0 < declared * num_channels <= (len(block) + 1) // 2:
        values = np.empty(declared * num_channels)
        lines = _compiled.parse_motion(block, values, num_channels, declared, MAX_VALUE)
        if lines >= declared:
            report.data_lines = lines
            if lines > declared:
                report.warnings.append(
                    f"'Frames: {declared}' but {lines} motion lines follow; reading the first {declared}")
            return values.reshape(declared, num_channels)
    buf = np.frombuffer(block, dtype=np.uint8)
    space = _WHITESPACE[buf]
    # Where each value starts, and which line that is on: positions, not per-byte arrays.
    starts = np.flatnonzero(~space[1:] & space[:-1]) + 1
    if len(buf) and not space[0]:
        starts = np.concatenate([[0], starts])
    newlines = np.flatnonzero(buf == 10)
    num_lines = len(newlines) + 1 if len(buf) else 0
    counts = np.bincount(np.searchsorted(newlines, starts), minlength=num_lines)
    rows = np.flatnonzero(counts)  # indices of non-empty lines within the block
    report.data_lines = len(rows)

    if num_channels == 0:
        if len(rows):
            raise InputError("the hierarchy has no channels but motion lines follow", source=label,
                             line=first_line + int(rows[0]))
        return np.zeros((declared, 0))
    if len(rows) < declared:
        complete = int(np.sum(counts[rows] == num_channels))
        short = (f"; line {first_line + int(rows[-1])} has {counts[rows[-1]]} of {num_channels} values"
                 if len(rows) and counts[rows[-1]] != num_channels else "")
        raise InputError(
            f"'Frames: {declared}' but only {complete} complete motion lines follow (file truncated?){short}",
            source=label,
            line=first_line + (int(rows[-1]) if len(rows) else 0),
        )
    used = rows[:declared]
    bad = np.flatnonzero(counts[used] != num_channels)
    if len(bad):
        row = int(used[bad[0]])
        if row == rows[-1] and counts[row] < num_channels:
            raise InputError(
                f"'Frames: {declared}' but only {declared - 1} complete motion lines follow "
                f"(file truncated? the last line has {counts[row]} of {num_channels} values)",
                source=label,
                line=first_line + row,
            )
        raise InputError(
            f"motion line has {counts[row]} values, expected {num_channels} (one per channel)",
            source=label,
            line=first_line + row,
        )
    if len(rows) > declared:
        report.warnings.append(
            f"'Frames: {declared}' but {len(rows)} motion lines follow; reading the first {declared}"
        )

    end = int(newlines[used[-1]]) + 1 if used[-1] < len(newlines) else len(buf)
    chunk = block[:end]
    try:
        # C's strtod over the whole block: no Python object per value (a 10,000-frame
        # clip's million numbers would cost 50 MB as bytes objects).
        values = np.fromstring(chunk, dtype=np.float64, sep=" ")
    except ValueError:
        values = None
    if values is None or values.size != declared * num_channels or not np.all(np.abs(values) <= MAX_VALUE):
        _raise_bad_value(chunk, first_line, label)
    return values.reshape(declared, num_channels)


def _raise_bad_value(chunk: bytes, first_line: int, label: str) -> None:
    """Find and report the first value that is not a number in range (error path only).

    A token at a time (a 200 MB line split whole took 8 times its size)."""
    offset = 0
    for match in _MOTION_WORD.finditer(chunk):
        if match.group() == b"\n":
            offset += 1
            continue
        text = match.group().decode("latin-1")
        if not _NUMBER_RE.match(text):
            raise InputError(f"motion value {text[:40]!r} is not a number", source=label, line=first_line + offset)
        if not abs(float(text)) <= MAX_VALUE:
            raise InputError(f"motion value {text[:40]} is out of range (at most {MAX_VALUE:g} in size)",
                             source=label, line=first_line + offset)
    raise InputError("motion data could not be read", source=label, line=first_line)


_MOTION_WORD = re.compile(rb"[^\s]+|\n")


def _motion_from_channels(skeleton: Skeleton, values: np.ndarray, frame_time: float) -> Motion:
    frames = values.shape[0]
    joints = skeleton.num_joints
    local_pos = np.broadcast_to(skeleton.offsets, (frames, joints, 3)).copy()
    adds = skeleton.positions == "add"
    euler = np.zeros((frames, joints, 3))
    column = 0
    orders = [skeleton.rotation_order(j) for j in range(joints)]
    for j, names in enumerate(skeleton.channels):
        order = orders[j]
        for name in names:
            axis = "XYZ".index(name[0])
            if name in POSITION_CHANNELS:
                local_pos[:, j, axis] = values[:, column] + (skeleton.offsets[j, axis] if adds else 0.0)
            else:
                euler[:, j, order.index(name[0])] = values[:, column]
            column += 1
    return Motion(skeleton, frame_time, quat_from_joint_euler(euler, orders), local_pos, euler)


# ---------------------------------------------------------------------------- writing


def check_bvh_positions(positions: object, name: str = "bvh positions") -> str:
    """``positions`` if it is one of `BVH_POSITIONS`, else a ConfigError naming it (as ``name``)."""
    return check_choice(name, positions, BVH_POSITIONS)


def written_positions(skeleton: Skeleton, positions: str = "standard") -> str:
    """What the position channels of a file written with ``positions`` do to the OFFSETs:
    ``replace`` (the standard) or ``add`` (``input`` on a clip read as adding)."""
    return skeleton.positions if check_bvh_positions(positions) == "input" else "replace"


def motion_channels(motion: Motion, *, positions: str = "standard") -> np.ndarray:
    """The motion as BVH channel values ``(F, C)`` in the skeleton's channel layout
    (position channels as `format_bvh` writes them with ``positions``)."""
    blocks = list(_channel_blocks(motion, motion.num_frames, positions))
    return np.concatenate(blocks or [np.zeros((motion.num_frames, 0))])


def _channel_layout(skeleton):
    """Where each channel of a motion line comes from: the joints with rotation channels by rotation order
    (order -> joints), and per column whether it is an angle, its joint and its component (the axis's
    place in the joint's order for an angle, in XYZ for a position)."""
    by_order: dict[str, list[int]] = {}
    for j in range(skeleton.num_joints):
        if any(c in ROTATION_CHANNELS for c in skeleton.channels[j]):
            by_order.setdefault(skeleton.rotation_order(j), []).append(j)
    source, joint, component = [], [], []
    for j, names in enumerate(skeleton.channels):
        order = skeleton.rotation_order(j)
        for name in names:
            rotation = name in ROTATION_CHANNELS
            source.append(int(rotation))
            joint.append(j)
            component.append(order.index(name[0]) if rotation else "XYZ".index(name[0]))
    return by_order, np.array(source, bool), np.array(joint, np.int64), np.array(component, np.int64)


def _channel_blocks(motion: Motion, block: int, positions: str = "standard"):
    """BVH channel values ``(n, C)`` for consecutive blocks of ``block`` frames.

    The Euler angles are made a block at a time too (`euler_blocks` carries their
    continuity from block to block): a long clip's angles are never all in memory.
    """
    skeleton = motion.skeleton
    adds = written_positions(skeleton, positions) == "add"
    frames = motion.num_frames
    by_order, source, joint, component = _channel_layout(skeleton)
    angles = {order: euler_blocks(motion.local_rotations, order, motion.euler_hint, block, columns=members)
              for order, members in by_order.items()}
    euler = np.zeros((min(block, frames), skeleton.num_joints, 3))
    for start in range(0, frames, block):
        part = slice(start, min(start + block, frames))
        count = part.stop - part.start
        for order, members in by_order.items():
            euler[:count, members] = next(angles[order])
        values = np.empty((count, len(source)))
        values[:, ~source] = motion.local_positions[part][:, joint[~source], component[~source]]
        if adds:  # the input's own convention, asked for: displacements from the OFFSETs
            values[:, ~source] -= skeleton.offsets[joint[~source], component[~source]]
        values[:, source] = euler[:count][:, joint[source], component[source]]
        yield values


def _fmt(value: float) -> str:
    text = f"{value:.6f}"
    return "0.000000" if text == "-0.000000" else text


def _format_header(motion: Motion) -> str:
    """The HIERARCHY and MOTION header lines; depth-first with an explicit stack (no recursion limit)."""
    skeleton = motion.skeleton
    out = io.StringIO()
    children = [[] for _ in range(skeleton.num_joints)]
    for j in range(1, skeleton.num_joints):
        children[skeleton.parents[j]].append(j)
    out.write("HIERARCHY\n")
    # Items: ("open", joint, depth) writes a joint's head and schedules its children
    # and its closing lines; ("close", joint, depth) writes its End Site and brace.
    stack: list[tuple[str, int, int]] = [("open", 0, 0)]
    while stack:
        action, j, depth = stack.pop()
        pad = "\t" * depth
        if action == "open":
            keyword = "ROOT" if j == 0 else "JOINT"
            out.write(f"{pad}{keyword} {skeleton.names[j]}\n{pad}{{\n")
            out.write(f"{pad}\tOFFSET {' '.join(_fmt(v) for v in skeleton.offsets[j])}\n")
            chans = skeleton.channels[j]
            out.write(f"{pad}\tCHANNELS {len(chans)}{''.join(' ' + c for c in chans)}\n")
            stack.append(("close", j, depth))
            stack.extend(("open", child, depth + 1) for child in reversed(children[j]))
        else:
            if np.isfinite(skeleton.end_sites[j, 0]):
                out.write(f"{pad}\tEnd Site\n{pad}\t{{\n")
                out.write(f"{pad}\t\tOFFSET {' '.join(_fmt(v) for v in skeleton.end_sites[j])}\n")
                out.write(f"{pad}\t}}\n")
            out.write(f"{pad}}}\n")
    frame_time = np.format_float_positional(motion.frame_time, trim="-")
    out.write(f"MOTION\nFrames: {motion.num_frames}\nFrame Time: {frame_time}\n")
    return out.getvalue()


_BLOCK_FRAMES = 1024
#: Beyond this magnitude micro-units no longer fit float64 exactly; such rows use Python's formatting.
_FAST_LIMIT = 1e9


def format_fixed(values: np.ndarray, decimals: int = 6, *, compiled: bool = True) -> bytes:
    """Rows of numbers as text: fixed point, space-separated, one line per row.

    Values are rounded to ``decimals`` places, and zero is never written with a
    minus sign. The compiled formatter (``io/_formatting.c``, built at install
    where there is a C compiler) writes them; where it was not built, or with
    ``compiled=False``, NumPy writes the same bytes: digits computed with integer
    arithmetic over the whole array and the characters gathered with a mask, a
    few NumPy passes rather than one Python format call per number (twice as
    fast as ``%`` formatting, and still 6x slower than the compiled loop).

    values : (F, C) float64, finite
    """
    values = np.asarray(values, dtype=np.float64)
    rows, cols = values.shape
    if rows == 0:
        return b""
    if cols == 0:
        return b"\n" * rows
    if np.max(np.abs(values)) >= _FAST_LIMIT:
        row = " ".join([f"%.{decimals}f"] * cols) + "\n"
        return ((row * rows) % tuple((np.round(values, decimals) + 0.0).ravel().tolist())).encode("ascii")
    if _compiled is not None and compiled and decimals <= 9:
        return _compiled.format_fixed(np.ascontiguousarray(values), rows, cols, decimals)
    scale = 10**decimals
    flat = values.ravel()
    units = np.rint(np.abs(flat) * scale).astype(np.int64)
    negative = (flat < 0) & (units > 0)
    whole, frac = np.divmod(units, scale)
    whole = whole.astype(np.int32)
    frac = frac.astype(np.int32 if decimals < 9 else np.int64) * 10 ** (decimals % 2)  # to an even digit count
    int_width = len(str(int(whole.max())))
    int_width += int_width % 2
    frac_width = decimals + decimals % 2
    # One record per value, every digit pair at an even offset so it is one uint16 store:
    # separator, sign, integer digits, '.', (dropped pad), decimals.
    point = 2 + int_width
    chars = np.empty((units.size, 4 + int_width + frac_width), dtype=np.uint8)
    chars[:, 0] = ord(" ")
    chars.reshape(rows, cols, -1)[:, 0, 0] = ord("\n")
    chars[:, 1] = ord("-")
    chars[:, point] = ord(".")
    pairs = chars.view(np.uint16)
    rest = whole
    for column in range(point - 2, 1, -2):
        rest, pair = np.divmod(rest, 100)
        pairs[:, column // 2] = _PAIRS[pair]
    rest = frac
    for column in range(chars.shape[1] - 2, point + 1, -2):
        rest, pair = np.divmod(rest, 100)
        pairs[:, column // 2] = _PAIRS[pair]
    keep = np.ones(chars.shape, dtype=bool)
    keep[0, 0] = False
    keep[:, 1] = negative
    keep[:, point] = decimals > 0  # as printf: no point without decimals
    keep[:, point + 1] = False
    keep[:, point + 2 + decimals :] = False
    # Leading zeros of the integer part go, but one digit always stays.
    for k in range(int_width - 1):
        keep[:, 2 + k] = whole >= 10 ** (int_width - 1 - k)
    return chars[keep].tobytes() + b"\n"


# Two ASCII digits per number 0..99, as the uint16 whose bytes they are in memory.
_PAIRS = np.array([[48 + i // 10, 48 + i % 10] for i in range(100)], dtype=np.uint8).view(np.uint16).ravel()


def format_bvh(motion: Motion, *, positions: str = "standard") -> bytes:
    """The whole file as bytes: fixed-point numbers, LF line ends, tabs.

    positions : ``standard`` (default): position channels are each joint's local
        translation, replacing its OFFSET, as Blender, bvhio and MotionBuilder read
        them; ``input``: in the convention the clip was read in (`Skeleton.positions`;
        displacements added to the OFFSETs for an iClone or MakeHuman clip, for
        re-import into iClone).
    """
    return b"".join(iter_bvh(motion, positions=positions))


def _finite(values: np.ndarray) -> bool:
    """Whether every value is finite: their sum is (one pass, no temporary), else each is (a sum of finite
    values past 1.8e308 is not)."""
    with np.errstate(over="ignore", invalid="ignore"):
        total = np.sum(values)
    return bool(np.isfinite(total)) or bool(np.all(np.isfinite(values)))


def iter_bvh(motion: Motion, *, positions: str = "standard"):
    """The file as consecutive pieces of bytes (the header, then blocks of frames); see `format_bvh`."""
    check_bvh_positions(positions)
    if not all(_finite(values) for values in (motion.local_positions, motion.local_rotations)):
        raise ValueError("motion has NaN or infinite values; refusing to write them")
    yield _format_header(motion).encode("utf-8")
    yield from _motion_lines(motion, _BLOCK_FRAMES, positions)


def _motion_lines(motion: Motion, block: int, positions: str = "standard", *, compiled: bool = True):
    """The motion lines as consecutive pieces of bytes, a block of frames each: `format_fixed` of
    `_channel_blocks`. Where the formatter is compiled, every rotation has one order and the positions are
    written as they are, it reads each channel from the block's positions and Euler angles where they lie
    (`format_columns`: no table of channels is made); the same bytes."""
    skeleton = motion.skeleton
    by_order, source, joint, component = _channel_layout(skeleton)
    if (not compiled or getattr(_compiled, "format_columns", None) is None or len(by_order) != 1
            or written_positions(skeleton, positions) == "add"):
        for values in _channel_blocks(motion, block, positions):
            yield format_fixed(values, compiled=compiled)
        return
    (order, members), = by_order.items()
    column = np.zeros(skeleton.num_joints, dtype=np.int64)
    column[members] = np.arange(len(members))
    # Each channel: where it lies in a frame's positions (j, axis), or -1 - where in its Euler angles.
    picks = np.where(source, -1 - (3 * column[joint] + component), 3 * joint + component)
    angles = euler_blocks(motion.local_rotations, order, motion.euler_hint, block, columns=members)
    frames, width = motion.num_frames, 3 * skeleton.num_joints
    for start in range(0, frames, block):
        part = slice(start, min(start + block, frames))
        count = part.stop - part.start
        euler = np.ascontiguousarray(next(angles), dtype=np.float64)
        placed = np.ascontiguousarray(motion.local_positions[part], dtype=np.float64)
        try:
            yield _compiled.format_columns(placed, euler, picks, count, width, 3 * len(members), 6)
        except ValueError:  # a number of 1e9 or more, or no channels: as `format_fixed` writes them
            values = np.empty((count, len(picks)))
            rotation = picks < 0
            values[:, ~rotation] = placed.reshape(count, -1)[:, picks[~rotation]]
            values[:, rotation] = euler.reshape(count, -1)[:, -1 - picks[rotation]]
            yield format_fixed(values)


def save_bvh(motion: Motion, path: str | os.PathLike | BinaryIO, *, overwrite: bool = True,
             positions: str = "standard") -> None:
    """Write ``motion`` as BVH, atomically (temporary file, then rename).

    ``path`` may be ``"-"`` (standard output) or a binary file object. ``positions``:
    ``standard`` or ``input``, the convention of the position channels (see `format_bvh`).
    """
    data = format_bvh(motion, positions=positions)
    if hasattr(path, "write"):
        write_all(path, data)
        return
    if str(path) == "-":
        write_all(sys.stdout.buffer, data)
        sys.stdout.buffer.flush()
        return
    atomic_write(Path(path), data, overwrite=overwrite)
