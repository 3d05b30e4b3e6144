"""Constraint post-processing (Kwon & Lee 2008, section 6): planted feet, hits that land, a floor.

Exaggeration moves end effectors, so feet slide and sink and punches miss.
This block runs after the last stage that moves positions (the springs) and
restores the constraints the capture had:

* **Contacts** are found on the captured motion: an end effector (a foot and
  its toes, a hand and its fingers) that is near the ground and nearly still,
  with hysteresis and a minimum duration. While in contact it keeps its
  captured position (``anchor = "captured"``), or its exaggerated position at
  the contact's first frame plus the captured roll since (``"exaggerated"``,
  which keeps the bigger stride), and its captured orientation, so toes and
  heels stay down too.
* **Targets** (``--target JOINT@FRAME[=x,y,z]``) keep an end effector where it
  was captured at a frame, or put it at a given point.
* **Stretch keys**: the length a stretch promised at its final frame, which the
  springs would otherwise soften.
* **Floor**: no joint of the output goes below the captured floor; a joint
  that would is pressed onto it by a smooth (C1) soft clamp, not cut.

Every constraint is a per-frame target and weight for one end effector,
eased in and out (C2 smootherstep) outside the constrained frames so nothing
pops. The chain above the end effector (limb base to end, sub-joints
included) is then deformed to meet it, for all constrained frames at once:
the discrete Laplacian curve deformation Nealen et al. (2007) describe and the
paper used, with the base fixed and the end at its target. Each point's
Laplacian (its offset from the length-weighted mean of its neighbours, i.e.
the chain's bend) is kept, turned with the chain's local direction, in two
passes. Without sub-joints (a plain thigh-knee-ankle chain) the chain is
solved by two-bone IK instead, which keeps both bones' lengths while they can
reach.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..analysis.branches import incoming_joint, minor_branches, rider_joints, rubber_groups
from ..analysis.limbs import Limb, behind_line, hinge_pole, offset_from_line
from ..core.errors import ConfigError, check_choice, check_flag, check_number
from ..core.kinematics import consecutive
from ..core.rotations import quat_between, quat_inv, quat_mul, quat_rotate, quat_slerp, sum_last, vector_norm
from ..core.settings import Flag, setting
from ..core.skeleton import Skeleton
from ..core.timing import check_duration, gaussian_average, parse_duration, parse_frame, smootherstep, spread_max
from .collide import deeper_than_captured, keep_out, prepare_body, unbend_hinges
from .state import Pins
from .subjoints import even_out

if TYPE_CHECKING:
    from .state import State, StretchKey

__all__ = [
    "ContactConfig",
    "TargetSpec",
    "parse_target",
    "Ground",
    "find_ground",
    "Effector",
    "find_effectors",
    "detect_contacts",
    "find_contacts",
    "constrain",
    "ConstraintPlan",
    "constraints_stage",
    "contact_weights",
    "run_ramps",
    "ease_lengths",
    "laplacian_deform",
    "two_bone_ik",
    "limb_contacts",
    "soft_floor",
    "smootherstep",
]

_ANCHORS = ("captured", "exaggerated")
#: Named sets of end effectors.
_SETS = {"feet": ("left_leg", "right_leg"), "hands": ("left_arm", "right_arm")}


@dataclass(frozen=True, kw_only=True)
class ContactConfig:
    """Settings of the contact block (detection, pinning and the floor).

    joints : end effectors watched for contacts: ``feet``, ``hands``, limb
        names (``left_leg``) or end-effector joint names
    anchor : ``captured`` keeps a planted end effector where it was captured;
        ``exaggerated`` where the exaggerated motion put it on the contact's
        first frame (horizontally), keeping the bigger stride
    height : near the ground: within this share of the body height above the
        lowest level the point itself reaches (points that never come within
        0.1 of the height of the floor, such as hands in a walk, never touch)
    speed : nearly still: slower than this many body heights per second
        (a contact holds while under 1.6 times this and 1.5 times ``height``)
    min_duration : shorter contacts are ignored (seconds, ``"80ms"`` or ``"10f"``)
    blend : time to ease into and out of each contact (and a floor press)
    floor : keep every joint above the captured floor
    """

    enabled: bool = setting(True, flag=Flag(
        "--contacts", "Feet (or the joints in [contacts]) that touch the ground in the capture stay planted there, "
        "and no joint goes below the captured floor (auto); off leaves them as exaggerated.",
        choices={"auto": True, "off": False}))
    joints: tuple[str, ...] = ("feet",)
    anchor: str = setting("captured", flag=Flag(
        "--anchor", "Where a planted foot stays: where it was captured, or where the exaggeration put it when it "
        "landed (keeps the bigger stride).", choices=_ANCHORS))
    height: float = 0.04
    speed: float = 0.3
    min_duration: str | float = "0.08s"
    blend: str | float = "0.15s"
    floor: bool = setting(True, flag=Flag(
        "--floor/--no-floor", "Keep every joint above the captured floor (with --contacts auto)."))
    collide: bool = setting(True, flag=Flag(
        "--collide/--no-collide", "Push hands, forearms, feet and shins out of the torso, pelvis, head and thighs "
        "where the captured ones stay out, and bend knees and elbows the captured way (with --contacts auto)."))

    def __post_init__(self) -> None:
        check_flag("contacts.enabled", self.enabled)
        check_flag("contacts.floor", self.floor)
        check_flag("contacts.collide", self.collide)
        if isinstance(self.joints, str) or not all(isinstance(j, str) for j in self.joints):
            raise ConfigError(f"contacts.joints must be a list of names (feet, hands, limbs or joints), got {self.joints!r}")
        object.__setattr__(self, "joints", tuple(self.joints))
        check_choice("contacts.anchor", self.anchor, _ANCHORS)
        check_number("contacts.height", self.height, 0, 1)
        check_number("contacts.speed", self.speed, 0, 100)
        for name in ("min_duration", "blend"):
            check_duration(getattr(self, name), f"contacts.{name}")


@dataclass(frozen=True, kw_only=True)
class TargetSpec:
    """An end effector held at a point at one frame (eased in and out over ``window``).

    joint : an end effector's joint name, or a limb name (its end)
    frame : frame number, or a time such as ``"1.25s"``
    position : (x, y, z) in the clip's units and axes; None keeps the
        captured position at that frame (the punch lands where it landed)
    window : time over which the target eases in before and out after the frame
    """

    joint: str
    frame: int | str
    position: tuple[float, float, float] | None = None
    window: str | float = "0.25s"

    def __post_init__(self) -> None:
        if not isinstance(self.joint, str) or not self.joint:
            raise ConfigError(f"target: joint must be a name, got {self.joint!r}")
        if self.position is not None:
            if not isinstance(self.position, (list, tuple)) or len(self.position) != 3:
                raise ConfigError(f"target {self.joint}: position must be three numbers x,y,z, got {self.position!r}")
            for axis, value in zip("xyz", self.position):
                check_number(f"target {self.joint}: {axis}", value, -1e9, 1e9)
            object.__setattr__(self, "position", tuple(float(v) for v in self.position))
        check_duration(self.window, f"target {self.joint}: window")
        parse_frame(self.frame, 1.0, what=f"target {self.joint}: frame")

    def frame_index(self, frame_time: float, num_frames: int) -> int:
        frame = parse_frame(self.frame, frame_time, what=f"target {self.joint}: frame")
        if not 0 <= frame < num_frames:
            raise ConfigError(f"target {self.joint}@{self.frame}: frame {frame} is outside the clip (0-{num_frames - 1})")
        return frame

    def to_dict(self) -> dict:
        out = {"joint": self.joint, "frame": self.frame, "window": self.window}
        if self.position is not None:
            out["position"] = list(self.position)
        return out


_TARGET = re.compile(r"^\s*([^@=\s]+)\s*@\s*([^=]+?)\s*(?:=\s*(.*))?$")


def parse_target(text: str) -> TargetSpec:
    """A target from the command line: ``JOINT@FRAME`` or ``JOINT@FRAME=x,y,z``.

    >>> parse_target("RightHand@1251=10,150,40").position
    (10.0, 150.0, 40.0)
    """
    match = _TARGET.match(text)
    if not match:
        raise ConfigError(f"target {text!r}: expected JOINT@FRAME or JOINT@FRAME=x,y,z, e.g. RightHand@1251")
    joint, frame, point = match.groups()
    position = None
    if point is not None:
        parts = [p.strip() for p in point.split(",")]
        try:
            position = tuple(float(p) for p in parts)
        except ValueError:
            raise ConfigError(f"target {text!r}: {point!r} is not three numbers x,y,z") from None
        if len(position) != 3 or not all(np.isfinite(position)):
            raise ConfigError(f"target {text!r}: {point!r} is not three finite numbers x,y,z")
    return TargetSpec(joint=joint, frame=frame, position=position)


# ---------------------------------------------------------------------------- the ground


class Ground(NamedTuple):
    """Which way is up and where the floor is.

    axis : index of the up axis; sign : +1 or -1 (which way along it is up)
    floor : the lowest height any captured joint reaches (in ``sign * coordinate``)
    height : the body height, the length scale of every threshold
    """

    axis: int
    sign: float
    floor: float
    height: float

    def heights(self, positions: np.ndarray) -> np.ndarray:
        return self.sign * positions[..., self.axis]

    def up(self) -> np.ndarray:
        vector = np.zeros(3)
        vector[self.axis] = self.sign
        return vector


def find_ground(skeleton: Skeleton, captured_pos: np.ndarray, limbs: dict[str, Limb] | None = None) -> Ground:
    """The up axis of the rest pose, its sign from the captured body, and the captured floor.

    captured_pos : (F, J, 3) float64 captured world positions (motion frames only)
    limbs : found limbs; up is from the feet toward the head (or the root); without
        legs, toward positive coordinates
    """
    axis = skeleton.up_axis()
    heights = captured_pos[..., axis]
    limbs = limbs or {}
    feet = [limbs[name].end for name in ("left_leg", "right_leg") if name in limbs]
    top = [limbs[name].end for name in ("neck", "spine") if name in limbs][:1] or [0]
    sign = 1.0
    if feet and heights.size:
        sign = 1.0 if np.mean(heights[:, top]) >= np.mean(heights[:, feet]) else -1.0
    floor = float((sign * heights).min()) if heights.size else 0.0
    return Ground(axis, sign, floor, skeleton.height())


def soft_floor(heights: np.ndarray, floor: float, margin: float) -> np.ndarray:
    """Heights pressed onto the floor smoothly: unchanged above it, never ``margin`` below it.

    Below the floor ``h -> floor - margin (1 - exp((h - floor) / margin))``: the
    same value and slope at the floor (C1), so a joint sliding under it keeps
    moving smoothly and flattens out just under the surface.
    """
    below = heights < floor
    out = np.array(heights, dtype=np.float64)
    out[below] = floor - margin * (1.0 - np.exp((heights[below] - floor) / margin))
    return out


# ---------------------------------------------------------------------------- end effectors


@dataclass(frozen=True)
class Effector:
    """An end effector and the chain that bends to move it.

    joint : the end joint; chain : original joints from the fixed base to ``joint``
    riders : joints that ride rigidly on it (toes, fingers)
    points : the joint and the riders with a link of their own: where it can touch
    """

    joint: int
    chain: tuple[int, ...]
    riders: tuple[int, ...] = field(default=())
    points: tuple[int, ...] = field(default=())


def find_effectors(skeleton: Skeleton, limbs: dict[str, Limb], rigid: np.ndarray,
                   groups: tuple[tuple[int, ...], ...] = ()) -> dict[int, Effector]:
    """Every end effector the block can move, keyed by joint.

    A limb's end (hands, feet, the head) bends its limb's chain from the
    limb's base; the end of any other rubber group bends that group.
    ``rigid`` (J,) marks the branches that ride rigidly (their joints are the
    end's riders).
    """
    out: dict[int, Effector] = {}
    lengths = skeleton.link_lengths()
    height = skeleton.height()

    def effector(chain) -> Effector | None:
        end = int(chain[-1])
        below = skeleton.descendants(end)[1:]
        if rigid[end] or not all(rigid[below]):
            return None  # something that bends hangs below: not an end
        riders = tuple(int(j) for j in below)
        points = (end,) + tuple(j for j in riders if lengths[j] > 1e-3 * height)
        return Effector(end, tuple(int(j) for j in chain), riders, points)

    for chain in list(groups) + [limb.joints for limb in limbs.values()]:
        if len(chain) >= 2 and (found := effector(chain)) is not None:
            out[found.joint] = found  # a limb's chain (from its base) wins over its group's
    return out


def resolve_effector(name: str, skeleton: Skeleton, limbs: dict[str, Limb], effectors: dict[int, Effector],
                     what: str, heights: np.ndarray | None = None) -> list[int]:
    """End-effector joints for a name: ``feet``, ``hands``, a limb or a joint; ConfigError otherwise.

    heights : (F, J) the capture's heights above the floor: ``feet`` are then also the arms' ends
        that go as low as the legs' (`mocap_exaggerate.analysis.limbs.standing_ends`: a fox's front paws)
    """
    if name == "feet":
        from ..analysis.limbs import standing_ends

        return [end for end in standing_ends(skeleton, limbs, heights) if end in effectors]
    if name in _SETS:
        return [limbs[limb].end for limb in _SETS[name] if limb in limbs and limbs[limb].end in effectors]
    if name in limbs:
        if limbs[name].end not in effectors:
            raise ConfigError(f"{what}: the end of {name} cannot be moved (it rides rigidly)")
        return [limbs[name].end]
    if name not in skeleton.names:
        raise ConfigError(f"{what}: no joint or limb named {name!r} (limbs: {', '.join(limbs) or 'none found'})")
    joint = skeleton.index(name)
    if joint not in effectors:
        names = ", ".join(skeleton.names[j] for j in sorted(effectors)) or "none"
        raise ConfigError(f"{what}: {name} is not an end effector (end effectors: {names})")
    return [joint]


# ---------------------------------------------------------------------------- detection


def _runs(mask: np.ndarray) -> np.ndarray:
    """Inclusive ``(start, end)`` rows of the runs of True in a 1-D mask, ``(R, 2)``."""
    padded = np.concatenate([[False], mask, [False]]).astype(np.int8)
    edges = np.diff(padded)
    return np.stack([np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1], axis=1)


def _mask_from_runs(runs: np.ndarray, length: int) -> np.ndarray:
    marks = np.zeros(length + 1, np.int64)
    np.add.at(marks, runs[:, 0], 1)
    np.add.at(marks, runs[:, 1] + 1, -1)
    return np.cumsum(marks[:-1]) > 0


def _runs_holding(loose: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """(F,) bool: the runs of ``loose`` (F,) that hold a frame of ``seed`` (F,) (a hysteresis: entered on the
    strict condition, held on the loose one)."""
    runs = _runs(loose)
    if not len(runs):
        return np.zeros(len(loose), bool)
    inside = np.cumsum(np.concatenate([[0], seed.astype(np.int64)]))
    return _mask_from_runs(runs[inside[runs[:, 1] + 1] - inside[runs[:, 0]] > 0], len(loose))


def _speed(points: np.ndarray, frame_time: float) -> np.ndarray:
    """Speed ``(F, P)`` of points ``(F, P, 3)`` by central differences over a light smoothing."""
    from ..core.timing import gaussian_average

    smooth = gaussian_average(points, max(0.02 / frame_time, 0.5))
    velocity = np.gradient(smooth, frame_time, axis=0) if len(points) > 1 else np.zeros_like(points)
    return vector_norm(velocity)


#: A point held still this long (seconds) touches up to `STILL_BAND` times ``contacts.height`` over its lowest
#: level (`detect_contacts`): a foot planted a little higher than its lowest step. Higher, a held foot is as
#: likely a kick or a balance held in the air, whose exaggeration a contact would take away.
STILL_HOLD = 0.25
STILL_BAND = 2.5


def detect_contacts(captured_pos: np.ndarray, effector: Effector, ground: Ground, frame_time: float,
                    config: ContactConfig, *, foot: bool = True) -> np.ndarray:
    """Inclusive ``(start, end)`` frame ranges ``(R, 2)`` in which the effector touches the ground.

    A point of the effector (its joint or a rider with a link of its own)
    touches when it is within ``config.height`` of its own lowest level and
    slower than ``config.speed``; a contact holds while it stays within 1.5
    times that height and 1.6 times that speed, and lasts at least
    ``config.min_duration`` (unless the clip's first or last frame cuts it
    short). A ``foot``'s point slower than ``config.speed`` for `STILL_HOLD`
    seconds or more touches too, within `STILL_BAND` times that height (0.1
    heights at the default 0.04), and holds, with the same hysteresis, while
    under 1.6 times that speed (a run the clip's ends cut needs the whole
    0.25 s too): the iClone slow walk's last step, planted 0.07 heights over
    its lowest level, slid 0.46 heights under the exaggeration. (The uneven
    walk's step onto a rise, its toes 0.11-0.12 heights up, is just past that
    band and still slides; a hand is not held so, as one that pauses in the
    air is not a contact.) The effector touches when any point does.
    """
    frames = captured_pos.shape[0]
    if frames < 3:
        return np.zeros((0, 2), np.int64)
    h = ground.height
    points = list(effector.points)
    pos = captured_pos[:, points]
    height = ground.heights(pos) - ground.floor
    own = np.percentile(height, 2.0, axis=0)
    reaches = own < 0.1 * h
    above = height - own
    speed = _speed(pos, frame_time) / h
    strict = (above < config.height * h) & (speed < config.speed) & reaches
    loose = (above < 1.5 * config.height * h) & (speed < 1.6 * config.speed) & reaches
    band = (above < STILL_BAND * config.height * h) & reaches & foot
    held, held_loose = band & (speed < config.speed), band & (speed < 1.6 * config.speed)
    hold = max(2, int(round(STILL_HOLD / frame_time)))
    touch = np.zeros(frames, bool)
    for p in range(len(points)):
        touch |= _runs_holding(loose[:, p], strict[:, p])
        still = _runs(held[:, p])
        seeds = still[still[:, 1] - still[:, 0] + 1 >= hold] if len(still) else still
        if len(seeds):
            # Held on through a blip over the speed (the uneven walk's landing ran 0.31-0.33 for three
            # frames, which cut the plant's first 17 frames off): the looser runs that hold a long-still one.
            touch |= _runs_holding(held_loose[:, p], _mask_from_runs(seeds, frames))
    runs = _runs(touch)
    shortest = max(1, int(round(parse_duration(config.min_duration, frame_time, what="contacts.min_duration"))))
    # A contact cut off by the clip's first or last frame may have lasted longer than we see.
    cut = (runs[:, 0] == 0) | (runs[:, 1] == frames - 1)
    return runs[(runs[:, 1] - runs[:, 0] + 1 >= np.where(cut, min(shortest, 2), shortest))]


def find_contacts(skeleton: Skeleton, captured_pos: np.ndarray, frame_time: float, limbs: dict[str, Limb],
                  effectors: dict[int, Effector], config: ContactConfig) -> tuple[Ground, dict[int, np.ndarray]]:
    """The ground, and the contact ranges ``(R, 2)`` of every end effector ``config.joints`` names."""
    ground = find_ground(skeleton, captured_pos, limbs)
    heights = ground.sign * captured_pos[..., ground.axis] - ground.floor
    watched: list[int] = []
    for name in config.joints:
        for joint in resolve_effector(name, skeleton, limbs, effectors, "contacts.joints", heights):
            if joint not in watched:
                watched.append(joint)
    feet = {limb.end for name, limb in limbs.items() if name.endswith("_leg")}
    return ground, {joint: detect_contacts(captured_pos, effectors[joint], ground, frame_time, config,
                                           foot=joint in feet)
                    for joint in watched}


def limb_contacts(skeleton: Skeleton, captured_pos: np.ndarray, frame_time: float, limbs: dict[str, Limb],
                  config: ContactConfig | None = None) -> dict[str, np.ndarray]:
    """The contact ranges ``(R, 2)`` of the limbs' ends a capture plants (``config.joints``: the feet), by limb."""
    config = config or ContactConfig()
    effectors = find_effectors(skeleton, limbs, minor_branches(skeleton))
    _, touching = find_contacts(skeleton, captured_pos, frame_time, limbs, effectors, config)
    return {name: touching[limb.end] for name, limb in limbs.items() if limb.end in touching}


