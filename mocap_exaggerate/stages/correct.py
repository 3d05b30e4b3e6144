"""Fast joint-hierarchy correction (Kwon & Lee 2008, section 4.2, their Figure 4).

Per frame, every link (p, c) with rest length ``l_c`` and current length ``d``
has excess ``x = max(0, d - max_stretch * l_c)``; the frame error is
``E = sum(x) / sum(l)``. While ``E > threshold``, each link is shortened by
``delta * x`` by moving its child toward its parent, all links at once, the
root fixed, only frames still above threshold iterated.

The child carries its subtree with it, as a joint in a hierarchy does. So a
link's correction changes that link's length and nothing else: every excess
shrinks by exactly ``(1 - delta)`` per iteration, ``E_k = (1 - delta)^k E_0``,
which halts for any delta in (0, 1], and link directions (the exaggerated
pose) are kept while lengths are pulled back.

Because of that, the iteration count each frame needs is known from its
starting error, and `correct` applies those iterations in one step: the
same result as iterating (a frame-by-frame loop oracle in the tests checks
it), at the cost of a single pass over the joints.

Done frame by frame, that reads as jitter once the motion is exaggerated: a
frame just over the threshold is pulled back while its neighbour is not,
and neighbours needing 3 or 4 iterations keep 1/8 or 1/16 of their excess.
So with ``smooth`` > 0 (the default) the share of excess removed is made
smooth in time, keeping the guarantees:

1. per frame, the share of excess the iteration removes, ``c = 1 - (1 - delta)^k``
   (0 under threshold);
2. spread over time by a running maximum over ``smooth`` either side (at least 4 frames), then
   a Gaussian truncated at that radius: never less than (1), so every frame
   still ends at or under the threshold, and exactly 0 more than two radii
   from any frame over it (those frames are untouched);
3. applied to a soft excess: ``max(0, d - m l)`` with its corner rounded
   over 5 % of the link's length (never less than the hard excess), so a
   link reaching its free stretch slows down instead of stopping dead.

The paper's correction only shortens. Exaggeration also squashes: two ends
pushed toward each other can bring an upper arm to a fifth of its length (the
looney amc2bvh jump), and its sub-links then spin as it comes back. Drawn
characters "do not squash unless they are under the influence of another
object" (Ibrahim 2018, section 4.2), so `floor_squash` gives links a soft
floor, ``min_length`` of their length (0.5 by default): a link squashed less
than two fifths of the way there keeps its length, one squashed more eases into
the floor, never reaching it, along its own direction (the pose's bends are
kept). Squash asked for on purpose (a stretch event) comes later and is not
bounded.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from ..analysis.limbs import limb_hinges
from ..core.errors import ConfigError, check_flag, check_number
from ..core.kinematics import cache_blocks, link_vectors
from ..core.native import kernels as _kernels  # the compiled loops, where built (core/native.py)
from ..core.rotations import vector_norm
from ..core.settings import Flag, setting
from ..core.timing import check_duration, parse_duration, smootherstep, soft_limit, spread_max
from .bends import keep_bends

if TYPE_CHECKING:
    from .state import State

__all__ = ["CorrectConfig", "CorrectReport", "accent_stretch", "correct", "correct_stage", "max_link_stretch",
           "floor_squash", "stretch_error"]

#: The correction's spread in time is never narrower than this many frames either side: at 30 fps its 0.1 s
#: is 3 frames, and a thigh let go over them moved the knee 2.09x its largest captured step (issue 25).
_FEWEST_FRAMES = 4

#: A threshold of 0 is reached only in the limit for delta < 1; stop this close to it.
_TOLERANCE = 1e-9


@dataclass(frozen=True, kw_only=True)
class CorrectConfig:
    """Settings of the correction block.

    threshold : the fraction of the skeleton's total link length that may
        remain as stretch in any frame (0.05: at most 5 % summed excess).
    delta : share of each link's excess removed per iteration, in (0, 1].
    max_stretch : stretch up to this factor of a link's rest length is not
        counted as excess (1 counts every stretch).
    max_iter : safety bound on iterations.
    smooth : how far (a duration, ``"0.1s"``, ``"12f"``) the correction is
        spread in time on each side of a frame that needs it; 0 corrects
        frame by frame exactly as the paper's iteration.
    accent_speed : stretch at accents. 0 (the paper): every link may stretch
        to ``max_stretch`` at any time. Otherwise a link gets that much free
        stretch only while its end moves (relative to the root, in the
        capture) at this speed or more, in body heights per second, none
        below a third of it: limbs stretch on the fast part of a move and
        hold their length in a pose, as a drawn cartoon does.
    torso : the share of ``max_stretch``'s free stretch the torso's links (the
        spine and neck chains) get; below 1 they are also held to it in
        every frame, so the torso never stretches more than that (cartoon
        torsos stretch less than limbs). 1 treats them like any link.
    min_length : the squash floor: no link is squashed below this share of
        its length (or of its captured length, where the capture has it
        shorter); links at more than ``1 - 0.4 (1 - min_length)`` of it (0.8
        at 0.5) are left alone, shorter ones ease into the floor (see
        `floor_squash`). 0 leaves squash unbounded, as the paper does; 1 is a
        hard floor at the length.
    """

    enabled: bool = setting(True, flag=Flag("--correct/--no-correct", "Switch link correction on or off."))
    threshold: float = setting(0.05, flag=Flag(
        "--threshold", "Correction: summed stretch allowed per frame, as a fraction of total link length."))
    delta: float = setting(0.5, flag=Flag("--delta", "Correction: share of excess removed per iteration, (0, 1]."))
    max_stretch: float = setting(1.0, flag=Flag(
        "--max-stretch", "Correction: stretch up to this factor of a link's length is free."))
    max_iter: int = setting(500, flag=Flag("--max-iter", "Correction: iteration bound."))
    smooth: str | float = "0.1s"
    accent_speed: float = 0.0
    torso: float = 1.0
    min_length: float = 0.5

    def __post_init__(self) -> None:
        check_flag("correct.enabled", self.enabled)
        check_number("correct.torso", self.torso, 0, 1)
        check_number("correct.min_length", self.min_length, 0, 1)
        check_number("correct.accent_speed", self.accent_speed, 0, 100)
        check_duration(self.smooth, "correct.smooth")
        check_number("correct.threshold", self.threshold, 0, 10)
        check_number("correct.delta", self.delta, 0, 1, low_open=True)
        check_number("correct.max_stretch", self.max_stretch, 1, 10)
        if not isinstance(self.max_iter, int) or isinstance(self.max_iter, bool) or not 1 <= self.max_iter <= 100000:
            raise ConfigError(f"correct.max_iter must be a whole number from 1 to 100000, got {self.max_iter!r}")


@dataclass(frozen=True)
class CorrectReport:
    """What the correction did: frames it touched, iterations, error before and after (max over frames)."""

    frames_corrected: int
    iterations: int
    max_error_before: float
    max_error_after: float
    unconverged_frames: int
    frames_floored: int = 0


def accent_stretch(captured: np.ndarray, frame_time: float, height: float, *, max_stretch: float,
                   accent_speed: float, radius: int) -> np.ndarray:
    """Per-frame, per-joint free stretch ``(F, J)`` for the link ending at each joint.

    ``1 + (max_stretch - 1) a`` where the accent ``a`` rises (smootherstep)
    from 0 at a third of ``accent_speed`` to 1 at it, for the joint's speed
    relative to the root in ``captured`` (F, J, 3), in body heights per
    second; spread over ``radius`` frames either side (never below the
    frame's own) so a stretch builds before the fast part and lets go after.
    """
    if len(captured) < 2:
        return np.full(captured.shape[:2], float(max_stretch))
    relative = captured - captured[:, :1]
    speed = vector_norm(np.gradient(relative, axis=0)) / (frame_time * height)
    low = accent_speed / 3.0
    accent = spread_max(smootherstep((speed - low) / (accent_speed - low)), radius)
    return 1.0 + (max_stretch - 1.0) * np.clip(accent, 0.0, 1.0)


def stretch_error(
    world_pos: np.ndarray, parents: np.ndarray, rest_lengths: np.ndarray, *, max_stretch: float = 1.0
) -> np.ndarray:
    """Per-frame error ``E = sum(max(0, d - max_stretch * l)) / sum(l)``, shape ``(F,)``."""
    x, _, _ = _excess(world_pos, parents, rest_lengths, max_stretch)
    return x.sum(axis=1) / _total_length(rest_lengths)


def _total_length(rest_lengths: np.ndarray) -> float:
    total = float(np.sum(rest_lengths[1:]))
    if total <= 0:
        raise ValueError("the skeleton has no link of non-zero length")
    return total


def _limits(max_stretch, rest_lengths: np.ndarray) -> np.ndarray:
    """Free length of each link: ``max_stretch`` (a number, or (F, J) per frame and joint) times rest length."""
    max_stretch = np.asarray(max_stretch, dtype=np.float64)
    if max_stretch.ndim == 2:
        max_stretch = max_stretch[:, 1:]
    return max_stretch * rest_lengths[1:]


def _excess(world_pos, parents, rest_lengths, max_stretch):
    vec = link_vectors(world_pos, parents)
    length = vector_norm(vec)
    x = np.maximum(0.0, length - _limits(max_stretch, rest_lengths))
    return x, vec, length


def correct(
    world_pos: np.ndarray,
    parents: np.ndarray,
    rest_lengths: np.ndarray,
    *,
    threshold: float,
    delta: float = 0.5,
    max_stretch: float = 1.0,
    max_iter: int = 500,
    smooth: float = 0.0,
    hard: np.ndarray | None = None,
) -> tuple[np.ndarray, CorrectReport]:
    """Pull over-stretched links back until each frame's error is at most ``threshold``.

    Parameters
    ----------
    world_pos : (F, J, 3) float64 world positions (e.g. after extrapolation)
    parents : (J,) int, -1 for the root, parents before children
    rest_lengths : (J,) float64 rest length of the link ending at each joint
    threshold, delta, max_stretch, max_iter : see `CorrectConfig`; ``max_stretch`` may also be
        (F, J), per frame and per joint (the link ending at it)
    smooth : radius in frames over which the correction is spread in time; 0 is
        the paper's frame-by-frame iteration
    hard : (J,) bool, links (by the joint they end at) held to their free length in
        every frame, whatever the threshold (their whole excess removed)

    Returns
    -------
    positions : (F, J, 3) float64, a new array; frames at or under threshold
        (and, with ``smooth``, more than ``2 smooth`` frames from one over it)
        are copied unchanged, and the root never moves
    report : CorrectReport
    """
    world_pos = np.asarray(world_pos, dtype=np.float64)
    parents = np.asarray(parents)
    rest_lengths = np.asarray(rest_lengths, dtype=np.float64)
    if world_pos.ndim != 3 or world_pos.shape[1:] != (len(parents), 3):
        raise ValueError(f"positions must be (F, {len(parents)}, 3), got {world_pos.shape}")
    if not 0 < delta <= 1:
        raise ValueError(f"delta must be in (0, 1], got {delta}")
    out = world_pos.copy()
    if float(np.sum(rest_lengths[1:])) <= 0:
        return out, CorrectReport(0, 0, 0.0, 0.0, 0)  # no link to over-stretch
    total = _total_length(rest_lengths)
    x, vec, length = _excess(world_pos, parents, rest_lengths, max_stretch)
    errors = x.sum(axis=1) / total
    active = np.flatnonzero(errors > threshold)
    hard = np.zeros(len(parents), bool) if hard is None else np.asarray(hard, bool)
    hard_links = hard[1:]
    limit = _limits(max_stretch, rest_lengths)
    limit = np.broadcast_to(limit, length.shape)
    width = _SOFT * rest_lengths[1:]
    if smooth > 0:
        excess = soft_excess(length, limit, width)
        # Held links round their corner only above their rest length: one at rest is never shortened
        # (omega 1 stays the identity), and the rounding still never takes them past their limit.
        corner = np.minimum(width, np.maximum(limit - rest_lengths[1:], 0.0))
        excess[:, hard_links] = soft_excess(length[:, hard_links], limit[:, hard_links], corner[:, hard_links])
    else:
        excess = x
    held = (excess[:, hard_links] > 1e-9 * rest_lengths[1:][hard_links]).any(axis=1) if hard_links.any() else []
    held = np.flatnonzero(held)
    if not len(active) and not len(held):
        return out, CorrectReport(0, 0, float(errors.max(initial=0.0)), float(errors.max(initial=0.0)), 0)

    target = max(threshold, _TOLERANCE) * (1.0 - 1e-6)  # land clearly under, not on it to the last bit

    # Iteration k leaves (1 - delta)^k of every excess, so the number of
    # iterations a frame needs is known in advance: apply them at once.
    start = errors[active]
    if not len(active):
        needed = np.zeros(0, dtype=np.int64)
    elif delta >= 1.0:
        needed = np.ones(len(active), dtype=np.int64)
    else:
        ratio = np.log(target / start) / np.log1p(-delta)
        # A tiny delta needs more iterations than max_iter (or int64) can count: cap before converting.
        needed = np.clip(np.ceil(ratio - 1e-9), 1, max_iter + 1).astype(np.int64)
        # Guard the rounding of the logs.
        needed += (1.0 - delta) ** needed * start > target
    steps = np.minimum(needed, max_iter)
    iterations = int(steps.max(initial=0))
    unconverged = int(np.sum(needed > max_iter))
    share = np.zeros(len(errors))
    share[active] = 1.0 - (1.0 - delta) ** steps  # share of each excess removed
    if smooth > 0:
        share = np.clip(spread_max(share, max(int(round(smooth)), _FEWEST_FRAMES)), 0.0, 1.0)
    touched = np.union1d(np.flatnonzero(share > 0), held)
    link_share = np.repeat(share[touched, None], len(parents) - 1, axis=1)
    link_share[:, hard_links] = 1.0
    new_len = length[touched] - link_share * excess[touched]
    out[touched] = _rebuild(out[touched], parents, vec[touched], length[touched], new_len)
    ms = np.asarray(max_stretch)
    after = stretch_error(out[touched], parents, rest_lengths, max_stretch=ms[touched] if ms.ndim == 2 else ms)
    max_after = max(float(after.max(initial=0.0)), float(np.delete(errors, touched).max(initial=0.0)))
    return out, CorrectReport(len(touched), iterations, float(errors.max()), max_after, unconverged)


def _rebuild(pos: np.ndarray, parents: np.ndarray, vec: np.ndarray, length: np.ndarray,
             new_length: np.ndarray, *, compiled: bool = True) -> np.ndarray:
    """Positions with every link ``vec`` (F, J-1, 3) scaled to ``new_length``, children carrying their subtree
    (in place on ``pos``; ``compiled``: by ``core/_kernels.c`` where it was built, the same bits)."""
    scale = np.divide(new_length, length, out=np.ones_like(length), where=length > 0)
    links = vec * scale[..., None]
    if (compiled and getattr(_kernels, "chain_add", None) is not None and pos.dtype == np.float64
            and pos.flags.c_contiguous and pos.ndim == 3 and len(parents) > 1
            and links.shape == (len(pos), len(parents) - 1, 3)):
        _kernels.chain_add(pos, np.ascontiguousarray(parents, dtype=np.int64), np.ascontiguousarray(links), len(pos),
                           len(parents))  # (the loop below, a frame at a time in C: the same bits)
        return pos
    for j in range(1, len(parents)):
        pos[:, j] = pos[:, parents[j]] + links[:, j - 1]
    return pos


#: Where the squash floor starts to act, as a share of the room between a link's length and its floor.
_KNEE = 0.4


def floor_squash(world_pos: np.ndarray, parents: np.ndarray, rest_lengths: np.ndarray, min_length: float,
                 captured: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """Positions (a new array) with every link squashed toward ``min_length`` of its length eased off it.

    A link's shortening ``s = l - d`` is kept up to a knee of two fifths of
    the room, ``0.4 (1 - min_length) l``, and above it eases into ``(1 - min_length) l``
    (`soft_limit`: continuous with its first derivative, so a link squashing
    smoothly comes back smoothly; ``min_length`` 1 is a hard floor at the
    length); the link keeps its direction and its child carries its subtree.
    Placeholder links (under 1e-3 of the longest) are left as they are.

    captured : (F, J, 3) the positions the squash is measured against: a link
        the capture itself has shorter (a keyframed squash, a rig's own) is
        floored from that length, not its rest length, so the capture comes
        through untouched; and a link squashed to nearly nothing (under 1e-6
        of its length, no direction of its own) takes the captured one.

    Returns the positions and how many frames moved; frames with no link past
    the knee are copied unchanged.

    >>> pos = np.array([[[0.0, 0, 0], [0.1, 0, 0], [0.1, 1, 0]]])  # a 1-long link squashed to 0.1
    >>> out, moved = floor_squash(pos, np.array([-1, 0, 1]), np.array([0.0, 1.0, 1.0]), 0.5)
    >>> np.round(out[0, :, :2], 3).tolist(), moved
    ([[0.0, 0.0], [0.506, 0.0], [0.506, 1.0]], 1)
    """
    out = np.array(world_pos, dtype=np.float64)
    links = rest_lengths[1:]
    if min_length <= 0 or not len(links) or links.max(initial=0.0) <= 0:
        return out, 0
    vec = link_vectors(out, parents)
    length = vector_norm(vec)
    full = links
    if captured is not None:
        full = np.minimum(links, vector_norm(link_vectors(captured, parents)))
    room = (1.0 - min_length) * full
    knee = _KNEE * room
    counted = links > 1e-3 * links.max()
    # (past the knee by more than rounding: at min_length 1 the knee is the length itself)
    squashed = np.flatnonzero(((full - length > knee + 1e-9 * links) & counted).any(axis=1))
    if not len(squashed):
        return out, 0
    full = np.broadcast_to(full, length.shape)[squashed]
    room, knee = np.broadcast_to(room, length.shape)[squashed], np.broadcast_to(knee, length.shape)[squashed]
    vec, length = vec[squashed], length[squashed]
    new_len = np.where(counted & (full - length > knee), full - soft_limit(full - length, knee, room), length)
    along = length
    if captured is not None:
        # No direction of its own: the captured link's, scaled to the floored length.
        lost = (length < 1e-6 * links) & counted
        if lost.any():
            was = captured[squashed][:, 1:] - captured[squashed][:, parents[1:]]
            vec = np.where(lost[..., None], was, vec)
            along = np.where(lost, vector_norm(was), length)
    out[squashed] = _rebuild(out[squashed], parents, vec, along, new_len)
    return out, len(squashed)


#: Width of the rounded corner of the soft excess, as a share of the link's rest length.
_SOFT = 0.05


def soft_excess(length: np.ndarray, limit: np.ndarray, width: np.ndarray) -> np.ndarray:
    """``max(0, length - limit)`` with its corner rounded (C1) over ``length - limit`` in [-width, width].

    Never less than the hard excess, equal to it outside the corner.

    >>> soft_excess(np.array([0.0, 1.0, 2.0, 3.0]), 2.0, 1.0).tolist()
    [0.0, 0.0, 0.25, 1.0]
    """
    u = length - limit
    width = np.maximum(width, 1e-300)
    inside = np.clip(u, -width, width) + width
    return np.where(u >= width, u, inside * inside / (4.0 * width))


# ---------------------------------------------------------------------------- the stage


def correct_stage(state: State, config: CorrectConfig) -> State:
    """The block: over-stretched links brought back toward their length, knees and elbows kept bent.

    Adds ``positions`` and ``correct_report``.
    """
    first = state.first
    skeleton = state.motion.skeleton
    frame_time = state.motion.frame_time
    smooth = parse_duration(config.smooth, frame_time, what="correct.smooth")
    max_stretch = config.max_stretch
    if config.accent_speed > 0 and max_stretch > 1:
        max_stretch = accent_stretch(state.captured_pos[first:], frame_time, skeleton.height(),
                                     max_stretch=max_stretch, accent_speed=config.accent_speed,
                                     radius=max(int(round(smooth)), 1))
    hard = None
    if config.torso < 1:
        hard = np.zeros(skeleton.num_joints, bool)
        for name in ("spine", "neck"):
            if name in state.limbs:
                hard[list(state.limbs[name].joints[1:])] = True
        max_stretch = np.broadcast_to(max_stretch, (len(state.positions) - first, skeleton.num_joints)).copy()
        max_stretch[:, hard] = 1.0 + (max_stretch[:, hard] - 1.0) * config.torso
    hinges = limb_hinges(skeleton, state.limbs)
    bent = keep_bends(state.positions[first:], state.captured_pos[first:], hinges) if hinges else state.positions[first:]
    body, report = correct(
        bent, skeleton.parents, skeleton.link_lengths(), threshold=config.threshold,
        delta=config.delta, max_stretch=max_stretch, max_iter=config.max_iter, smooth=smooth, hard=hard,
    )
    body, floored = floor_squash(body, skeleton.parents, skeleton.link_lengths(), config.min_length,
                                 state.captured_pos[first:])
    report = replace(report, frames_floored=floored)
    positions = state.positions.copy()
    positions[first:] = body
    notes = state.notes
    if report.unconverged_frames:
        notes += (f"correction stopped at max_iter with {report.unconverged_frames} frame(s) above threshold",)
    return replace(state, positions=positions, correct_report=report, notes=notes)


def max_link_stretch(positions: np.ndarray, parents: np.ndarray, lengths: np.ndarray) -> float:
    """Largest ratio of current to rest length over links longer than 1e-3 of the longest.

    Shorter ones are placeholders (Reallusion's pelvis sits 0.7 micrometres from its hip):
    moved a centimetre they read as a 37,000x stretch.
    """
    long_links = lengths > 1e-3 * max(lengths.max(), 1e-12)
    long_links[0] = False
    if not long_links.any():
        return 1.0
    links, ends = np.flatnonzero(long_links), parents[long_links]
    largest = [(vector_norm(positions[part][:, links] - positions[part][:, ends]) / lengths[long_links]).max()
               for part in cache_blocks(len(positions), 8 * len(links))]  # no (F, links, 3) temporaries
    return float(np.max(largest))  # (NaN stays NaN; no frames is an error, as before)
