"""Motion trails as JSON: the end-effector paths of every stretch, written for plotting or editing.

A trails file holds, per stretch event, the limb, its end joint, the frames,
and the original and exaggerated end-effector positions. Moving the
``exaggerated`` points in a DCC and handing the file back (a path file) makes
the limb follow them: the thesis's control spheres.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from ..core.errors import InputError
from .files import LIMITS, read_limited

__all__ = ["format_trails", "read_trails"]


def format_trails(trails: list[dict], *, source: str, fps: float) -> bytes:
    """The trails file as bytes (``trails`` as in `StretchResult.trails`)."""
    return (json.dumps({"input": source, "fps": fps, "trails": trails}, indent=1) + "\n").encode("utf-8")


def read_trails(path: str | os.PathLike) -> dict[str, tuple[list[int], np.ndarray]]:
    """Edited paths from a trails file: limb -> (frames, points ``(n, 3)``)."""
    label = str(path)
    try:
        data = json.loads(read_limited(Path(path), limit=LIMITS["text"], what="trails file", label=label).decode("utf-8"))
    except FileNotFoundError:
        raise InputError("no such path file", source=label) from None
    except IsADirectoryError:
        raise InputError("is a folder, not a trails file", source=label) from None
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as error:
        raise InputError(f"not a JSON trails file ({error})", source=label) from None
    except InputError:
        raise
    except ValueError:  # an integer of more than 4,300 digits (Python's own limit)
        raise InputError("not a trails file: a number of more than 4,300 digits", source=label) from None
    trails = data.get("trails", []) if isinstance(data, dict) else []
    if not isinstance(trails, list):
        raise InputError("'trails' must be a list of trails", source=label)
    paths = {}
    for number, trail in enumerate(trails, start=1):
        try:
            frames = [int(f) for f in trail["frames"]]
            points = np.asarray(trail["exaggerated"], dtype=np.float64)
            limb = str(trail["limb"])
        except (KeyError, TypeError, ValueError, OverflowError, IndexError):
            raise InputError(f"trail #{number} needs limb, frames and exaggerated points", source=label) from None
        if not all(0 <= f <= 10**9 for f in frames):
            raise InputError(f"trail #{number} ({limb}): frames must be frame numbers from 0", source=label)
        if points.shape != (len(frames), 3) or not np.all(np.abs(points) <= 1e9):
            raise InputError(f"trail #{number} ({limb}) has {len(frames)} frames but points of shape {points.shape}; "
                             "expected one finite x, y, z (at most 1e9 in size) per frame", source=label)
        paths[limb] = (frames, points)
    if not paths:
        raise InputError("no trails in it", source=label)
    return paths