def contact_weights(runs: np.ndarray, frames: int, ramp) -> np.ndarray:
    """Weight ``(F,)``: 1 inside the runs, easing to 0 over ``ramp`` frames outside them.

    ``ramp`` is one number for every run, or ``(n, 2)`` frames before and after each run.
    """
    free = np.ones(frames)
    if not len(runs):
        return 1.0 - free
    ramps = np.maximum(np.broadcast_to(np.asarray(ramp, dtype=np.float64), (len(runs), 2)), 0.0)
    for (first, last), (before, after) in zip(runs, ramps):  # a loop over contacts, not frames
        lo, hi = max(0, int(first - before - 1)), min(frames, int(np.ceil(last + after + 2)))
        index = np.arange(lo, hi, dtype=np.float64)
        early = smootherstep(1.0 - (first - index) / (before + 1.0))
        late = smootherstep(1.0 - (index - last) / (after + 1.0))
        # Combined as 1 - prod(1 - w), not max: where one run's ease out meets the next one's ease in,
        # a max has a corner (a foot between two close steps popped at 3x the free run's acceleration).
        free[lo:hi] *= 1.0 - np.where(index < first, early, np.where(index > last, late, 1.0))
    return 1.0 - free


def run_ramps(runs: np.ndarray, gap: np.ndarray, speed: float, ramp: float, longest: float) -> np.ndarray:
    """Frames ``(n, 2)`` to ease into and out of each run.

    At least ``ramp``, and long enough that closing the ``gap`` (F,) between
    where the point is and where it must be adds at most ``speed`` per frame
    over the whole ease (a smootherstep's steepest slope is 15/8 of its
    average), but never more than ``longest``: the shortest ``R`` with
    ``15/8 max(gap over the R frames) / R <= speed``.
    """
    frames = len(gap)
    longest = max(int(np.ceil(longest)), int(np.ceil(ramp)))
    steps = np.arange(longest + 1)
    out = np.empty((len(runs), 2))
    for row, (first, last) in enumerate(runs):
        for side, (start, direction) in enumerate(((first, -1), (last, 1))):
            reach = np.clip(start + direction * steps, 0, frames - 1)
            needed = 1.875 * np.maximum.accumulate(gap[reach]) / max(speed, 1e-300)
            fits = np.flatnonzero((steps >= ramp) & (steps >= needed))
            out[row, side] = steps[fits[0]] if len(fits) else longest
    return out


