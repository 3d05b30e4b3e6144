"""Strikes found by their shape: a limb unfolding to near full reach, away from the body, not as a step.

A strike (a punch, a kick, a thrust, a throw, an arm shot up to grab) is an arm or a leg
that unfolds from clearly bent to nearly straight and stops there, pointing away from the
torso, whatever its speed. Three things that look the same to a speed threshold are not
strikes, and the shape tells them apart:

- a leg reaching forward to take a step of a walk, jog or hop: its foot lands within a
  moment of full reach (or is on the ground at it), by the same contact finder that plants
  the feet (`mocap_exaggerate.stages.contacts.find_contacts`);
- an arm swinging with the stride or a leg straightening to stand up: nothing unfolds, or
  the limb ends hanging down along the torso;
- an arm pushing down at the side (a dribble): it ends along the torso's down line.

- both arms or both legs unfolding together (a jump, legs swung while sitting, arms opened
  in a dance): a strike is one limb's.

So a candidate is every hold of a limb near full reach: a peak of its reach (base to end
over its full length) of at least 0.8, with the frames either side within 0.04 of it (an
arm raised and held creeps up for a second; that is one reach). It is taken when its reach
is at least ``min_reach``, it rose by at least ``min_rise`` within ``window`` seconds before
the hold, the limb points at least ``min_angle`` degrees (arms; ``min_leg_angle`` legs) away
from the torso's down line when it arrives, it is not a step, and the other limb of its
pair does not unfold with it.
Measured against strikes labelled by hand in the 33 shared clips (``tests/data/strikes.json``,
``bench/strikes.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.rotations import vector_norm
from ..core.timing import gaussian_average
from .limbs import limb_length, standing_up

__all__ = ["Candidate", "strike_candidates", "CANDIDATE_REACH"]

#: The least reach a peak needs to be weighed at all (and reported as the strongest one missed).
CANDIDATE_REACH = 0.8
#: Degrees from straight down under which a limb points at the floor (a scoop, a leg stepping down): not a strike.
FLOOR_ANGLE = 30.0
#: Degrees a limb must sweep through to point at the floor as a strike (a chop comes down from above;
#: a scoop or a leg stepping down turns less).
CHOP = 90.0
#: Degrees from the torso's down line past which both arms unfolding at once reach up (two strikes).
OVERHEAD = 135.0
#: Reach within this of a hold's top belongs to the hold.
HOLD = 0.04


@dataclass(frozen=True)
class Candidate:
    """A hold of a limb near full reach, weighed as a strike.

    limb : the limb; start : where its extension gets going; arrive : the frame it first comes
        within 0.02 of its top reach (a strike's key frame); last : the last frame of the hold
    reach : the hold's top, over the limb's full length; rise : the reach gained from the least
        reach of the window before the hold
    angle : degrees between the limb (base to end) and the torso's down line when it arrives (the
        least of that and at its top)
    floor_angle : the same from straight down (toward the floor)
    sweep : degrees the limb turned through from ``start`` to ``arrive``
    step : a leg whose foot is down at ``arrive`` or lands within 0.15 s of it
    paired : the other limb of its pair unfolds at the same time
    why : empty for a strike; otherwise every test it failed, in words
    """

    limb: str
    start: int
    arrive: int
    last: int
    reach: float
    rise: float
    angle: float
    floor_angle: float
    sweep: float
    step: bool
    paired: bool
    why: str

    @property
    def taken(self) -> bool:
        return not self.why

    def strength(self) -> float:
        """How near a strike it comes, to name the strongest when none is taken: reach, unfolding and angle,
        each as a share of a typical strike's (capped at 1), halved for a step or a pair."""
        return (self.reach * min(self.rise / 0.4, 1.0) * min(self.angle / 60.0, 1.0)
                * (0.5 if self.step else 1.0) * (0.5 if self.paired else 1.0))

    def describe(self, frame_time: float, first: int = 0) -> str:
        at = self.arrive + first
        return (f"{self.limb} at frame {at} ({at * frame_time:.2f} s): reach {self.reach:.2f}, "
                f"unfolded by {self.rise:.2f}, {self.angle:.0f} degrees from the torso's down line")


