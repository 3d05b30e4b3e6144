"""Squash and stretch along motion paths (Ibrahim 2018, the Stretch-Engine, section 4.3).

For a limb (base joint to end effector), a frame range and a scale S, the end
effector's path over the range is scaled about its origin O (the first point,
or the last with ``pivot = "end"``): ``O + S (P - O)`` on the chosen axes. The
thesis then looks for the point P2 on the line from the path's final point P1
to its scaled image P3 at which the limb is exactly S times as long as at P1
(a line-sphere intersection here; the thesis uses the law of sines), which
gives the effective scale S'. The original and S'-scaled paths are blended
with the time ratio from the origin (the thesis: the arc-length ratio, which
is the same at even speed; see `exaggerated_path`), passed through an ease
curve, and the limb follows the new path: the chain turns toward the new end and
stretches along its own axis, the hand or foot riding along.

Beyond the thesis: a ``release`` after the range (before it, with the pivot
at the end) lets the limb ease back instead of snapping to its captured
length on the next frame, leaving its peak at the speed it arrived with.
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..analysis.limbs import limb_length
from ..analysis.strikes import CANDIDATE_REACH, Candidate, strike_candidates
from ..core.errors import ConfigError, check_number
from ..core.kinematics import link_vectors
from ..core.rotations import quat_between, quat_rotate, vector_norm
from ..core.settings import Flag, setting
from ..core.timing import parse_duration, parse_frame
from .state import StretchKey

if TYPE_CHECKING:
    from .contacts import ContactConfig
    from .state import State

__all__ = [
    "StretchSpec",
    "StretchEvent",
    "StretchResult",
    "StretchPlan",
    "stretch_stage",
    "specs_for_paths",
    "parse_stretch",
    "ease_curve",
    "release_curve",
    "solve_effective_scale",
    "exaggerated_path",
    "apply_stretches",
    "MAX_SCALE",
    "AutoStretchConfig",
    "find_strikes",
    "weigh_strikes",
    "strike_scale",
    "captured_scale",
    "overlapping",
]

#: How long a stretched limb takes to come back after its range, unless the spec says.
DEFAULT_RELEASE = "0.2s"
#: The thesis's range of scale: 0 (fully squashed) to 5 (the extreme, a character pulled by a rocket).
MAX_SCALE = 5.0
_AXES = "xyz"


@dataclass(frozen=True, kw_only=True)
class StretchSpec:
    """One squash-and-stretch event.

    limb : limb name (``left_arm``, ``right_leg``, ``spine``, ``neck`` or one
        declared in ``[limbs]``)
    start, end : frame range, inclusive: frame numbers, or durations such as
        ``"1.2s"`` (converted with the clip's frame time)
    scale : S in [0, 5]: the limb's length at the final frame becomes S times
        its length there
    axes : which of x, y, z the path is scaled on
    pivot : ``start`` scales away from the first frame (the limb is longest
        at the last); ``end`` scales from the last frame (longest at the first)
    blend : share of the change applied, 0 (none) to 1
    ease_in : (percent, value), percent in [0, 1], value in [0, 0.5], or None
    ease_out : (percent, value), percent in [0, 1], value in [0.5, 1], or None
    release : how long the limb takes to return to its captured length after
        the range (before it with ``pivot = "end"``), leaving the peak at the
        speed it reached it; 0 snaps back as in the thesis
    """

    limb: str
    start: int | str
    end: int | str
    scale: float
    axes: str = "xyz"
    pivot: str = "start"
    blend: float = 1.0
    ease_in: tuple[float, float] | None = None
    ease_out: tuple[float, float] | None = None
    release: str | float = DEFAULT_RELEASE

    def __post_init__(self) -> None:
        where = f"stretch {self.limb}"
        check_number(f"{where}: scale", self.scale, 0, MAX_SCALE)
        check_number(f"{where}: blend", self.blend, 0, 1)
        axes = str(self.axes).lower()
        if not axes or any(a not in _AXES for a in axes) or len(set(axes)) != len(axes):
            raise ConfigError(f"{where}: axes must be some of x, y, z, got {self.axes!r}")
        object.__setattr__(self, "axes", "".join(a for a in _AXES if a in axes))
        if self.pivot not in ("start", "end"):
            raise ConfigError(f"{where}: pivot must be start or end, got {self.pivot!r}")
        for name, (low, high) in (("ease_in", (0.0, 0.5)), ("ease_out", (0.5, 1.0))):
            value = getattr(self, name)
            if value is None:
                continue
            if not isinstance(value, (tuple, list)) or len(value) != 2:
                raise ConfigError(f"{where}: {name} must be percent,value, got {value!r}")
            check_number(f"{where}: {name} percent", value[0], 0, 1)
            check_number(f"{where}: {name} value", value[1], low, high)
            object.__setattr__(self, name, (float(value[0]), float(value[1])))
        if self.ease_in and self.ease_out and self.ease_in[0] >= 1 - self.ease_out[0]:
            raise ConfigError(
                f"{where}: ease_in percent {self.ease_in[0]:g} must come before the ease_out point "
                f"(1 - {self.ease_out[0]:g}); lower one of them"
            )
        parse_duration(self.release, 1.0, what=f"{where}: release")

    def frames(self, frame_time: float, num_frames: int) -> tuple[int, int]:
        """The inclusive frame range, validated against the clip."""
        first = parse_frame(self.start, frame_time, what=f"stretch {self.limb}: start")
        last = parse_frame(self.end, frame_time, what=f"stretch {self.limb}: end")
        if not 0 <= first < last < num_frames:
            raise ConfigError(
                f"stretch {self.limb}: frames {first}-{last} must lie within 0-{num_frames - 1} with start < end"
            )
        return first, last

    def span(self, frame_time: float, num_frames: int) -> tuple[int, int]:
        """Frames the event touches, release included (inclusive)."""
        first, last = self.frames(frame_time, num_frames)
        release = int(round(parse_duration(self.release, frame_time, what=f"stretch {self.limb}: release")))
        lo = first - release if self.pivot == "end" else first
        hi = last + release if self.pivot == "start" else last
        return max(lo, 0), min(hi, num_frames - 1)

    def shifted(self, frames: int) -> StretchSpec:
        """The same event ``frames`` later (frame-number ranges only)."""
        return replace(self, start=int(self.start) + frames, end=int(self.end) + frames)

    def to_dict(self) -> dict:
        out = {"limb": self.limb, "start": self.start, "end": self.end, "scale": float(self.scale),
               "axes": self.axes, "pivot": self.pivot, "blend": float(self.blend), "release": self.release}
        if self.ease_in:
            out["ease_in"] = list(self.ease_in)
        if self.ease_out:
            out["ease_out"] = list(self.ease_out)
        return out


def overlapping(span: tuple[int, int], others) -> bool:
    """Whether the inclusive frame range ``span`` shares a frame with any ``(first, last)`` in ``others``."""
    first, last = span
    return any(first <= b and a <= last for a, b in others)


# (The scale is any word here: -2, 1e9 or nan is then told what a scale must be, as 6 is.)
_SPEC = re.compile(r"^\s*([A-Za-z_][\w.-]*)\s*:\s*([^:]+?)\s*-\s*([^:]+?)\s*:\s*([^:]+?)\s*((?::[^:]+)*)$")


def parse_stretch(text: str) -> StretchSpec:
    """A spec from the command line: ``LIMB:START-END:SCALE[:key=value...]``.

    >>> parse_stretch("left_arm:120-160:3:axes=xz:ease_in=0.6,0.2").axes
    'xz'
    """
    match = _SPEC.match(text)
    if not match:
        raise ConfigError(f"stretch spec {text!r}: expected LIMB:START-END:SCALE[:key=value...], e.g. left_arm:120-160:3")
    limb, start, end, scale, rest = match.groups()
    options: dict = {}
    for item in filter(None, rest.split(":")):
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep:
            raise ConfigError(f"stretch spec {text!r}: {item!r} is not key=value")
        if key in ("ease_in", "ease_out"):
            parts = value.split(",")
            if len(parts) != 2:
                raise ConfigError(f"stretch spec {text!r}: {key} takes percent,value (e.g. {key}=0.6,0.2)")
            options[key] = tuple(_number(p, text, key) for p in parts)
        elif key in ("blend",):
            options[key] = _number(value, text, key)
        elif key in ("axes", "pivot", "release"):
            options[key] = value.strip()
        else:
            raise ConfigError(f"stretch spec {text!r}: unknown key {key!r} (axes, pivot, blend, ease_in, ease_out, release)")
    return StretchSpec(limb=limb, start=start, end=end, scale=_number(scale, text, "scale"), **options)


def _number(text: str, spec: str, key: str) -> float:
    text = text.strip()
    try:
        return float(text[:-1]) / 100.0 if text.endswith("%") else float(text)
    except ValueError:
        raise ConfigError(f"stretch spec {spec!r}: {key} {text!r} is not a number") from None


def ease_curve(ease_in: tuple[float, float] | None = None, ease_out: tuple[float, float] | None = None):
    """The remap curve r -> eased r on [0, 1]: monotone, through (0, 0) and (1, 1).

    The ease-in point sits at ``(percent, value)``, the ease-out point at
    ``(1 - percent, value)`` (its percent counts from the end); a monotone
    cubic (PCHIP) runs through the points. Without ease points it is the
    identity (the thesis's linear scale).
    """
    xs, ys = [0.0], [0.0]
    if ease_in:
        xs.append(ease_in[0])
        ys.append(ease_in[1])
    if ease_out:
        xs.append(1.0 - ease_out[0])
        ys.append(ease_out[1])
    xs.append(1.0)
    ys.append(1.0)
    keep = np.concatenate([[True], np.diff(xs) > 1e-9])
    xs, ys = np.array(xs)[keep], np.array(ys)[keep]
    if len(xs) == 2:
        return lambda r: np.clip(np.asarray(r, dtype=np.float64), 0.0, 1.0)
    from scipy.interpolate import PchipInterpolator

    spline = PchipInterpolator(xs, ys)
    return lambda r: np.clip(spline(np.clip(np.asarray(r, dtype=np.float64), 0.0, 1.0)), 0.0, 1.0)


def solve_effective_scale(base: np.ndarray, origin: np.ndarray, final: np.ndarray, scale: float, mask: np.ndarray):
    """The effective scale S' and the new final point P2.

    base : (3,) base joint P0 at the final frame; origin : (3,) path origin O;
    final : (3,) the path's final point P1; mask : (3,) bool, scaled axes.

    P2 = P1 + t (P3 - P1) with P3 the fully scaled final point, and t the
    intersection of that line with the sphere ``|P2 - P0| = S |P1 - P0|``
    nearest t = 0 (for S > 1 with a scaled-up path this is the thesis's P2,
    on or past P3). Then ``S' = 1 + t (S - 1)`` on the masked axes ends the
    scaled path exactly at P2. A squash (S < 1) on axes along which the end
    cannot come that close to the base has no intersection: the closest
    point is taken and ``exact`` is False.

    Returns (S', P2, exact).
    """
    length = np.linalg.norm(final - base)
    direction = np.where(mask, (scale - 1.0) * (final - origin), 0.0)  # P3 - P1
    if scale == 1.0 or length == 0.0:
        return 1.0, final.copy(), scale == 1.0
    a = float(direction @ direction)
    offset = final - base
    if a < 1e-24:
        return 1.0, final.copy(), False
    b = 2.0 * float(offset @ direction)
    c = float(offset @ offset) - (scale * length) ** 2
    disc = b * b - 4 * a * c
    if disc >= 0:
        # Of the two intersections take the nearer one: the smallest change to the path.
        root = np.sqrt(disc)
        t = min((-b - root) / (2 * a), (-b + root) / (2 * a), key=abs)
        return 1.0 + t * (scale - 1.0), final + t * direction, True
    t = -b / (2 * a)  # the line never comes that close to the base: take its closest point
    return 1.0 + t * (scale - 1.0), final + t * direction, False


def exaggerated_path(path: np.ndarray, base_at_final: np.ndarray, spec: StretchSpec):
    """The new end-effector path over the range, ``(n, 3)``, in frame order.

    path : (n, 3) end-effector positions over the range, in frame order
    base_at_final : (3,) base joint at the final frame (the last, or the first with pivot end)
    Returns (new_path, effective_scale, exact); ``exact`` False means the
    axes had to be relaxed (the end reaches S times the length along the limb).
    """
    ordered = path[::-1] if spec.pivot == "end" else path
    origin, final = ordered[0], ordered[-1]
    mask = np.array([a in spec.axes for a in _AXES])
    effective, end_point, exact = solve_effective_scale(base_at_final, origin, final, spec.scale, mask)
    scaled = np.where(mask, origin + effective * (ordered - origin), ordered)
    # The thesis blends by the arc-length ratio from the origin. By time instead: the same on a path
    # travelled at even speed, but where the end stops dead (a kick meeting the ball) an arc-length
    # weight stops with it, and the stretch's acceleration there was 4x the captured kick's.
    ratio = np.linspace(0.0, 1.0, len(ordered)) if len(ordered) > 1 else np.ones(1)
    if not exact and spec.scale != 1.0:
        # The chosen axes cannot bring the end to S times the length (a squash across
        # the motion): keep the limb length promise by ending on the limb's own axis,
        # P0 + S (P1 - P0), and spread the difference along the path.
        goal = base_at_final + spec.scale * (final - base_at_final)
        scaled = scaled + ratio[:, None] * (goal - scaled[-1])
    weight = spec.blend * ease_curve(spec.ease_in, spec.ease_out)(ratio)
    new = (1.0 - weight)[:, None] * ordered + weight[:, None] * scaled
    return (new[::-1] if spec.pivot == "end" else new), effective, exact


@dataclass(frozen=True)
class StretchEvent:
    """One stretch as applied.

    limb : the limb stretched; frames : its inclusive (first, last) frame range
    scale, axes, pivot : as declared (or as found, for a strike)
    effective_scale : the scale S' the path was blended toward (the thesis's section 4.3)
    axes_relaxed : the path could not squash on the axes asked and was squashed along the limb
    reach : for a strike found, the reach it ends at in limb lengths (its style); None for declared ones
    captured : for a declared stretch, the S asked: the limb's length at the key frame over its captured
        length there (``scale`` is the factor that took on the exaggerated limb); None for found ones
    moved_body : the limb's end was planted somewhere in the event: the body moved instead of it
    """

    limb: str
    frames: tuple[int, int]
    scale: float
    axes: str
    pivot: str
    effective_scale: float
    axes_relaxed: bool
    reach: float | None = None
    captured: float | None = None
    moved_body: bool = False

    def to_dict(self) -> dict:
        """The event as the manifest lists it."""
        out = {"limb": self.limb, "frames": list(self.frames), "scale": self.scale, "axes": self.axes,
               "pivot": self.pivot, "effective_scale": self.effective_scale, "axes_relaxed": self.axes_relaxed}
        if self.reach is not None:
            out["reach"] = self.reach
        if self.captured is not None:
            out["captured"] = self.captured
        if self.moved_body:
            out["moved_body"] = True
        return out


@dataclass
class StretchResult:
    """What the stretch pass did.

    positions : (F, J, 3) float64 world positions after all stretches
    stretch_factors : (F, J) float64, each link's length over its length before
        the pass (1 where untouched): the glTF writer turns it into thickness
    events : one `StretchEvent` per stretch
    trails : per event, frames and the original and new end-effector paths
    """

    positions: np.ndarray
    stretch_factors: np.ndarray
    events: list[StretchEvent] = field(default_factory=list)
    trails: list[dict] = field(default_factory=list)


def release_curve(shift: np.ndarray, frames: int) -> np.ndarray:
    """The displacement ``(frames, 3)`` after a stretch whose displacement over its range was ``shift (n, 3)``.

    A cubic Hermite from the last displacement and its velocity (one frame's
    change) to rest at 0 on the frame after the release: the limb leaves its
    peak at the speed it reached it and settles without a snap (a smoothstep
    from a standing start stopped it dead on the peak frame, a pop of four
    times the captured acceleration on a kicking foot).

    >>> release_curve(np.array([[0.0, 0, 0], [1.0, 0, 0]]), 3)[:, 0].round(3).tolist()
    [0.984, 0.625, 0.203]
    """
    last = shift[-1]
    velocity = shift[-1] - shift[-2] if len(shift) > 1 else np.zeros(3)
    span = frames + 1.0
    # A range that ends mid-swing would carry on well past its peak: at most one peak's worth over the
    # release (an overshoot of at most 15 %). A strike ends at its greatest reach, nearly at rest.
    size = np.linalg.norm(velocity) * span
    velocity = velocity * min(1.0, np.linalg.norm(last) / size) if size > 0 else velocity
    s = np.arange(1, frames + 1, dtype=np.float64)[:, None] / span
    h00 = 2.0 * s**3 - 3.0 * s**2 + 1.0
    h10 = s**3 - 2.0 * s**2 + s
    return h00 * last + h10 * span * velocity


def apply_stretches(
    world_pos: np.ndarray,
    skeleton,
    limbs: dict,
    specs: tuple[StretchSpec, ...],
    frame_time: float,
    *,
    paths: dict | None = None,
    planted: dict[str, tuple] | None = None,
) -> StretchResult:
    """Apply every stretch spec to ``world_pos (F, J, 3)``; returns a StretchResult.

    ``limbs`` maps limb names to `Limb`s (``find_limbs``). ``paths`` maps a
    limb name to ``(frames, positions)`` edited by hand (a trails file): that
    path replaces the computed one for the event on that limb covering those frames.
    ``planted`` maps a limb name to ``(weights (F,), stand (F, 3) or None)``:
    weights 1 where its end is planted (eased in and out), ``stand`` where it
    stands then (None: where it is). There the end stays and the base moves along
    the line from it to the length asked, the body with it (a stretched support
    leg lifts the hips, a squashed one lowers them).
    """
    world_pos = np.array(world_pos, dtype=np.float64)
    frames_total = world_pos.shape[0]
    before = world_pos.copy()
    taken: dict[str, list[tuple[int, int, StretchSpec]]] = {}
    plans = []
    for spec in specs:
        if spec.limb not in limbs:
            known = ", ".join(limbs) or "none found"
            raise ConfigError(f"stretch {spec.limb}: no such limb on this skeleton (limbs: {known})")
        first, last = spec.frames(frame_time, frames_total)
        lo, hi = spec.span(frame_time, frames_total)
        for other_lo, other_hi, other in taken.get(spec.limb, []):
            if overlapping((lo, hi), [(other_lo, other_hi)]):
                raise ConfigError(
                    f"stretch {spec.limb}: frames {first}-{last} overlap {other.start}-{other.end} "
                    f"on the same limb (release included); split or merge them"
                )
        taken.setdefault(spec.limb, []).append((lo, hi, spec))
        plans.append((spec, first, last, lo, hi))

    events, trails = [], []
    for spec, first, last, lo, hi in plans:
        limb = limbs[spec.limb]
        base, end = limb.base, limb.end
        path = world_pos[first : last + 1, end]
        final_frame = first if spec.pivot == "end" else last
        new_path, effective, exact = exaggerated_path(path, world_pos[final_frame, base], spec)
        edited = (paths or {}).get(spec.limb)
        if edited is not None:
            edit_frames, edit_pos = edited
            index = np.asarray(edit_frames) - first
            inside = (index >= 0) & (index < len(new_path))
            new_path[index[inside]] = np.asarray(edit_pos, dtype=np.float64)[inside]
        target = world_pos[:, end].copy()
        target[first : last + 1] = new_path
        # Release: the displacement leaves the range with the speed it had and comes to rest at 0.
        shift = new_path - world_pos[first : last + 1, end]
        if spec.pivot == "start" and hi > last:
            target[last + 1 : hi + 1] += release_curve(shift, hi - last)
        if spec.pivot == "end" and lo < first:
            target[lo:first] += release_curve(shift[::-1], first - lo)[::-1]
        span = slice(lo, hi + 1)
        held = (planted or {}).get(spec.limb)
        moved_body = held is not None and bool(np.any(held[0][span] > 0))
        if moved_body:
            # Planted: the end stands where the contacts will put it and the base moves along the line
            # from it to the length asked, the body with it (the least move that keeps both).
            weight = held[0][span][:, None]
            stand = held[1][span] if held[1] is not None else world_pos[span, end]
            length = vector_norm(target[span] - world_pos[span, base], keepdims=True)
            away = world_pos[span, base] - stand
            away /= np.maximum(vector_norm(away, keepdims=True), 1e-12)
            shift = weight * (stand + length * away - world_pos[span, base])
            world_pos[span, _body_of(skeleton, base)] += shift[:, None]
            target[span] = (1.0 - weight) * target[span] + weight * stand
        _follow(world_pos, skeleton, limb, target, span)
        events.append(StretchEvent(limb=spec.limb, frames=(first, last), scale=float(spec.scale), axes=spec.axes,
                                   pivot=spec.pivot, effective_scale=round(float(effective), 6), axes_relaxed=not exact,
                                   moved_body=moved_body))
        trails.append({
            "limb": spec.limb, "joint": skeleton.names[end], "frames": list(range(lo, hi + 1)),
            "original": before[span, end].round(6).tolist(), "exaggerated": world_pos[span, end].round(6).tolist(),
        })

    lengths_before = vector_norm(link_vectors(before, skeleton.parents))
    lengths_after = vector_norm(link_vectors(world_pos, skeleton.parents))
    factors = np.ones((frames_total, skeleton.num_joints))
    factors[:, 1:] = np.divide(lengths_after, lengths_before, out=np.ones_like(lengths_after),
                               where=lengths_before > 1e-12)
    return StretchResult(world_pos, factors, events, trails)


def _body_of(skeleton, base: int) -> np.ndarray:
    """The joints that move with the body when a limb's end stays put: all but those below ``base``."""
    below = set(skeleton.descendants(base)[1:])
    return np.array([j for j in range(skeleton.num_joints) if j not in below], dtype=np.int64)


def _follow(world_pos: np.ndarray, skeleton, limb, target: np.ndarray, span: slice) -> None:
    """Turn and stretch the limb chain (in place) so its end reaches ``target`` over ``span``.

    The chain turns about its base by the smallest rotation from the old
    base-to-end direction to the new one, and stretches along that axis only
    (an elbow's sideways offset is kept). Everything else below the base (the
    hand and fingers, the arms off a stretched spine, twist bones) rides
    rigidly with its nearest chain joint.
    """
    chain = list(limb.joints)
    base, end = chain[0], chain[-1]
    pos = world_pos[span]
    origin = pos[:, base]
    old = pos[:, end] - origin
    new = target[span] - origin
    old_len = vector_norm(old)
    new_len = vector_norm(new)
    turn = quat_between(old, new)
    stretch = np.divide(new_len, old_len, out=np.ones_like(old_len), where=old_len > 1e-12)
    axis = np.divide(old, old_len[:, None], out=np.zeros_like(old), where=old_len[:, None] > 1e-12)
    offset = pos[:, chain] - origin[:, None]
    along = np.sum(offset * axis[:, None], axis=-1, keepdims=True)
    offset = offset + (stretch[:, None, None] - 1.0) * along * axis[:, None]
    new_chain = origin[:, None] + quat_rotate(turn[:, None], offset)
    riders = [int(j) for j in skeleton.descendants(base)[1:] if j not in chain]
    if riders:
        in_chain = {j: k for k, j in enumerate(chain)}
        anchor = []
        for j in riders:
            up = int(skeleton.parents[j])
            while up not in in_chain:
                up = int(skeleton.parents[up])
            anchor.append(in_chain[up])
        anchor = np.array(anchor)
        rel = pos[:, riders] - pos[:, np.array(chain)[anchor]]
        pos[:, riders] = new_chain[:, anchor] + quat_rotate(turn[:, None], rel)
    pos[:, chain] = new_chain
    world_pos[span] = pos


@dataclass(frozen=True, kw_only=True)
class AutoStretchConfig:
    """Automatic stretch events: strikes found in the motion get the style's scale.

    A strike is a punch, kick, thrust, throw or reach, found by its shape, whatever its speed
    (`mocap_exaggerate.analysis.strikes`): an arm or leg whose reach (base to end over the
    limb's full length) peaks at ``min_reach`` or more, having unfolded by ``min_rise`` within
    ``window`` seconds, pointing ``min_angle`` degrees or more away from the torso's down line
    (not hanging or pushed down at the side), and, for a leg, not a step: its foot neither on
    the ground at full reach nor landing within 0.15 s of it. The event runs from where the
    extension gets going to the frame of greatest reach; back-to-back strikes (a one-two)
    shorten the first one's release.

    arm, leg, spine, neck : the style's range of scale per limb: the limb's length at the
        strike's end, in limb lengths (2: the arm reaches twice its length, whatever the
        exaggeration had already made of it; the thesis: limbs about 2, torso at most the
        limbs, 5 the extreme)
    """

    enabled: bool = setting(False, flag=Flag(
        "--auto-stretch/--no-auto-stretch",
        "Find strikes (punches, kicks, thrusts, throws, reaches) and stretch them by the style's scale."))
    arm: float = 2.0
    leg: float = 2.0
    spine: float = 1.5
    neck: float = 1.5
    min_reach: float = 0.92
    min_rise: float = 0.2
    min_angle: float = 50.0
    min_leg_angle: float = 40.0
    window: float = 0.6
    axes: str = "xyz"
    ease_in: tuple[float, float] | None = (0.5, 0.25)

    def __post_init__(self) -> None:
        if not isinstance(self.enabled, bool):
            raise ConfigError(f"auto_stretch.enabled must be true or false, got {self.enabled!r}")
        for name in ("arm", "leg", "spine", "neck"):
            check_number(f"auto_stretch.{name}", getattr(self, name), 0, MAX_SCALE)
        if self.spine > max(self.arm, self.leg) or self.neck > max(self.arm, self.leg):
            raise ConfigError(
                "auto_stretch: the torso (spine, neck) should stretch no more than the limbs (arm, leg), "
                f"got spine {self.spine:g}, neck {self.neck:g}, arm {self.arm:g}, leg {self.leg:g}"
            )
        check_number("auto_stretch.min_reach", self.min_reach, 0, 1)
        check_number("auto_stretch.min_rise", self.min_rise, 0, 1)
        check_number("auto_stretch.min_angle", self.min_angle, 0, 180)
        check_number("auto_stretch.min_leg_angle", self.min_leg_angle, 0, 180)
        check_number("auto_stretch.window", self.window, 0.05, 5)
        if isinstance(self.ease_in, list):
            object.__setattr__(self, "ease_in", tuple(self.ease_in))
        StretchSpec(limb="check", start=0, end=1, scale=self.arm, axes=self.axes, ease_in=self.ease_in)


def weigh_strikes(world_pos: np.ndarray, skeleton, limbs: dict, frame_time: float,
                  config: AutoStretchConfig) -> list[Candidate]:
    """Every reach peak of the arms and legs in ``world_pos (F, J, 3)`` weighed as a strike (`strike_candidates`),
    the legs' steps found as the contacts stage finds them."""
    from .contacts import limb_contacts

    steps = limb_contacts(skeleton, world_pos, frame_time, limbs) if len(world_pos) >= 8 else {}
    return strike_candidates(world_pos, skeleton, limbs, frame_time, min_reach=config.min_reach,
                             min_rise=config.min_rise, min_angle=config.min_angle,
                             min_leg_angle=config.min_leg_angle, window=config.window, steps=steps)


def find_strikes(world_pos: np.ndarray, skeleton, limbs: dict, frame_time: float, config: AutoStretchConfig,
                 candidates: list[Candidate] | None = None) -> list[StretchSpec]:
    """Stretch events for the strikes in ``world_pos (F, J, 3)`` (frame numbers relative to it).

    candidates : `weigh_strikes`'s, when already weighed. The scale of each event is the
    style's (``config.arm`` or ``config.leg``): the limb's reach at the strike's end in limb
    lengths; `strike_scale` turns it into a factor on whatever reach the motion being
    stretched has there. Of strikes of one limb that overlap, the one reaching furthest.
    """
    if candidates is None:
        candidates = weigh_strikes(world_pos, skeleton, limbs, frame_time, config)
    release = int(round(parse_duration(DEFAULT_RELEASE, frame_time)))
    specs = []
    for name in limbs:
        taken = sorted((c for c in candidates if c.limb == name and c.taken), key=lambda c: (-c.reach, c.arrive))
        chosen: list[tuple[int, int]] = []
        for strike in taken:
            if not overlapping((strike.start - 1, strike.arrive + 1), chosen):
                chosen.append((strike.start, strike.arrive))
        chosen.sort()
        scale = config.arm if name.endswith("_arm") else config.leg
        for k, (start, end) in enumerate(chosen):
            gap = chosen[k + 1][0] - end - 1 if k + 1 < len(chosen) else release
            specs.append(StretchSpec(limb=name, start=start, end=end, scale=scale, axes=config.axes,
                                     ease_in=config.ease_in, release=f"{max(0, min(release, gap))}f"))
    return specs


def nothing_found(candidates: list[Candidate], frame_time: float, first: int = 0) -> str:
    """The note for a clip with no strike found: the strongest candidate and why it was not taken."""
    if not candidates:
        return (f"auto-stretch: no strike found: no arm or leg comes within {CANDIDATE_REACH:g} of its full reach "
                "at a peak")
    strongest = max(candidates, key=lambda c: c.strength())
    return (f"auto-stretch: no strike found; the strongest candidate, {strongest.describe(frame_time, first)}, "
            f"was not taken: {strongest.why}")


def captured_scale(spec: StretchSpec, captured: np.ndarray, world_pos: np.ndarray, skeleton, limbs: dict,
                   frame_time: float) -> StretchSpec:
    """A declared stretch with its S (times the captured limb at the key frame) turned into a factor on ``world_pos``.

    The extrapolation and the correction have already changed the limb: S on top of them made an arm
    2.73x its captured length for S = 2.5. The factor that gives S times the captured length is
    ``S * captured / exaggerated`` at the key frame (the last, or the first with pivot end), at most
    `MAX_SCALE`. A spec naming no limb of the skeleton is left for `apply_stretches` to refuse.
    """
    limb = limbs.get(spec.limb)
    if limb is None:
        return spec
    first, last = spec.frames(frame_time, world_pos.shape[0])
    key = first if spec.pivot == "end" else last
    was = float(np.linalg.norm(captured[key, limb.end] - captured[key, limb.base]))
    now = float(np.linalg.norm(world_pos[key, limb.end] - world_pos[key, limb.base]))
    if was <= 0 or now <= 0:
        return spec
    return replace(spec, scale=float(min(MAX_SCALE, spec.scale * was / now)))


def strike_scale(spec: StretchSpec, world_pos: np.ndarray, skeleton, limbs: dict, frame_time: float) -> StretchSpec:
    """A found strike with its scale turned from "reach in limb lengths" into a factor on ``world_pos``.

    The exaggeration has already lengthened the limb at the strike's end: a
    2x style on an arm the extrapolation made 1.6x long would reach 3.2x.
    The factor that makes it reach ``spec.scale`` limb lengths instead is
    ``scale * full / reach``, and never below 1 (a strike does not squash).
    """
    limb = limbs[spec.limb]
    full = limb_length(skeleton, limb)
    first, last = spec.frames(frame_time, world_pos.shape[0])
    key = first if spec.pivot == "end" else last
    reach = float(np.linalg.norm(world_pos[key, limb.end] - world_pos[key, limb.base]))
    if reach <= 0 or full <= 0:
        return spec
    return replace(spec, scale=float(min(MAX_SCALE, max(1.0, spec.scale * full / reach))))


# ---------------------------------------------------------------------------- the stage


class StretchPlan(NamedTuple):
    """The stretch stage's settings: the declared events, the automatic finder's, and the contacts
    (a planted foot stays where it stands: the body moves instead)."""

    specs: tuple[StretchSpec, ...]
    auto: AutoStretchConfig
    contacts: ContactConfig | None = None


def stretch_stage(state: State, plan: StretchPlan) -> State:
    """The block: the declared stretches, the strikes found and the hand-edited paths, applied.

    Adds ``positions``, ``stretch`` (events, trails, stretch factors) and ``stretch_keys``
    (the length each event promised at its final frame). Nothing to do without any of the three.
    """
    motion, first = state.motion, state.first
    if not plan.specs and not state.paths and not plan.auto.enabled:
        return state
    # S means the captured limb: the factor on the exaggerated limb that makes it S times its captured length.
    declared = [captured_scale(spec, state.captured_pos, state.positions, motion.skeleton, state.limbs,
                               motion.frame_time) for spec in plan.specs]
    asked = {(spec.limb, spec.frames(motion.frame_time, motion.num_frames)): spec.scale for spec in plan.specs
             if spec.limb in state.limbs}  # (a limb the skeleton lacks is refused by apply_stretches)
    specs = declared + list(specs_for_paths(state.paths or {}, plan.specs))
    if not specs and not plan.auto.enabled:  # (edited paths too short to be an event)
        return state
    notes = list(state.notes)
    reaches: dict[tuple[str, int, int], float] = {}
    if plan.auto.enabled:
        # Strikes are found in the captured motion, not in its exaggeration.
        captured = state.captured_pos[first:]
        weighed = weigh_strikes(captured, motion.skeleton, state.limbs, motion.frame_time, plan.auto)
        found = find_strikes(captured, motion.skeleton, state.limbs, motion.frame_time, plan.auto, weighed)
        styled = [spec.shifted(first) for spec in found]
        found = [strike_scale(spec, state.positions, motion.skeleton, state.limbs, motion.frame_time)
                 for spec in styled]
        notes += [f"auto-stretch: {s.limb} frames {s.start}-{s.end} to {style.scale:g} limb lengths (x{s.scale:.3g})"
                  for s, style in zip(found, styled)]
        if not found:
            notes.append(nothing_found(weighed, motion.frame_time, first))
        reaches = {(s.limb, int(s.start), int(s.end)): style.scale for s, style in zip(found, styled)}
        span = functools.partial(StretchSpec.span, frame_time=motion.frame_time, num_frames=motion.num_frames)
        for spec in found:  # the user's own events win over found ones
            if not overlapping(span(spec), [span(other) for other in specs if other.limb == spec.limb]):
                specs.append(spec)
    result = apply_stretches(state.positions, motion.skeleton, state.limbs, tuple(specs), motion.frame_time,
                             paths=state.paths, planted=_planted(state, plan.contacts, [s.limb for s in specs]))
    positions = result.positions
    positions[:first] = state.positions[:first]
    events, keys = [], []
    for event in result.events:
        reach = reaches.get((event.limb, *event.frames))
        if reach is not None:  # a found strike: its style is the reach it ends at, in limb lengths
            event = replace(event, reach=reach)
        if (event.limb, event.frames) in asked:  # a declared one: S as asked, against the captured limb
            event = replace(event, captured=float(asked[event.limb, event.frames]))
        events.append(event)
        if event.axes_relaxed:
            notes.append(
                f"stretch {event.limb} frames {event.frames[0]}-{event.frames[1]}: the path cannot "
                f"squash to x{event.scale:g} on axes {event.axes}; squashed along the limb instead"
            )
        limb = state.limbs[event.limb]
        frame = event.frames[1] if event.pivot == "start" else event.frames[0]
        if frame >= first:
            vectors = positions[first:, limb.end] - positions[first:, limb.base]
            keys.append(StretchKey(event.limb, limb.base, limb.end, frame - first, vectors))
    return replace(state, positions=positions, stretch=replace(result, events=events), stretch_keys=tuple(keys),
                   notes=tuple(notes))


def _planted(state: State, contacts: ContactConfig | None, names: list[str]) -> dict[str, tuple]:
    """Per stretched limb whose end the contacts stage will plant: ``(F,)`` weights, eased as it eases
    them, and where it will stand (the capture with ``anchor = "captured"``; None: where it is)."""
    from .contacts import contact_weights, limb_contacts

    if contacts is None or not contacts.enabled or not names:
        return {}
    motion, first = state.motion, state.first
    wanted = {name: limb for name, limb in state.limbs.items() if name in names}
    runs = limb_contacts(motion.skeleton, state.captured_pos[first:], motion.frame_time, state.limbs, contacts)
    ramp = parse_duration(contacts.blend, motion.frame_time, what="contacts.blend")
    out = {}
    for name, limb in wanted.items():
        if name in runs and len(runs[name]):
            weights = np.zeros(motion.num_frames)
            weights[first:] = contact_weights(runs[name], motion.num_frames - first, ramp)
            out[name] = (weights, state.captured_pos[:, limb.end] if contacts.anchor == "captured" else None)
    return out


def specs_for_paths(paths: dict, specs: tuple[StretchSpec, ...]) -> tuple[StretchSpec, ...]:
    """Events (scale 1, no release) for edited paths on limbs no declared stretch covers."""
    extra = []
    for limb, (edit_frames, _) in paths.items():
        if not any(s.limb == limb for s in specs) and len(edit_frames) >= 2:
            extra.append(StretchSpec(limb=limb, start=int(min(edit_frames)), end=int(max(edit_frames)), scale=1.0,
                                     release=0))
    return tuple(extra)
