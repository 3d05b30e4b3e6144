"""What a picture shows: which frames, which joint, and the view that frames them.

`telling_frames` and `telling_window` pick the moments where the exaggeration
shows most, `fastest_end` the joint whose path is worth drawing, `preview_window`
the part of the motion asked for; `view_axes`, `view_limits` and
`camera_centres` place the view so that everything drawn is in it, at one scale.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.errors import ConfigError, check_number
from ..core.motion import Motion
from ..core.rotations import vector_norm
from ..core.skeleton import Skeleton
from ..pipeline import PipelineResult

__all__ = ["lined_up", "telling_frames", "telling_window", "fastest_end", "preview_window", "view_axes",
           "view_limits", "steady_view", "camera_centres"]


def lined_up(motion: Motion, result: PipelineResult, world: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """The captured world positions ``(F_out, J, 3)`` frame for frame with the output, and the
    output's first motion frame (past the rest-pose frames it kept).

    world : ``motion.world_positions()`` when the caller has it (it is not computed again)
    """
    world = motion.world_positions() if world is None else world
    if result.rest_frames_dropped:  # the output starts where the motion does
        return world[result.rest_frames:], 0
    return world, result.rest_frames


def telling_frames(motion: Motion, result: PipelineResult, count: int = 4, *,
                   world: np.ndarray | None = None) -> list[int]:
    """The ``count`` output frames where the body is most exaggerated, in time order.

    Exaggerated by the largest distance of any joint from where it was captured, relative
    to the root (so that a body drifting as a whole does not decide), the picks at least
    an eighth of the clip apart, so that one accent does not fill the row.
    """
    captured, first = lined_up(motion, result, world)
    exaggerated = result.world_positions[:, result.original_index]
    moved = (exaggerated - exaggerated[:, :1]) - (captured - captured[:, :1])
    away = vector_norm(moved).max(axis=1)[first:]
    apart = max(len(away) // 8, 1)
    picks: list[int] = []
    for frame in np.argsort(-away, kind="stable"):
        if len(picks) == count:
            break
        if all(abs(int(frame) - p) >= apart for p in picks):
            picks.append(int(frame))
    return sorted(first + p for p in picks)


def telling_window(motion: Motion, result: PipelineResult, joint: int, seconds: float = 3.0, *,
                   world: np.ndarray | None = None) -> tuple[int, int]:
    """Output frames ``[start, end)`` of about ``seconds`` around the moment ``joint`` is moved
    furthest from its captured path: the part of a long clip a path picture can show."""
    captured, first = lined_up(motion, result, world)
    away = vector_norm(result.world_positions[:, result.original_index[joint]] - captured[:, joint])
    total = len(away)
    width = max(int(round(seconds / motion.frame_time)), 2)
    if total - first <= width:
        return first, total
    peak = first + int(np.argmax(away[first:]))
    start = int(np.clip(peak - width // 2, first, total - width))
    return start, start + width


def fastest_end(motion: Motion, first: int | None = None, *, world: np.ndarray | None = None) -> int:
    """The end effector (hand, foot, head of the limbs found) that moves fastest in ``motion``.

    Fastest by the 99th percentile of its world speed from frame ``first`` on (default: past
    the leading rest-pose frames, whose jump into the motion is no move), so that one
    glitch in the capture does not decide. Falls back to the fastest joint of all on a rig
    whose limbs are not found.
    """
    from ..analysis.limbs import find_limbs
    from ..analysis.tpose import detect_rest_frames

    world = motion.world_positions() if world is None else world
    world = world[(detect_rest_frames(motion, world) if first is None else first):]
    ends = sorted({limb.end for limb in find_limbs(motion.skeleton).values()}) or list(range(motion.skeleton.num_joints))
    if len(world) < 2:
        return ends[0]
    speed = vector_norm(np.diff(world[:, ends], axis=0))
    return ends[int(np.argmax(np.percentile(speed, 99, axis=0)))]


def preview_window(motion: Motion, result: PipelineResult, *, start: float = 0.0,
                   seconds: float | None = None) -> tuple[int, int]:
    """Output frames ``[begin, end)``: from ``start`` seconds into the motion (past the rest-pose
    frames the output kept) for ``seconds`` (default: to the end)."""
    check_number("start", start, 0.0, math.inf)
    first = result.first
    total = result.world_positions.shape[0]
    begin = first + start / motion.frame_time  # a float until it is known to be a frame: start may be inf
    if begin >= total - 0.5:
        length = max(total - 1 - first, 0) * motion.frame_time
        raise ConfigError(f"start {start:g} s is past the end of the motion ({length:.3f} s long)")
    begin = int(round(begin))
    if seconds is None:
        return begin, total
    check_number("seconds", seconds, 0.0, math.inf, low_open=True)
    count = seconds / motion.frame_time  # inf shows the rest
    return begin, total if count >= total - begin else min(total, begin + max(int(round(count)), 1))


def view_axes(skeleton: Skeleton, root_path: np.ndarray) -> tuple[int, int, int]:
    """(right, up, depth): look along the horizontal axis the root moves least along (from its side).

    root_path : (F, 3) root positions over the clip
    A body that stays in place (a loop on a treadmill) and whose spine lies along the ground (a
    fox, a cat) is seen from the side of its spine, not from its nose.
    """
    up = skeleton.up_axis()
    horizontal = [a for a in range(3) if a != up]
    spread = np.ptp(root_path[:, horizontal], axis=0) if len(root_path) else np.zeros(2)
    if spread.max() < 0.25 * skeleton.height():
        from ..analysis.limbs import find_limbs

        spine = find_limbs(skeleton).get("spine")
        if spine is not None:
            rest = skeleton.rest_positions()
            along = rest[spine.end] - rest[spine.base]
            if abs(along[up]) < 0.7 * np.linalg.norm(along):  # more along the ground than up
                length = horizontal[int(np.argmax(np.abs(along[horizontal])))]
                return length, up, next(a for a in horizontal if a != length)
    depth = horizontal[int(np.argmin(spread))]
    right = horizontal[int(np.argmax(spread))] if spread.max() > 0 else horizontal[0]
    return right, up, depth


def view_limits(points: np.ndarray, centre: np.ndarray, *, margin: float = 0.04, min_aspect: float = 0.5,
                max_aspect: float = 3.0) -> tuple[float, float, float]:
    """One view that shows every point of every frame: ``(half_width, low, high)``.

    points : (F, N, 2) float, what is drawn at each of F frames (or picture columns) as (across, up)
    centre : (F,) float, where each frame's view is centred across

    Frame f shows ``centre[f] ± half_width`` across and ``[low, high]`` up: the same size for
    every frame, so that bodies drawn in different frames or panels are at one scale. A margin
    of ``margin`` times the larger extent is left on every side; the view is at least
    ``min_aspect`` and at most ``max_aspect`` times as wide as it is tall (it grows to be).

    >>> view_limits(np.array([[[0.0, 0.0], [1.0, 2.0]]]), np.array([0.0]), margin=0.0)
    (1.0, 0.0, 2.0)
    """
    points = np.asarray(points, dtype=np.float64)
    centre = np.asarray(centre, dtype=np.float64)
    if points.ndim != 3 or points.shape[-1] != 2 or points.shape[1] == 0:
        raise ValueError(f"points must be (F, N, 2) with N > 0, got {points.shape}")
    if centre.shape != points.shape[:1]:
        raise ValueError(f"centre must be ({points.shape[0]},), got {centre.shape}")
    low, high = float(points[..., 1].min()), float(points[..., 1].max())
    half = float(np.abs(points[..., 0] - centre[:, None]).max())
    extent = max(high - low, 2.0 * half)
    pad = margin * extent if extent > 0 else 1.0  # a single point still gets a view around it
    low, high, half = low - pad, high + pad, half + pad
    grow = max(2.0 * half / max_aspect - (high - low), 0.0) / 2.0
    low, high = low - grow, high + grow
    return max(half, 0.5 * min_aspect * (high - low)), low, high


def steady_view(captured: np.ndarray, everything: np.ndarray, centre: np.ndarray, tall: float, *,
                room: float = 0.15) -> tuple[float, float, float]:
    """A view at one scale whatever the settings: `view_limits` of the ``captured`` points (F, N, 2) with
    ``room`` times the body's height ``tall`` around them, grown only where ``everything`` drawn (F, M, 2)
    goes further. Two previews of one clip with different settings then show the body at the same size
    in pictures of the same size, unless one exaggerates past that room (nine previews of a sweep came out
    499 to 801 pixels tall, each body at its own scale)."""
    half, low, high = view_limits(captured, centre, margin=0.0)
    pad = room * tall if tall > 0 else 0.0
    half, low, high = half + pad, low - pad, high + pad
    across = np.abs(everything[..., 0] - centre[:, None])
    return (max(half, float(across.max()) * 1.02), min(low, float(everything[..., 1].min())),
            max(high, float(everything[..., 1].max())))


def camera_centres(root_across: np.ndarray, points: np.ndarray, tall: float, sigma: float) -> np.ndarray:
    """``(F,)``: where each frame's view is centred across.

    Standing still over everything drawn unless the root travels more than half the body's
    height ``tall``; then following it, smoothed over ``sigma`` frames so that the body's own
    surges show: the extrapolation's own Gaussian average, whose point-reflected ends keep a
    steady run steady there.
    """
    from ..core.timing import gaussian_average

    if np.ptp(root_across) <= 0.5 * tall:
        across = points[..., 0]
        return np.full(len(root_across), 0.5 * (across.min() + across.max()))
    return gaussian_average(root_across, sigma)