def strike_candidates(world_pos: np.ndarray, skeleton, limbs: dict, frame_time: float, *, min_reach: float,
                      min_rise: float, min_angle: float, min_leg_angle: float, window: float,
                      steps: dict[str, np.ndarray] | None = None) -> list[Candidate]:
    """Every hold near full reach of every arm and leg in ``world_pos (F, J, 3)``, weighed; in frame order.

    steps : limb name -> ``(R, 2)`` inclusive frame ranges its end is on the ground (legs)
    """
    frames = world_pos.shape[0]
    if frames < 8:
        return []
    span = max(3, int(round(window / frame_time)))
    near = max(1, int(round(0.1 / frame_time)))  # a peak is the highest reach 0.1 s either side
    soon = int(round(0.15 / frame_time))  # a foot landing this soon after full reach: a step
    up = np.zeros(3)
    axis, sign = standing_up(skeleton, world_pos[:: max(1, frames // 200)])
    up[axis] = sign
    down = _torso_down(world_pos, limbs, up)
    found: dict[str, list[dict]] = {}
    for name, limb in limbs.items():
        if not name.endswith(("_arm", "_leg")):
            continue
        full = limb_length(skeleton, limb)
        if full <= 0:
            continue
        vector = world_pos[:, limb.end] - world_pos[:, limb.base]
        reach = gaussian_average(vector_norm(vector) / full, 0.015 / frame_time)  # not jitter
        # Away from the body: from the torso's down line and from the floor's (a scoop down to the floor from a
        # bent back points away from the torso and at the floor; a leg stepping down a climbing frame too).
        direction = vector / np.maximum(vector_norm(vector), 1e-12)[:, None]
        angle = np.degrees(np.arccos(np.clip(np.sum(direction * down, axis=-1), -1.0, 1.0)))
        floor_angle = np.degrees(np.arccos(np.clip(-direction @ up, -1.0, 1.0)))
        down_at = np.zeros(frames, bool)
        for first, last in (steps or {}).get(name, ()):
            down_at[max(0, first - soon): last + 1] = True  # on the ground, or landing within 0.15 s
        rate = np.gradient(reach, frame_time)
        found[name] = []
        previous = -1
        for top, first, last in _holds(reach, near, direction):
            lo = max(0, first - span, min(previous + 1, first))  # not back past the limb's last hold
            previous = last
            least = lo + int(np.argmin(reach[lo : first + 1]))
            arrive = first + int(np.argmax(reach[first : top + 1] >= reach[top] - 0.02))
            fastest = float(rate[least : arrive + 1].max(initial=0.0))
            start = least
            if fastest > 0:  # where the extension gets going
                start = max(lo, least + int(np.argmax(rate[least : arrive + 1] >= 0.25 * fastest)) - 1)
            found[name].append(dict(start=int(start), arrive=int(arrive), last=int(last),
                                    reach=round(float(reach[top]), 4), rise=round(float(reach[top] - reach[least]), 4),
                                    angle=round(float(min(angle[arrive], angle[top])), 2),
                                    floor_angle=round(float(min(floor_angle[arrive], floor_angle[top])), 2),
                                    sweep=round(float(np.degrees(np.arccos(np.clip(
                                        direction[start] @ direction[arrive], -1.0, 1.0)))), 2),
                                    step=name.endswith("_leg") and bool(down_at[arrive])))
    out = []
    for name, holds in found.items():
        # Both legs unfolding together, neither on the ground: legs swung from a seat, kicked out in a leap (a
        # standing leg straightening under a kick is not a pair); both arms flung out together: a pose, a leap,
        # a balance (both arms reaching overhead are two strikes: reaching up to grab).
        other = found.get(_pair_of(name), [])
        together = 0.5 * min_rise if name.endswith("_leg") else min_rise  # (the hand following on a sword's hilt: no)
        unfolding = [(h["start"] - soon, h["arrive"] + soon) for h in other
                     if h["rise"] >= together and h["reach"] >= CANDIDATE_REACH and not h["step"]]
        for h in holds:
            paired = (any(a <= h["arrive"] and h["start"] <= b for a, b in unfolding)
                      and (name.endswith("_leg") or h["angle"] < OVERHEAD))
            least_angle = min_leg_angle if name.endswith("_leg") else min_angle
            reasons = []
            if h["reach"] < min_reach:
                reasons.append(f"reach {h['reach']:.2f} is under {min_reach:g}")
            if h["rise"] < min_rise:
                reasons.append(f"it unfolded by {h['rise']:.2f} of its length, under {min_rise:g}")
            if h["angle"] < least_angle:
                reasons.append(f"it points {h['angle']:.0f} degrees from the torso's down line, under {least_angle:g} "
                               "(hanging)")
            if h["floor_angle"] < FLOOR_ANGLE and h["sweep"] < CHOP:
                reasons.append(f"it points {h['floor_angle']:.0f} degrees from straight down and turned only "
                               f"{h['sweep']:.0f} to get there (at the floor, not a chop)")
            if h["step"]:
                reasons.append("its foot is down or lands within 0.15 s (a step)")
            if paired:
                reasons.append(f"the {_pair_of(name).replace('_', ' ')} unfolds with it (a leap or a pose)")
            if h["arrive"] - h["start"] < 2:
                reasons.append("it lasts under 3 frames")
            why = "; ".join(reasons)
            out.append(Candidate(name, h["start"], h["arrive"], h["last"], h["reach"], h["rise"], h["angle"],
                                 h["floor_angle"], h["sweep"], h["step"], paired, why))
    return sorted(out, key=lambda c: (c.arrive, c.limb))


def _holds(reach: np.ndarray, near: int, direction: np.ndarray) -> list[tuple[int, int, int]]:
    """(top, first, last) of every hold near a reach peak of at least `CANDIDATE_REACH`: the peak (the
    highest of the hold), the first and last frames within `HOLD` of it. Peaks on one hold (pointing
    within 30 degrees of each other; ``direction`` (F, 3) unit, the limb's) count once."""
    padded = np.pad(reach, near, mode="edge")
    highest = np.lib.stride_tricks.sliding_window_view(padded, 2 * near + 1).max(axis=-1)
    holds: list[tuple[int, int, int]] = []
    for peak in np.flatnonzero((reach >= highest) & (reach >= CANDIDATE_REACH)):
        below = reach < reach[peak] - HOLD
        before = np.flatnonzero(below[:peak])
        after = np.flatnonzero(below[peak:])
        first = int(before[-1]) + 1 if len(before) else 0
        last = int(peak + after[0]) - 1 if len(after) else len(reach) - 1
        # On the hold before, pointing the same way (an arm held up creeping higher; not a straight
        # leg swung from standing into a kick).
        if holds and peak <= holds[-1][2] and direction[peak] @ direction[holds[-1][0]] >= np.cos(np.radians(30)):
            if reach[peak] <= reach[holds[-1][0]]:
                continue
            first = min(first, holds.pop()[1])  # its top is this one; it began where it began
        holds.append((int(peak), first, last))
    return holds


def _pair_of(name: str) -> str:
    side, _, kind = name.partition("_")
    return f"{'right' if side == 'left' else 'left'}_{kind}"


def _torso_down(world_pos: np.ndarray, limbs: dict, up: np.ndarray) -> np.ndarray:
    """(F, 3) unit: from the top of the spine toward the hips (straight down, ``-up``, without a spine)."""
    spine = limbs.get("spine")
    if spine is None:
        return np.broadcast_to(-up, world_pos.shape[:1] + (3,))
    down = world_pos[:, spine.base] - world_pos[:, spine.end]
    return down / np.maximum(vector_norm(down, keepdims=True), 1e-12)