def ease_lengths(runs: np.ndarray, paths: np.ndarray, shift: np.ndarray, limits: np.ndarray, ramp: float,
                 longest: float) -> np.ndarray:
    """Frames ``(n, 2)`` to ease into and out of each run, chosen by the speed of the eased path.

    paths : (F, k, 3) the points that move with the eased one (a foot and the toes riding it)
    shift : (F, 3) where the eased point must go minus where it is (the move the ease adds)
    limits : (k,) the step per frame each point may take (the extrapolation's speed limit)

    Easing over ``R`` frames moves the points by ``w_R(d) shift`` at ``d`` frames from the run
    (``w_R`` the smootherstep of `contact_weights`). The ease is the shortest ``R >= ramp`` for
    which no point steps further than ``max(limit, its own step before the ease)`` anywhere in
    the ``longest`` frames beside the run; where none is, the ``R`` whose worst step is the
    smallest. Unlike `run_ramps`, which bounds the move the ease adds, this bounds the
    path the viewer sees: an ease that adds speed along a move already at the limit is
    lengthened, one that adds speed against the move is not.
    """
    frames = len(paths)
    longest = max(int(np.ceil(longest)), int(np.ceil(ramp)))
    distance = np.arange(longest + 2)  # frames from the run's edge (0: its first or last frame)
    lengths = np.arange(int(np.ceil(ramp)), longest + 1)
    weights = smootherstep(np.clip(1.0 - distance[None, :] / (lengths[:, None] + 1.0), 0.0, 1.0))  # (R, d)
    out = np.empty((len(runs), 2))
    # Each side of each run (first: easing in, before it; last: easing out, after it), a block of sides at a time.
    edges = np.asarray(runs, dtype=np.int64).reshape(-1)
    directions = np.tile([-1, 1], len(runs))
    for block in range(0, len(edges), _EASE_BLOCK):
        cut = slice(block, block + _EASE_BLOCK)
        reach = np.clip(edges[cut, None] + directions[cut, None] * distance, 0, frames - 1)  # (n, d)
        near, moved = paths[reach], shift[reach]  # (n, d, k, 3), (n, d, 3)
        allowed = np.maximum(vector_norm(np.diff(near, axis=1)), limits)  # (n, d-1, k)
        # The shortest ease first, every side at once: most fit (a length's worst step is the same number
        # whether it is worked out alone or with others); the others try every length.
        shortest = _worst_steps(near, moved, weights[:1], allowed)[:, 0]
        for index in range(len(reach)):
            side = block + index
            if shortest[index] <= 1.0 + 1e-9:
                out.flat[side] = lengths[0]
                continue
            worst = _worst_steps(near[index][None], moved[index][None], weights, allowed[index][None])[0]
            fits = np.flatnonzero(worst <= 1.0 + 1e-9)
            out.flat[side] = lengths[fits[0]] if len(fits) else lengths[int(np.argmin(worst))]
    return out


