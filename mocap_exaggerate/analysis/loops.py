"""Looping clips: found, run as the loop repeated, and cut back to one cycle that still loops.

A game's run or walk cycle is made to play over and over: its last frame repeats its first
(how glTF and FBX exporters close a cycle) or leads into it. Every time filter of the
pipeline (the exaggeration's Gaussian, the speed limit, the correction's smoothing, the
contacts' easing, the springs' lag) sees a clip's ends as ends, so an exaggerated cycle no
longer meets itself: the Quaternius robot's run at cartoon jumped 0.33 heights where it loops.

Here a loop is run as the pipeline sees an endless one: the clip is extended by its own
cycle, `HALO` seconds before and after (the root carried on by its travel per cycle), the
stages run over that, and the cycle in the middle is cut back out. The filters and the
springs then see the motion that comes before and after every frame, and the cycle's ends
meet as its other frames do. A closed loop's last frame is made its first exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..core.motion import Motion
from ..core.rotations import vector_norm

__all__ = ["LOOP_MODES", "CLOSED", "HALO", "MOST_CYCLES", "Loop", "find_loop", "repeats_first"]

#: ``auto`` takes a clip whose last frame repeats its first as a loop; ``on`` takes every clip as
#: one (its last frame leading into its first, where it does not repeat it); ``off`` takes none.
LOOP_MODES = ("auto", "on", "off")
#: A clip is a closed loop when no joint's place relative to the root differs between its last and
#: first frames by more than this share of the body's height, nor the root's turn by more than this
#: many radians (a game cycle's repeat is exact; no capture comes back within a thousandth of a
#: height). Where the root itself goes is free: that is the cycle's travel.
CLOSED = 1e-3
#: Seconds of the cycle run before and after it: past the reach of every time filter of the stages
#: at any preset (the widest, the body pass's eased pushes and the extrapolation's band, reach 1.3
#: and 1.2 s at looney), so the cycle's ends see what the cycle around them would be.
HALO = 5.0
#: At most this many whole cycles either side: a short cycle at a high frame rate (3 frames at
#: 10,000 fps) would otherwise be run as 50,000 frames.
MOST_CYCLES = 64


@dataclass(frozen=True)
class Loop:
    """A clip taken as a loop, and how it is run.

    period : frames in one cycle (a closed loop's last frame, its first again, is not counted)
    closed : the last frame repeats the first
    travel : (3,) the root's move over one cycle (0 for a cycle on the spot)
    halo : frames of the cycle run before the clip
    length : frames run in all (the clip, `halo` before it and the rest after it)

    A cycle shorter than `HALO` is run as a whole number of cycles starting on its calmest frame
    (`find_loop`), whichever frame the clip starts on: the same frames in the same order for the
    same cycle. So what the stages measure over the whole clip (top speeds, the floor's level, what
    the speed limit takes) is the cycle's own, the output is the same cycle wherever the clip
    starts, and the fades at the run's own ends fall where the body is calmest, cycles away from
    the clip. A longer cycle has `HALO` seconds of itself on each side (a clip taken as a loop with
    ``--loop on`` costs 10 s more, not three times itself).
    """

    period: int
    closed: bool
    travel: np.ndarray
    halo: int
    length: int

    def extend(self, motion: Motion) -> Motion:
        """The clip with `halo` frames of its cycle before it (`length` frames in all), its root carried on by
        its travel per cycle."""
        frames = np.arange(self.length) - self.halo  # 0: the clip's first frame
        cycle, source = np.divmod(frames, self.period)
        positions = motion.local_positions[source]
        positions[:, 0] += cycle[:, None] * self.travel
        hint = None if motion.euler_hint is None else motion.euler_hint[source]
        return Motion(motion.skeleton, motion.frame_time, motion.local_rotations[source], positions, hint)

    def middle(self, frames: int) -> slice:
        """The extended clip's frames that are the clip's own."""
        return slice(self.halo, self.halo + frames)

    def close(self, motion: Motion) -> Motion:
        """A closed loop's last frame made exactly its first (moved by the cycle's travel): the rounding of a
        run over many frames otherwise leaves them apart in the last digits."""
        if not self.closed:
            return motion
        rotations = motion.local_rotations.copy()
        positions = motion.local_positions.copy()
        rotations[-1] = rotations[0]
        positions[-1] = positions[0]
        positions[-1, 0] += self.travel
        hint = None
        if motion.euler_hint is not None:
            hint = motion.euler_hint.copy()
            hint[-1] = hint[0]
        return replace(motion, local_rotations=rotations, local_positions=positions, euler_hint=hint)

    def describe(self, frame_time: float) -> str:
        """What a note says of it."""
        kind = "its last frame repeating its first" if self.closed else "its last frame leading into its first"
        return (f"a loop of {self.period} frames ({kind}): run as the loop repeated, {self.halo * frame_time:.3g} s "
                "before it, so the output loops too (--loop off takes it as a clip)")


def find_loop(motion: Motion, world_pos: np.ndarray, world_rot: np.ndarray, mode: str = "auto", *,
              reach: float = 0.0) -> Loop | None:
    """The clip as a loop (`Loop`), or None.

    world_pos, world_rot : (F, J, 3) and (F, J, 4) the clip's forward kinematics
    mode : `LOOP_MODES`: ``auto`` finds closed loops (`CLOSED`), ``on`` takes any clip of 3 frames or
        more as a loop (closed where it is one, else its last frame leads into its first); either
        carries the root on by its travel per cycle, not by a turn (a cycle that turns, taken as a
        loop with ``on``, is repeated facing one way)
    reach : seconds the stages' filters reach, where more than `HALO` (a wide sigma)
    """
    if mode == "off" or motion.num_frames < 3:
        return None
    closed = repeats_first(motion, world_pos, world_rot)
    if not closed and mode != "on":
        return None
    frames = motion.num_frames
    root = world_pos[:, 0]
    if closed:
        period, travel = frames - 1, root[-1] - root[0]
    else:  # the step from the last frame into the first is one more of the cycle's
        period, travel = frames, (root[-1] - root[0]) * frames / (frames - 1)
    travel = np.asarray(travel, dtype=np.float64)
    halo = math.ceil(max(HALO, reach) / motion.frame_time)
    if halo >= period:  # whole cycles from the calmest frame (`Loop`)
        cycle = world_pos[:period] - world_pos[:period, :1]  # the body about its root, frame by frame
        moves = vector_norm(np.roll(cycle, -1, axis=0) - cycle).sum(axis=1)  # the last frame leads into the first
        if closed:
            moves[-1] = vector_norm(world_pos[-1] - world_pos[-1, :1] - cycle[-1]).sum()
        cycles = min(math.ceil(halo / period), MOST_CYCLES)
        calm = int(np.argmin(moves))
        return Loop(period, closed, travel, halo=cycles * period + (-calm) % period,
                    length=2 * (cycles + 1) * period)
    return Loop(period, closed, travel, halo=halo, length=frames + 2 * halo)


def repeats_first(motion: Motion, world_pos: np.ndarray, world_rot: np.ndarray) -> bool:
    """The last frame is the first again: every joint's place from the root and the root's turn, within `CLOSED`
    (``world_pos`` and ``world_rot`` need hold only the first and last frames)."""
    height = max(motion.skeleton.height(), 1e-12)
    relative = world_pos[[0, -1]] - world_pos[[0, -1], :1]
    if vector_norm(relative[1] - relative[0]).max() > CLOSED * height:
        return False
    turn = abs(float(np.dot(world_rot[0, 0], world_rot[-1, 0])))  # q and -q are one turn
    return turn >= math.cos(CLOSED / 2)  # within a thousandth of a radian
