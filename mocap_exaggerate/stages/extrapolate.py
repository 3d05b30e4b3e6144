"""Trajectory extrapolation (Kwon & Lee 2008, section 4.1, eq. 1-3), band-limited.

Each joint's world trajectory ``j_k(t)`` is pushed away from its Gaussian
average ``a_k = j_k * g_sigma``. The paper's eq. (1),
``e_k = omega * j_k + (1 - omega) * a_k = j_k + (omega - 1)(j_k - a_k)``,
multiplies every deviation faster than sigma by omega, capture noise and
marker kinks included: at omega 5 a small step in the capture becomes a
one-frame jump a fifth of the body tall. So the deviation that is amplified
is taken after a short smoothing, a difference of Gaussians:

    e_k = j_k + (omega - 1) * ramp(t) * (j_k * g_smooth - j_k * g_sigma)

The band between ``smooth`` and ``sigma`` (swings, reaches, weight shifts)
is exaggerated; what is faster than ``smooth`` (jitter) passes through as
captured, neither amplified nor removed. ``smooth = 0`` is the paper's
formula. ``ramp`` fades the exaggeration in over one sigma after the first
motion frame (a T-pose or settling frames before it are kept as captured,
and would otherwise end in a jump) and out over one sigma before the last,
where the reflected padding has least to go on. omega = 1 is the identity.

Speed limit: exaggerating a deviation also multiplies its speed, so the
fastest moment of a move (a take-off, a punch) becomes a whip four or five
times faster than anything in the capture, which reads as a pop. With
``max_speed`` = m the added motion ``d = e - j`` of a joint may move at most
``(m - 1)`` times that joint's top captured speed, so the joint never moves
more than m times as fast as it ever did: where ``|d'|`` is over budget
``d`` is scaled down by a gain that is smooth in time (its running minimum
over sigma / 3 either side, spread like the correction's), a few passes. Extremes of a pose, where the
motion is slow, keep their full exaggeration; only the whip is calmed.

Stillness: where a joint stands still in the capture its average still
moves when a move comes near, and an exaggerated hip would float about
while the actor waits. With ``still`` set, a joint's exaggeration is scaled
by how much it moves: none below ``still`` speed (body heights per
second), all from 3x that, spread over sigma either side so a move's
anticipation and settle survive.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..analysis.branches import rider_joints
from ..analysis.limbs import LIMB_NAMES, find_limbs, limb_joints, torso_joints
from ..core.errors import ConfigError, check_flag, check_number
from ..core.rotations import vector_norm
from ..core.settings import Flag, setting
from ..core.skeleton import Skeleton
from ..core.timing import end_ramp, gaussian_average, parse_duration, smootherstep, soft_limit, spread_max, step_gain
from .contacts import find_ground

if TYPE_CHECKING:
    from .state import State

__all__ = ["ExtrapolateConfig", "extrapolate", "extrapolate_stage", "Limited", "SpeedLimitReport", "speed_limit_report",
           "resolve_weights", "welded", "ROOT_NAMES", "WELD"]

#: Widest Gaussian accepted, whatever the clip (a minute; 100,000 frames).
MAX_SIGMA_SECONDS = 60.0
MAX_SIGMA_FRAMES = 100_000


def parse_weight(text: str) -> tuple[str, float]:
    """One ``NAME=W`` pair of ``--weight``: a joint, pattern or limb and a weight from 0 to 10."""
    shown = repr(text) if len(text) <= 80 else repr(text[:80]) + f"... ({len(text)} characters)"
    key, sep, value = text.partition("=")
    if not sep or not key.strip():
        raise ConfigError(f"{shown} is not NAME=WEIGHT (e.g. LeftArm=2, left_leg=0.5, 'Left*'=0)")
    try:
        weight = float(value)
    except ValueError:
        raise ConfigError(f"{shown}: weight {value[:80]!r} is not a number") from None
    if not math.isfinite(weight) or not 0 <= weight <= 10:
        raise ConfigError(f"{shown}: weight must be between 0 and 10")
    return key.strip(), weight


@dataclass(frozen=True, kw_only=True)
class ExtrapolateConfig:
    """Settings of the extrapolation block.

    sigma : width of the Gaussian average: seconds (``0.2``, ``"0.2s"``,
        ``"200ms"``) or frames (``"18f"``). Wider means slower swings count as
        "deviation" and get exaggerated.
    omega : how far past the captured motion to go; 1 is the identity, 5 the
        paper's usual value, values below 1 calm the motion down.
    smooth : the short time scale (same units as sigma) below which motion is
        passed through unamplified: capture jitter and one-frame kinks. 0 is
        the paper's formula, which amplifies them too. At most half of sigma
        is used.
    max_speed : no joint moves faster than this many times its own top
        captured speed (the exaggeration is calmed where it would); 0 for
        no limit.
    still : a joint slower than this (body heights per second) is left as
        captured, so a waiting body does not float; 0 exaggerates always.
    torso : the spine, neck, head, collars and shoulders get this share of
        their own exaggeration on top of the root's (the torso is the body's
        mass and swings less than the limbs, but rides with the hips).
    crouch : the hips sink no lower above the captured floor than this share
        of their captured height at that frame: a crouch exaggerated deeper
        eases into it, the whole body lifted (`crouch_lift`; the contacts then
        plant the feet, the legs unfolding). Only with the contacts and the
        floor on, and times the root's weight (a root weighted 0 stays as
        captured); 0 lets the body sink as the exaggeration puts it (a jump's
        crouch went to a quarter of its height, the legs crumpled under it).
    weights : ``(pattern, weight)`` pairs; a pattern is a joint name, a shell
        pattern (``Left*``) or a limb name (``left_arm``). A joint's effective
        omega is ``1 + weight * (omega - 1)``; weight 0 keeps it as captured.
        Later pairs win.
    """

    enabled: bool = setting(True, flag=Flag("--extrapolate/--no-extrapolate", "Switch trajectory extrapolation on or off."))
    sigma: str | float = setting("0.2s", flag=Flag(
        "--sigma", "Width of the Gaussian average: 0.2s, 200ms or 18f (frames).", metavar="DURATION"))
    omega: float = setting(5.0, flag=Flag("--omega", "Extrapolation factor: 1 = as captured, 5 = the paper's, <1 calms."))
    smooth: str | float = "0.05s"
    max_speed: float = 2.0
    still: float = 0.05
    torso: float = 1.0
    crouch: float = 0.5
    weights: tuple[tuple[str, float], ...] = setting((), flag=Flag(
        "--weight", "Per-joint exaggeration weight; NAME is a joint, a pattern (Left*) or a limb (left_arm, "
        "right_leg, spine, neck). Repeatable; 0 keeps it as captured.",
        metavar="NAME=W", parse=parse_weight, multiple=True), table=True)

    def __post_init__(self) -> None:
        check_flag("extrapolate.enabled", self.enabled)
        seconds = parse_duration(self.sigma, 1.0, what="extrapolate.sigma")
        frames = parse_duration(self.sigma, np.inf, what="extrapolate.sigma")  # nonzero only for "18f"
        if seconds > MAX_SIGMA_SECONDS if frames == 0 else frames > MAX_SIGMA_FRAMES:
            raise ConfigError(f"extrapolate.sigma must be at most {MAX_SIGMA_SECONDS:g} s or {MAX_SIGMA_FRAMES} "
                              f"frames, got {self.sigma!r}")
        check_number("extrapolate.omega", self.omega, 0, 50)
        check_number("extrapolate.still", self.still, 0, 10)
        check_number("extrapolate.torso", self.torso, 0, 10)
        check_number("extrapolate.crouch", self.crouch, 0, 1)
        if self.max_speed != 0:  # (0: no limit, said in the message too)
            try:
                check_number("extrapolate.max_speed", self.max_speed, 1, 100)
            except ConfigError:
                raise ConfigError(f"extrapolate.max_speed must be 0 (no limit) or a number in [1, 100], "
                                  f"got {self.max_speed!r}") from None
        if parse_duration(self.smooth, 1.0, what="extrapolate.smooth") > MAX_SIGMA_SECONDS:
            raise ConfigError(f"extrapolate.smooth must be at most {MAX_SIGMA_SECONDS:g} s, got {self.smooth!r}")
        for pattern, weight in self.weights:
            check_number(f"extrapolate.weights[{pattern!r}]", weight, 0, 10)

    def sigma_frames(self, frame_time: float, frames: int | None = None) -> float:
        """Sigma in frames; with ``frames`` (the clip's length) also checked against it.

        A Gaussian much wider than the clip averages nothing more, only costs
        time and memory: sigma may be at most twice the clip (or 1000 frames).
        """
        sigma = parse_duration(self.sigma, frame_time, what="extrapolate.sigma")
        if frames is not None and sigma > max(2 * frames, 1000):
            # (Said with the frame rate: a preset's sigma in seconds at an --fps far from the clip's own,
            # 10,000 for a 120 fps take, is what usually makes it so wide.)
            most = max(2 * frames, 1000)
            raise ConfigError(
                f"extrapolate.sigma {self.sigma!r} is {sigma:,.4g} frames at {1.0 / frame_time:g} fps; a clip of "
                f"{frames:,} frames takes at most {most:,} (the larger of twice its length and 1,000): "
                "a smaller sigma, or the clip's own frame rate"
            )
        return sigma

    def smooth_frames(self, frame_time: float) -> float:
        """The smoothing scale in frames: at most half of sigma (a band needs room between the two)."""
        smooth = parse_duration(self.smooth, frame_time, what="extrapolate.smooth")
        return min(smooth, 0.5 * parse_duration(self.sigma, frame_time, what="extrapolate.sigma"))


def extrapolate(
    world_pos: np.ndarray,
    *,
    sigma: float,
    omega: float,
    weights: np.ndarray | None = None,
    smooth: float = 0.0,
    ramp: float = 0.0,
    max_speed: float = 0.0,
    still: float = 0.0,
    torso: tuple[np.ndarray, float] | None = None,
    riders: dict[int, list[int]] | None = None,
    axis: int = 0,
    return_limited: bool = False,
) -> np.ndarray | tuple[np.ndarray, Limited]:
    """Exaggerate trajectories away from their Gaussian average.

    Parameters
    ----------
    world_pos : (F, J, 3) float64 world positions, time along ``axis``
    sigma : Gaussian standard deviation in frames
    omega : extrapolation factor; 1 returns the input unchanged
    weights : (J,) float64 or None; per-joint scale of ``omega - 1``
    smooth : standard deviation in frames of the short smoothing; 0 amplifies every deviation
    ramp : frames over which the exaggeration fades in at the first frame and out at the last
        (a C2 smootherstep); 0 for none
    max_speed : the most a joint may move per frame, as a multiple of its own largest captured
        move; 0 for no limit
    still : a joint moving less than this per frame (after the short smoothing) keeps its
        captured position, fully exaggerated from 3x that; 0 for always
    torso : ``(joints, share)``: these joints take the root's exaggeration and only ``share``
        of their own on top of it (a torso that swings less but still rides with the hips)
    riders : joint -> joints that ride rigidly on it (a foot's toes): the joint's speed limit
        is the slowest of its own and theirs, since whatever it does they do too
    return_limited : also return what the speed limit left of the exaggeration (`Limited`)

    Returns
    -------
    (F, J, 3) float64 ``j + w (omega - 1) r(t) (j * g_smooth - j * g_sigma)``: eq. (1) with a
    per-joint omega when ``smooth`` and ``ramp`` are 0. With ``return_limited``, and `Limited`.

    Examples
    --------
    >>> t = np.linspace(0, 2 * np.pi, 101)[:, None, None]
    >>> out = extrapolate(np.sin(t) * np.ones((1, 1, 3)), sigma=3.0, omega=1.0, smooth=1.0)
    >>> bool(np.allclose(out, np.sin(t)))
    True
    """
    world_pos = np.asarray(world_pos, dtype=np.float64)
    if world_pos.ndim != 3 or world_pos.shape[-1] != 3:
        raise ValueError(f"positions must be (F, J, 3), got {world_pos.shape}")
    moved = np.moveaxis(world_pos, axis, 0)
    gain = np.full(moved.shape[1], omega - 1.0)
    if weights is not None:
        weights = np.asarray(weights, dtype=np.float64)
        if weights.shape != gain.shape:
            raise ValueError(f"weights must be ({moved.shape[1]},), got {weights.shape}")
        gain = gain * weights
    if not np.any(gain):
        none = np.zeros(moved.shape[:2])
        return (world_pos.copy(), Limited(none, none)) if return_limited else world_pos.copy()
    smoothed = gaussian_average(moved, smooth)
    deviation = smoothed - gaussian_average(moved, sigma)
    if torso is not None and len(torso[0]):
        joints, share = torso  # ride with the root, swing a share of their own
        deviation[:, joints] = deviation[:, :1] + share * (deviation[:, joints] - deviation[:, :1])
    deviation *= gain[:, None]
    if still > 0 and len(moved) > 1:
        speed = vector_norm(np.gradient(smoothed, axis=0))  # (F, J) per frame
        moving = smootherstep((speed - still) / (2.0 * still))
        deviation *= spread_max(moving, max(int(round(sigma)), 1))[..., None]
    if ramp > 0:
        deviation *= end_ramp(len(moved), ramp)[:, None, None]
    asked = vector_norm(deviation) if return_limited else None
    if max_speed > 0 and len(moved) > 2:
        top = vector_norm(np.diff(moved, axis=0)).max(axis=0)
        for joint, below in (riders or {}).items():
            moving = top[below][top[below] > 0]
            if len(moving):
                top[joint] = min(top[joint], moving.min())
        budget = (max_speed - 1.0) * top
        deviation = _limit_speed(deviation, budget, max(int(round(sigma / 3.0)), 2))
    out = np.moveaxis(moved + deviation, 0, axis)
    if return_limited:
        return out, Limited(asked, vector_norm(deviation))
    return out


class Limited(NamedTuple):
    """What the speed limit left of the exaggeration: each joint's displacement from its
    captured path per frame ``(F, J)``, as asked (omega, weights, stillness, ramp) and as kept."""

    asked: np.ndarray
    kept: np.ndarray

    def taken(self) -> np.ndarray:
        """``(J,)`` the share of each joint's exaggeration the limit took, over the clip (0 to 1)."""
        asked = self.asked.sum(axis=0)
        return np.where(asked > 1e-12, 1.0 - self.kept.sum(axis=0) / np.maximum(asked, 1e-300), 0.0)


#: Passes of the speed limit; each leaves less over budget (the gain's own change adds a little speed).
_SPEED_PASSES = 4


def _limit_speed(deviation: np.ndarray, budget: np.ndarray, radius: int) -> np.ndarray:
    """``deviation`` (F, J, 3) scaled by per-joint gains smooth in time so its one-frame moves stay within ``budget`` (J,).

    The gain a frame needs, ``budget / |step|`` where a step is over it,
    is spread over ``radius`` frames either side (a running minimum, then a
    Gaussian truncated there, so never above what any frame needs) and the
    deviation scaled by it; repeated, since scaling by a changing gain adds
    a step of its own. A joint still over budget after the passes has its
    whole deviation scaled down, so the budget always holds.
    """
    out = deviation
    for _ in range(_SPEED_PASSES):
        step = vector_norm(np.diff(out, axis=0))  # (F-1, J)
        over = step > budget * (1.0 - 1e-9)
        if not over.any():
            return out
        share = np.where(over, budget / np.maximum(step, 1e-300), 1.0) * 0.98
        out = out * step_gain(share, radius)[..., None]
    # Still over after the passes (a gain changing fast where the deviation is large: a sigma of
    # a few frames): scale those joints' whole deviation down, which scales every step alike.
    step = vector_norm(np.diff(out, axis=0)).max(axis=0)
    scale = np.where(step > budget, budget / np.maximum(step, 1e-300), 1.0)
    return out * scale[:, None]


# ---------------------------------------------------------------------------- the stage


def extrapolate_stage(state: State, config: ExtrapolateConfig) -> State:
    """The block: every joint's path pushed away from its Gaussian average, after the rest frames.

    Adds ``positions`` and ``speed_limit`` (``max_speed``, which the later stages keep to).
    """
    first = state.first
    skeleton = state.motion.skeleton
    weights = resolve_weights(skeleton, config.weights, state.limbs)
    positions = state.positions.copy()
    frame_time = state.motion.frame_time
    sigma = config.sigma_frames(frame_time, len(state.positions) - first)
    notes = state.notes
    asked = parse_duration(config.smooth, frame_time, what="extrapolate.smooth")
    if asked > 0.5 * sigma:
        notes += (f"extrapolate.smooth {config.smooth!r} is more than half of sigma {config.sigma!r}; used "
                  f"{0.5 * sigma * frame_time:.3g} s (the band between them is what gets exaggerated)",)
    positions[first:], limited = extrapolate(
        state.positions[first:], sigma=sigma, omega=config.omega, weights=weights,
        smooth=config.smooth_frames(frame_time), ramp=sigma, max_speed=config.max_speed,
        still=config.still * skeleton.height() * frame_time,
        torso=(torso_joints(skeleton, state.limbs), config.torso) if config.torso != 1 else None,
        riders=rider_joints(skeleton), return_limited=True,
    )
    # The crouch floor, after the speed limit: added before it, the limit's per-joint gains bent the lift and
    # stretched the legs (a squashed support leg asked for went to 0.75 where 0.5 was asked). It adds at most
    # the hips' own drop speed; on the looney boxer one step reaches 1.757x its captured top against 1.75.
    lift = crouch_floor(state.captured_pos[first:], skeleton, state.limbs, config.crouch, weights)
    if lift is not None:
        positions[first:] += lift(positions[first:])[:, None]
    report = speed_limit_report(limited, skeleton, config.max_speed, frame_time, first, sigma)
    if report is not None and report.joints:
        notes += (report.note(),)
    warnings = state.warnings
    if sigma < 1.0 and config.omega != 1.0:  # (a new user's --sigma 0 ran, said 1.00x and nothing else)
        warnings += (f"extrapolate.sigma {config.sigma!r} is {sigma:.3g} frames: an average over less than a frame "
                     "is the motion itself, so next to nothing is exaggerated (the presets take 0.15-0.3s)",)
    return replace(state, positions=positions, notes=notes, warnings=warnings, speed_limit=config.max_speed,
                   speed_report=report)


#: Where the crouch floor starts to act, as a share of the room between the captured height and the floor.
_CROUCH_KNEE = 0.4


def crouch_lift(captured: np.ndarray, height: np.ndarray, crouch: float) -> np.ndarray:
    """(F,) how far to lift the body so its hips, ``height`` (F,) above the floor, sink no lower than
    ``crouch`` times their ``captured`` (F,) height at that frame.

    A drop below the captured height is kept up to a knee, two fifths of the way to that floor, and
    eases into the floor past it (`soft_limit`, continuous with its first derivative), never reaching
    it; frames at or above the knee are not lifted. (At ``crouch`` 0 the floor is the ground itself.)

    >>> np.round(crouch_lift(np.array([1.0, 1.0, 1.0]), np.array([1.2, 0.9, 0.1]), 0.5), 3).tolist()
    [0.0, 0.0, 0.406]
    """
    drop = captured - height
    room = (1.0 - crouch) * np.maximum(captured, 0.0)
    return np.maximum(drop - soft_limit(drop, _CROUCH_KNEE * room, room), 0.0)


def crouch_floor(captured_pos: np.ndarray, skeleton: Skeleton, limbs: dict, crouch: float,
                 weights: np.ndarray | None = None) -> Callable[[np.ndarray], np.ndarray] | None:
    """The crouch floor: ``positions (F, J, 3) -> (F, 3)``, the body's move up so
    its hips (the middle of the legs' base joints) sink no lower above the captured floor than ``crouch``
    times their captured height (`crouch_lift`), times the root's weight (at most 1: a root kept as
    captured, ``--weight root=0``, is not lifted). None where there is nothing to do (``crouch`` 0, no legs,
    a root weighted 0). Not spread in time: the lift is a smooth function of the hips' drop, as smooth as
    the motion (spread over the contacts' ramps, a kneeling boxer's lift carried on as he got up)."""
    hips = [limbs[name].joints[0] for name in ("left_leg", "right_leg") if name in limbs]
    share = 1.0 if weights is None else float(np.clip(weights[0], 0.0, 1.0))
    if crouch <= 0 or not hips or share == 0 or not len(captured_pos):
        return None
    ground = find_ground(skeleton, captured_pos, limbs)
    captured = ground.heights(captured_pos[:, hips].mean(axis=1)) - ground.floor

    def lift(positions: np.ndarray) -> np.ndarray:
        height = ground.heights(positions[:, hips].mean(axis=1)) - ground.floor
        return share * crouch_lift(captured, height, crouch)[:, None] * ground.up()

    return lift


#: The speed limit is said (with -v, and in the manifest's warnings) when it takes more than this
#: share of a joint's exaggeration.
SPEED_TAKEN_SAID = 0.25


@dataclass(frozen=True)
class SpeedLimitReport:
    """How much of the exaggeration the speed limit took (the manifest's ``result.speed_limit``).

    max_speed : ``extrapolate.max_speed``
    taken : the share of the whole body's exaggeration taken (0 to 1)
    joints : ``(name, share)`` of the joints it took more than `SPEED_TAKEN_SAID` from, most first
    seconds : where it took the most from the first of them: the span (seconds from the clip's
        start) around its peak where more than that share of its exaggeration is taken, frame by frame
    """

    max_speed: float
    taken: float
    joints: tuple[tuple[str, float], ...]
    seconds: tuple[float, float] | None

    def note(self) -> str:
        name, share = self.joints[0]
        more = f" and {len(self.joints) - 1} more joint(s)" if len(self.joints) > 1 else ""
        when = f", most from {self.seconds[0]:.2f} to {self.seconds[1]:.2f} s" if self.seconds else ""
        return (f"the speed limit (extrapolate.max_speed {self.max_speed:g}) took {share:.0%} of {name}'s "
                f"exaggeration{more}{when}, {self.taken:.0%} of the body's: more omega moves it little more; "
                f"--set extrapolate.max_speed=3 (or 0, no limit) lets it whip faster")

    def to_dict(self) -> dict:
        return {"max_speed": self.max_speed, "taken": round(self.taken, 4),
                "joints": {name: round(share, 4) for name, share in self.joints},
                "seconds": [round(s, 4) for s in self.seconds] if self.seconds else None}


def speed_limit_report(limited: Limited, skeleton: Skeleton, max_speed: float, frame_time: float, first: int,
                       sigma: float) -> SpeedLimitReport | None:
    """What the limit took (`SpeedLimitReport`), None without a limit or an exaggeration."""
    asked = limited.asked.sum()
    if max_speed <= 0 or asked <= 1e-12:
        return None
    taken = limited.taken()
    order = [j for j in np.argsort(-taken, kind="stable") if taken[j] > SPEED_TAKEN_SAID]
    seconds = None
    if order:
        worst = order[0]
        window = max(int(round(sigma)), 1)  # frame by frame, over a sigma: where the whip was calmed
        asked_near = gaussian_average(limited.asked[:, worst], window / 3.0)
        kept_near = gaussian_average(limited.kept[:, worst], window / 3.0)
        share = np.where(asked_near > 1e-12, 1.0 - kept_near / np.maximum(asked_near, 1e-300), 0.0)
        peak = int(np.argmax(share))
        if share[peak] > SPEED_TAKEN_SAID:  # the run of frames over the share around its peak
            below = np.flatnonzero(share <= SPEED_TAKEN_SAID)
            start = below[below < peak].max(initial=-1) + 1
            end = below[below > peak].min(initial=len(share))
            seconds = (float((first + start) * frame_time), float((first + end) * frame_time))
    return SpeedLimitReport(float(max_speed), float(1.0 - limited.kept.sum() / asked),
                            tuple((skeleton.names[j], float(taken[j])) for j in order), seconds)


def resolve_weights(skeleton: Skeleton, weights: tuple[tuple[str, float], ...], limbs: dict | None = None) -> np.ndarray:
    """Per-joint weights ``(J,)`` from ``(pattern, weight)`` pairs; later pairs win.

    A pattern is a limb name (its joints and everything below its end), an
    exact joint name, ``root`` or ``pelvis`` (the root, on any rig, unless a joint
    has that name), or a shell pattern over joint names.

    Joints welded together (a link shorter than `WELD` of the body's height:
    Reallusion's CC_Base_Pelvis on CC_Base_Hip, CMU's LHipJoint on Hips) take
    one weight: the last given to any of them. Two welded joints exaggerated
    apart would open a link of no length into one of centimetres, a stretch
    of thousands of times that no correction can undo. For the same reason the
    joints riding rigidly on another (`rider_joints`: fingers on a hand, toes on
    a foot) take the weight of the joint they ride on.
    """
    out = np.ones(skeleton.num_joints)
    weld = welded(skeleton)
    for pattern, weight in weights:
        if pattern in ROOT_NAMES and pattern not in skeleton.names:
            joints = np.array([0])
        elif pattern in LIMB_NAMES or (limbs and pattern in limbs):
            limbs = find_limbs(skeleton) if limbs is None else limbs
            if pattern not in limbs:
                raise ConfigError(f"weight {pattern}={weight:g}: no {pattern} found on this skeleton")
            joints = limb_joints(skeleton, limbs[pattern])
        elif pattern in skeleton.names:
            joints = np.array([skeleton.index(pattern)])
        else:
            joints = skeleton.match(pattern)
            if not len(joints):
                sample = ", ".join(skeleton.names[:6])
                raise ConfigError(
                    f"weight {pattern}={weight:g}: no joint or limb matches {pattern!r} "
                    f"(joints: {sample}, ...; limbs: {', '.join(LIMB_NAMES)}; root)"
                )
        out[np.isin(weld, weld[joints])] = weight
    for anchor, below in rider_joints(skeleton).items():
        out[below] = out[anchor]
    return out


#: Names a weight can give the root by on every rig.
ROOT_NAMES = ("root", "pelvis")

#: Links shorter than this share of the body's height weld their joints together (`welded`).
WELD = 0.01


def welded(skeleton: Skeleton) -> np.ndarray:
    """``(J,)`` for each joint, the highest joint it is welded to by links shorter than `WELD` x height."""
    short = skeleton.link_lengths() < WELD * skeleton.height()
    weld = np.arange(skeleton.num_joints)
    for j in range(1, skeleton.num_joints):  # parents come first: one pass (joints, not frames)
        if short[j]:
            weld[j] = weld[skeleton.parents[j]]
    return weld