#: Run sides `ease_lengths` works out at once (its temporaries about 200 kB per hundred).
_EASE_BLOCK = 256


def _worst_steps(near: np.ndarray, moved: np.ndarray, weights: np.ndarray, allowed: np.ndarray) -> np.ndarray:
    """For sides ``near (n, d, k, 3)`` of `ease_lengths` (the points beside a run) and each ease's weights
    ``(R, d)``: the largest ratio ``(n, R)`` of a point's step on the eased path ``near + w moved``
    (``moved (n, d, 3)``) to the step it is ``allowed (n, d-1, k)``."""
    eased = near[:, None] + weights[None, :, :, None, None] * moved[:, None, :, None, :]  # (n, R, d, k, 3)
    steps = vector_norm(np.diff(eased, axis=2))  # (n, R, d-1, k)
    allowed = np.broadcast_to(allowed[:, None], steps.shape)
    # (a point that never moves, in a clip held still, may not move at all: 0 / 0 fits)
    ratio = np.divide(steps, allowed, out=np.where(steps > 0, np.inf, 0.0), where=allowed > 0)
    return ratio.max(axis=(2, 3))


def anchored_targets(captured: np.ndarray, current: np.ndarray, runs: np.ndarray, ground: Ground) -> np.ndarray:
    """Targets ``(F, 3)`` for ``anchor = "exaggerated"``: the captured path moved, in each contact,
    by the horizontal offset of the exaggerated position on its first frame; the offset
    slides linearly from one contact's to the next between them."""
    offsets = current[runs[:, 0]] - captured[runs[:, 0]]
    offsets[:, ground.axis] = 0.0
    knots = runs.astype(np.float64).reshape(-1)
    values = np.repeat(offsets, 2, axis=0)
    index = np.arange(len(captured), dtype=np.float64)
    shift = np.stack([np.interp(index, knots, values[:, k]) for k in range(3)], axis=1)
    return captured + shift


# ---------------------------------------------------------------------------- deformation


def _laplacian_system(rest: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Neighbour weights ``a, b (n-2,)`` of each interior point and the inverse ``(n-2, n-2)`` of
    the interior system ``x_i - a_i x_{i-1} - b_i x_{i+1} = delta_i``.

    rest : (n,) rest length of the segment ending at each point (rest[0] unused). The
    weights are by length (``a_i = l_{i+1} / (l_i + l_{i+1})``), so a chain whose
    Laplacians are all zero is spread in proportion to its rest lengths.
    """
    before, after = rest[1:-1], rest[2:]
    total = before + after
    a = np.divide(after, total, out=np.full_like(total, 0.5), where=total > 0)
    b = 1.0 - a
    n = len(rest) - 2
    system = np.eye(n)
    if n > 1:
        system[np.arange(1, n), np.arange(n - 1)] = -a[1:]
        system[np.arange(n - 1), np.arange(1, n)] = -b[:-1]
    return a, b, np.linalg.inv(system)


def laplacian_deform(points: np.ndarray, end: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """Move a chain's last point to ``end`` keeping its first point and its shape.

    points : (F, n, 3) float64 chain positions, base first
    end : (F, 3) float64 where the last point must go
    rest : (n,) rest length of the segment ending at each point

    The discrete Laplacian curve deformation (Nealen et al. 2007, used by Kwon
    & Lee for their section 6): with both ends fixed, the interior points solve
    ``L x = delta``, where ``delta`` are the chain's own Laplacians (its bends).
    The Laplacians are not turned with the chord: on exaggerated limbs that
    fold through themselves (looney jumps) the chord swings half a turn in a
    few frames and a turned bend whipped the knee around (7x the largest
    acceleration), while the plain solve moves every point by a length-weighted
    share of the end's move, so it is as smooth in time as its input. The
    system's matrix is the same for every frame: it is inverted
    once and applied to all frames together. Returns (F, n, 3).
    """
    points = np.asarray(points, dtype=np.float64)
    n = points.shape[1]
    out = points.copy()
    out[:, -1] = end
    if n < 3:
        return out
    rest = np.asarray(rest, dtype=np.float64)
    a, b, inverse = _laplacian_system(rest)
    delta = points[:, 1:-1] - a[:, None] * points[:, :-2] - b[:, None] * points[:, 2:]
    rhs = delta
    rhs[:, 0] += a[0] * out[:, 0]
    rhs[:, -1] += b[-1] * out[:, -1]
    out[:, 1:-1] = np.einsum("ij,fjk->fik", inverse, rhs)
    return out


#: The last share of a two-bone chain's reach over which it eases into straight (soft IK).
SOFT_REACH = 0.1
#: Reach (base to end over the bones' length) below which a two-bone chain folds as rubber, easing in from the second.
FOLDED = (0.2, 0.45)
#: The limbs whose middle joint is a hinge (a knee, an elbow) the body pass keeps bending the captured way.
LIMB_HINGES = ("left_arm", "right_arm", "left_leg", "right_leg")
#: A stretch's length missed by more than this share is said (a warning: stderr and the manifest).
SHORTFALL = 0.01

#: At most this many rounds of the body pass and the floor (`constrain`): each lift off the floor can put a
#: part back in (a boxer's pelvis lifted off the canvas onto his heel), and the next round pushes it out.
BODY_ROUNDS = 4
#: Frames (a Gaussian's sigma) over which a two-bone chain's middle joint's move is eased in time (2 let a
#: looney boxer's knee move 2.004x its largest captured step as he knelt, issue 25).
HINGE_EASE = 2.5


def two_bone_ik(base: np.ndarray, middle: np.ndarray, end: np.ndarray, target: np.ndarray,
                pole: np.ndarray | None = None, soft: float = SOFT_REACH) -> np.ndarray:
    """The middle joint ``(F, 3)`` that lets a two-bone chain reach ``target`` (its end goes there).

    The middle joint moves by as much as a two-bone solve's middle moves
    between the chain's end now and the target, so the chain is unchanged
    where the target is its end (a foot easing onto its contact starts from
    the exaggerated leg, not from a solve of it). The solve keeps both bones'
    current lengths while the target is well within reach and bends in the
    plane the chain bends in now, on the side of ``pole`` ``(F, 3)`` (where
    the knee or elbow points, `hinge_pole`) where the chain runs nearly
    straight: a straight chain's own bend is noise, and following it swung
    the knee round.

    Near full reach the solve eases into straight instead of snapping to it
    (soft IK): over the last ``soft`` share of the reach the bend closes
    exponentially and the bones lengthen to make up the rest. A
    length-keeping solve moves the middle joint without bound there (its
    offset is a square root of the distance to full reach): that was the
    knee pop of ``--no-subjoints``. Past reach (or closer than the bones
    can fold) both bones scale together, as rubber would.
    """
    upper = vector_norm(middle - base)
    lower = vector_norm(end - middle)
    own = offset_from_line(base, middle, end)
    if pole is not None:  # the pole decides the side where the chain's own bend is under 5-20 % of its upper bone
        clear = smootherstep((vector_norm(own) / np.maximum(upper, 1e-12) - 0.05) / 0.15)
        own = own + (1.0 - clear)[:, None] * 0.2 * upper[:, None] * pole
    now = _solve_middle(base, upper, lower, end, own, soft)
    moved = _solve_middle(base, upper, lower, target, own, soft)
    # Folded nearly shut (a looney squat's thigh onto its shin) keeping both lengths swings the middle
    # joint by the bones' length over the end's distance from the base times the end's move (12x at
    # 4 % of the reach): there the middle joint takes its share of the end's move, as rubber.
    reach = np.minimum(vector_norm(end - base), vector_norm(target - base))
    folded = smootherstep((FOLDED[1] - reach / np.maximum(upper + lower, 1e-12)) / (FOLDED[1] - FOLDED[0]))
    share = upper / np.maximum(upper + lower, 1e-12)
    # The chain's own departure from the solve (a knee nearly straight sits off the soft solve's bend)
    # is kept where the target is its end and let go as the target moves away.
    keep = np.exp(-vector_norm(target - end) / np.maximum(soft * (upper + lower), 1e-12))
    solved = moved + keep[:, None] * (middle - now)
    return (1.0 - folded)[:, None] * solved + folded[:, None] * (middle + share[:, None] * (target - end))


def _solve_middle(base, upper, lower, target, side, soft) -> np.ndarray:
    """Where a two-bone chain's middle joint goes for its end to reach ``target``, bending toward ``side``."""
    reach = target - base
    distance = vector_norm(reach)
    tiny = 1e-12
    direction = reach / np.maximum(distance, tiny)[:, None]
    # The side projected across the new line (not turned onto it: a turn is undefined where the line
    # swings past a half turn, a projection is not).
    side = side - sum_last(side * direction, keepdims=True) * direction
    side_len = vector_norm(side)
    fallback = np.cross(direction, np.eye(3)[np.argmin(np.abs(direction), axis=-1)])
    side = np.where((side_len > tiny)[:, None], side, fallback)
    side /= np.maximum(vector_norm(side), tiny)[:, None]
    longest = upper + lower
    shortest = np.abs(upper - lower)
    zone = soft * longest
    start = longest - zone
    solved = distance.copy()  # the distance the bones at their lengths reach
    outer = (distance > start) & (zone > tiny)
    solved[outer] = start[outer] + zone[outer] * (1.0 - np.exp(-(distance[outer] - start[outer]) / zone[outer]))
    far = ~outer & (distance > longest)
    solved[far] = longest[far]
    near = distance < shortest
    solved[near] = shortest[near]
    scale = np.divide(distance, solved, out=np.ones_like(distance), where=solved > tiny)
    along = np.divide(solved**2 + upper**2 - lower**2, 2 * solved, out=np.zeros_like(solved), where=solved > tiny)
    height = np.sqrt(np.maximum(upper**2 - along**2, 0.0))
    return base + scale[:, None] * (along[:, None] * direction + height[:, None] * side)


# ---------------------------------------------------------------------------- the block


class ConstraintResult(NamedTuple):
    """What the block did.

    positions : (F, J', 3) float64 positions on the rubber hierarchy
    pin_joints : (k,) int original joints that keep their captured orientation by ``pin_weights (F, k)``
    contacts : joint name -> inclusive (start, end) frame ranges found
    ground : the up axis and floor used (None when contacts were off)
    keys : per stretch key, the length reached over the length promised
    body : frames on which each part was pushed out of the body (``pushed``) and each limb's middle
        joint brought back from bending the wrong way (``unbent``); empty with ``collide`` off
    """

    positions: np.ndarray
    pin_joints: np.ndarray
    pin_weights: np.ndarray
    contacts: dict[str, list[list[int]]]
    ground: Ground | None
    keys: list[dict]
    body: dict[str, dict[str, int]]


def sub_chain(hierarchy, chain: tuple[int, ...]) -> np.ndarray:
    """Indices in the rubber hierarchy of an original chain and the sub-joints between its joints."""
    out = [int(hierarchy.original[chain[0]])]
    between = ~hierarchy.is_original
    for child in chain[1:]:
        out.extend(int(j) for j in np.flatnonzero(between & (hierarchy.link_child == child)))
        out.append(int(hierarchy.original[child]))
    return np.array(out)


def constrain(
    sub_pos: np.ndarray,
    hierarchy,
    skeleton: Skeleton,
    limbs: dict[str, Limb],
    captured_pos: np.ndarray,
    captured_rot: np.ndarray,
    frame_time: float,
    *,
    config: ContactConfig,
    targets: tuple[tuple[TargetSpec, int], ...] = (),
    keys: tuple[StretchKey, ...] = (),
    groups: tuple[tuple[int, ...], ...] = (),
    max_speed: float = 0.0,
    riders: dict[int, list[int]] | None = None,
) -> ConstraintResult:
    """Restore contacts, targets, stretch keys and the floor on rubber positions.

    sub_pos : (F, J', 3) float64 positions on ``hierarchy`` (motion frames only)
    hierarchy, skeleton : the rubber hierarchy and the original skeleton it was cut from
    captured_pos, captured_rot : (F, J, 3), (F, J, 4) captured world transforms of the original joints
    targets : (spec, frame) pairs, frames counted in ``sub_pos``
    keys : stretch keys, frames counted in ``sub_pos``
    groups : rubber groups of original joints (their ends are end effectors too)
    max_speed : the extrapolation's speed limit (times each joint's captured top speed): a foot
        easing onto its contact and the joints ``riders`` (joint -> rigid riders) keep to it too
        (`ease_lengths`); the ease adds at most the foot's captured top speed in any case (`run_ramps`)
    """
    out = np.array(sub_pos, dtype=np.float64)
    frames = out.shape[0]
    effectors = find_effectors(skeleton, limbs, hierarchy.rigid, groups)
    original = hierarchy.original
    rest = hierarchy.skeleton.link_lengths()
    ramp = parse_duration(config.blend, frame_time, what="contacts.blend")
    poles: dict[int, np.ndarray | None] = {}

    def pole_of(effector: Effector) -> np.ndarray | None:
        """Where the effector's knee or elbow points (`hinge_pole`), for a chain of three original joints."""
        if effector.joint not in poles:
            chain = list(effector.chain)
            poles[effector.joint] = (hinge_pole(captured_pos[:, chain], captured_rot[:, chain[0]])
                                     if len(chain) == 3 else None)
        return poles[effector.joint]

    goals: dict[int, np.ndarray] = {}

    def goal(joint: int) -> np.ndarray:
        if joint not in goals:
            goals[joint] = out[:, original[joint]].copy()
        return goals[joint]

    pins: dict[int, np.ndarray] = {}
    found: dict[str, list[list[int]]] = {}
    ground = None
    if config.enabled:
        ground, touching = find_contacts(skeleton, captured_pos, frame_time, limbs, effectors, config)
        for joint, runs in touching.items():
            found[skeleton.names[joint]] = runs.tolist()
            if not len(runs):
                continue
            if config.anchor == "captured":
                target = captured_pos[:, joint]
            else:
                target = anchored_targets(captured_pos[:, joint], out[:, original[joint]], runs, ground)
            # A foot landing far from where the exaggeration put it eases in longer, not faster.
            gap = vector_norm(target - out[:, original[joint]])
            speed = float(vector_norm(np.diff(captured_pos[:, joint], axis=0)).max(initial=0.0))
            lengths = run_ramps(runs, gap, speed, ramp, 0.5 / frame_time)
            if max_speed > 0:  # and long enough that the foot and its toes keep to the speed limit
                moving = [joint, *(riders or {}).get(joint, [])]
                limits = max_speed * vector_norm(np.diff(captured_pos[:, moving], axis=0)).max(axis=0)
                lengths = np.maximum(lengths, ease_lengths(runs, out[:, original[moving]], target - out[:, original[joint]],
                                                           limits, ramp, 0.5 / frame_time))
            weight = contact_weights(runs, frames, lengths)
            g = goal(joint)
            g += weight[:, None] * (target - g)
            pins[joint] = weight
    asked: dict[int, np.ndarray] = {}  # ends a target or a stretch key puts somewhere: the body pass leaves them
    for spec, frame in targets:
        for joint in resolve_effector(spec.joint, skeleton, limbs, effectors, f"target {spec.joint}@{spec.frame}"):
            window = parse_duration(spec.window, frame_time, what=f"target {spec.joint}: window")
            weight = contact_weights(np.array([[frame, frame]]), frames, window)
            point = captured_pos[frame, joint] if spec.position is None else np.asarray(spec.position)
            g = goal(joint)
            g += weight[:, None] * (point - g)
            asked[joint] = np.maximum(asked.get(joint, 0.0), weight)
    for key in keys:
        if key.end not in effectors:
            continue
        weight = contact_weights(np.array([[key.frame, key.frame]]), frames, ramp)
        g = goal(key.end)
        g += weight[:, None] * (out[:, original[key.base]] + key.vectors - g)
        asked[key.end] = np.maximum(asked.get(key.end, 0.0), weight)
    for joint, g in goals.items():
        _move_end(out, hierarchy, effectors[joint], g, rest, pole_of(effectors[joint]))

    def lift_ends() -> None:
        """Lift each end effector (and its toes) off the floor, its chain bending to follow."""
        up = ground.up()
        margin = 0.005 * ground.height
        for joint, effector in effectors.items():
            # A rider is never further from the end than in the capture: only the frames where the end comes
            # within that reach of the floor can have a point under it (elsewhere the lift is 0).
            riders = list(effector.points[1:])
            reach = (vector_norm(captured_pos[:, riders] - captured_pos[:, joint:joint + 1]).max(axis=1) if riders
                     else np.zeros(frames)) * (1.0 + 1e-9) + 1e-9 * ground.height
            # Lifting the end turns it (its incoming link moves), which moves its toes: a few rounds.
            for _ in range(4):
                rows = np.flatnonzero(ground.heights(out[:, original[joint]]) - reach < ground.floor)
                lift = np.zeros(frames)
                if len(rows):
                    points = _effector_points(out, hierarchy, skeleton, effector, captured_pos, captured_rot,
                                              pins.get(joint), rows)
                    lowest = ground.heights(points).min(axis=1)
                    lift[rows] = soft_floor(lowest, ground.floor, margin) - lowest
                if not np.any(lift > 1e-6 * ground.height):
                    break
                lift = _spread_lift(lift, ramp, pins.get(joint))
                _move_end(out, hierarchy, effector, out[:, original[joint]] + lift[:, None] * up, rest,
                          pole_of(effector))

    def lift_body() -> None:
        """Lift every moving point off the floor (the feet held where they are planted)."""
        margin = 0.005 * ground.height
        moving = np.flatnonzero(~hierarchy.rigid[hierarchy.link_child])
        heights = ground.sign * out[:, moving, ground.axis]  # (`Ground.heights`, of the up axis alone)
        # Only the points that come under the floor are lifted (the others' lift is 0, spread or not).
        low = np.flatnonzero(np.any(heights < ground.floor, axis=0))
        below = heights[:, low]
        lift = soft_floor(below, ground.floor, margin) - below
        lifted = np.any(lift != 0.0, axis=0)
        low, below, lift = low[lifted], below[:, lifted], lift[:, lifted]
        held = np.zeros(lift.shape)
        for joint, weight in pins.items():
            held[:, np.isin(hierarchy.link_child[moving[low]], effectors[joint].chain[-1:])] = weight[:, None]
        lift = _spread_lift(lift, ramp, held)
        out[:, moving[low], ground.axis] = ground.sign * (below + lift)

    body: dict[str, dict[str, int]] = {}
    floor = config.enabled and config.floor
    if config.enabled and config.collide:
        # Knees and elbows the captured way, then the limbs out of the body; the floor has the last say, and
        # a hand lifted off it (a scoop) can fold into the body again: out of the body once more, then the floor.
        hinges = {}
        for name in LIMB_HINGES:
            limb = limbs.get(name)
            if limb is None or limb.end not in effectors or tuple(effectors[limb.end].chain) != tuple(limb.joints):
                continue
            pole = pole_of(effectors[limb.end])
            if pole is not None:
                hinges[name] = (pole, behind_line(captured_pos, limb.joints, pole)[0])
        shape = prepare_body(limbs, captured_pos)

        def move(points: np.ndarray, effector: Effector, goal: np.ndarray) -> None:
            _move_end(points, hierarchy, effector, goal, rest, pole_of(effector))

        def chain_of(chain: tuple[int, ...]) -> np.ndarray:
            return sub_chain(hierarchy, chain)

        body["unbent"], body["pushed"] = {}, {}
        # The floor's lifts can put a part back in (a boxer's pelvis exaggerated under the canvas and lifted
        # onto his heel): rounds until none is deeper than the capture's (or BODY_ROUNDS; at least two with a
        # floor, one without).
        for round_ in range(BODY_ROUNDS if floor else 1):
            unbent = unbend_hinges(out, hierarchy, limbs, hinges, chain_of)
            pushed = keep_out(out, hierarchy, limbs, effectors, shape, ramp, pins, move, chain_of,
                              asked=asked) if shape is not None else {}
            for kind, done in (("unbent", unbent), ("pushed", pushed)):
                for name, count in done.items():
                    body[kind][name] = max(body[kind].get(name, 0), count)
            if floor:
                lift_ends()
            unbend_hinges(out, hierarchy, limbs, hinges, chain_of)  # what the floor's lifts bent back
            if floor:
                lift_body()
            if round_ >= 1 and (shape is None or not deeper_than_captured(np.take(out, original, axis=1), shape)):
                break
    elif floor:
        lift_ends()
        lift_body()

    held = []
    for key in keys:
        reached = np.linalg.norm(out[key.frame, original[key.end]] - out[key.frame, original[key.base]])
        promised = np.linalg.norm(key.vectors[key.frame])
        held.append({"limb": key.limb, "frame": key.frame,
                     "ratio": round(float(reached / promised), 6) if promised > 0 else 1.0})
    pin_joints = np.array(sorted(pins), dtype=np.int64)
    pin_weights = np.stack([pins[j] for j in pin_joints], axis=1) if len(pin_joints) else np.zeros((frames, 0))
    return ConstraintResult(out, pin_joints, pin_weights, found, ground, held, body)


def _spread_lift(lift: np.ndarray, ramp: float, pinned: np.ndarray | None) -> np.ndarray:
    """A lift off the floor (F,) or (F, K), spread in time so a point coming down fast slows before it.

    Never less than ``lift`` (the spread's running maximum sees every frame), and
    on planted frames (``pinned`` weight 1) exactly ``lift``, so a pinned foot stays put.
    """
    spread = spread_max(lift, int(round(ramp)))
    if pinned is None:
        return spread
    pinned = pinned if pinned.shape == lift.shape else pinned.reshape(lift.shape)
    return lift + (spread - lift) * (1.0 - pinned)


def _move_end(out: np.ndarray, hierarchy, effector: Effector, goal: np.ndarray, rest: np.ndarray,
              pole: np.ndarray | None) -> None:
    """Deform the effector's chain (in place) so its end reaches ``goal``: the frames where it must move
    (a two-bone chain's knee, eased in time, a little around them too).

    pole : (F, 3) the side a two-bone chain of three original joints bends to (`hinge_pole`), or None
    """
    chain = sub_chain(hierarchy, effector.chain)
    end = out[:, chain[-1]]
    frames = np.flatnonzero(np.any(np.abs(goal - end) > 0, axis=-1))
    if not len(frames):
        return
    run = consecutive(chain, out.shape[1])
    points = out[frames, run] if isinstance(run, slice) else out[frames][:, chain]
    if len(chain) != 3:
        deformed = laplacian_deform(points, goal[frames], rest[chain])
        if isinstance(run, slice):
            out[frames, run] = deformed
        else:
            out[frames[:, None], chain[None, :]] = deformed
        return
    middle = two_bone_ik(points[:, 0], points[:, 1], points[:, 2], goal[frames],
                         None if pole is None else pole[frames])
    # The middle joint's move, eased in time: where the hip rushes past a planted foot the solve
    # turns the knee faster than anything captured turns it.
    move = np.zeros(end.shape)
    move[frames] = middle - points[:, 1]
    out[:, chain[1]] += gaussian_average(move, HINGE_EASE)
    out[frames, chain[2]] = goal[frames]


def _effector_points(out, hierarchy, skeleton, effector: Effector, captured_pos, captured_rot, pin,
                     rows: np.ndarray | slice = slice(None)) -> np.ndarray:
    """Where the effector's joint and riders will be ``(F, P, 3)`` on the frames ``rows`` (each frame's
    numbers its own), turned as orientation recovery will turn it (by the link into it, `incoming_joint`)."""
    joint = effector.joint
    position = out[rows, hierarchy.original[joint]]
    if len(effector.points) == 1:
        return position[:, None]
    above = incoming_joint(skeleton, joint)
    turned = captured_rot[rows, joint]
    rotation = turned
    if above >= 0:
        turn = quat_between(captured_pos[rows, joint] - captured_pos[rows, above],
                            position - out[rows, hierarchy.original[above]])
        rotation = quat_mul(turn, rotation)
    if pin is not None:
        rotation = quat_slerp(rotation, turned, pin[rows])
    riders = list(effector.points[1:])
    local = quat_rotate(quat_inv(turned)[:, None], captured_pos[:, riders][rows] - captured_pos[rows, joint][:, None])
    return np.concatenate([position[:, None], position[:, None] + quat_rotate(rotation[:, None], local)], axis=1)


# ---------------------------------------------------------------------------- the stage


class ConstraintPlan(NamedTuple):
    """The constraints stage's settings: contact detection and the floor, and the targets."""

    contacts: ContactConfig
    targets: tuple[TargetSpec, ...]


def constraints_stage(state: State, plan: ConstraintPlan) -> State:
    """The block: planted feet, targets, the stretches' promised lengths and the floor, on rubber positions.

    Reads ``stretch_keys`` and ``speed_limit``; adds ``sub_positions``, ``pins`` and ``constraints``
    (the manifest's report). Nothing to do without contacts, targets or a stretch stage.
    """
    if not plan.contacts.enabled and not plan.targets and state.stretch_keys is None:
        return state
    motion, first = state.motion, state.first
    skeleton = motion.skeleton
    hierarchy, positions = state.rubber()
    targets = []
    for spec in plan.targets:
        frame = spec.frame_index(motion.frame_time, motion.num_frames)
        if frame < first:
            raise ConfigError(f"target {spec.joint}@{spec.frame}: frame {frame} is a rest-pose frame "
                              f"(motion starts at {first})")
        targets.append((spec, frame - first))
    groups = hierarchy.groups or rubber_groups(skeleton, hierarchy.rigid)
    result = constrain(
        positions[first:], hierarchy, skeleton, state.limbs, state.captured_pos[first:], state.captured_rot[first:],
        motion.frame_time, config=plan.contacts, targets=tuple(targets), keys=state.stretch_keys or (), groups=groups,
        max_speed=state.speed_limit,
        riders=rider_joints(skeleton),
    )
    # The chains bent to meet their targets, with even sub-links again (each keeping its direction): every
    # limb, not only the chains bent. `even_out` is not a fixed point, and this second pass after the springs'
    # own leaves the skin's edges nearer even (evening only the chains bent, inside `constrain`: 3.48 -> 3.59 %
    # of the MakeHuman body's edges past 2x on the looney boxer, bench/skin.py).
    bent = [j for limb in state.limbs.values() for j in limb.joints[1:]]
    out = even_out(result.positions, hierarchy, np.array(bent, dtype=np.int64), in_place=True)  # (constrain's own)
    if first:
        out = np.concatenate([positions[:first], out])
    weights = np.zeros((len(positions), len(result.pin_joints)))
    weights[first:] = result.pin_weights
    contacts = {name: [[int(a) + first, int(b) + first] for a, b in runs] for name, runs in result.contacts.items()}
    report = {"contacts": contacts, "anchor": plan.contacts.anchor if plan.contacts.enabled else None,
              "targets": [{**spec.to_dict(), "frame": frame + first} for spec, frame in targets],
              "stretch_keys": [{**key, "frame": key["frame"] + first} for key in result.keys],
              "body": result.body}
    if result.ground is not None:
        report["floor"] = {"axis": "XYZ"[result.ground.axis], "up": "+" if result.ground.sign > 0 else "-",
                           "height": round(result.ground.sign * result.ground.floor, 6)}
    # A length a stretch promised and did not get is said, not left in the manifest to be found.
    warnings = state.warnings + tuple(
        f"stretch {key['limb']} at frame {key['frame'] + first}: the limb reaches {key['ratio']:.1%} of the length "
        f"asked; " + ("the floor or a planted foot held it back" if key["ratio"] < 1 else "a planted foot pulled it")
        for key in result.keys if abs(key["ratio"] - 1.0) > SHORTFALL)
    return replace(state, sub_positions=out, pins=Pins(result.pin_joints, weights), constraints=report,
                   warnings=warnings)
