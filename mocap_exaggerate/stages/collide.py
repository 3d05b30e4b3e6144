"""Limbs kept out of the body, and knees and elbows bending the captured way (part of the constraints block).

Exaggerating each joint's path on its own can put a hand through the chest, fold a shin into
its thigh or bend a knee backwards; Kwon and Lee name it as a limitation of their method.
Here, after the contacts, targets and stretch keys and before the floor:

- `keep_out`: each hand, forearm, foot and shin is pushed out of the torso, pelvis, head and
  thighs (`mocap_exaggerate.analysis.body`) by as much as it is deeper in than the captured
  one at that frame, the shortest way (the captured part's side near the capsule's axis),
  eased in time so the push never falls short on a frame and grows and fades over `EASE`
  contact ramps (twice that for a planted leg's knee or the body); the limb's end moves and
  its chain bends to follow, as for a contact;
- `unbend_hinges`: a knee or elbow further behind its limb's base-to-end line than the
  captured one (against the side the captured joint bends to, `hinge_pole`) is brought back
  to the line by a C1 clip of the excess, frame by frame, the sub-joints on both its links
  moving with it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from ..analysis.body import CapturedSides, body_capsules, limb_parts, penetrations
from ..analysis.limbs import behind_line
from ..core.kinematics import consecutive
from ..core.rotations import vector_norm
from ..core.timing import end_ramp, gaussian_average, spread_max

__all__ = ["Body", "prepare_body", "keep_out", "deeper_than_captured", "unbend_hinges", "eased_push", "move_middle", "EASE"]

#: A push out of the body grows and fades over this many contact ramps (contacts.blend, 0.15 s): a hand
#: swinging past the hips is in the pelvis for a few frames, and pushed out over so few it shook.
EASE = 2.0


def eased_push(push: np.ndarray, ramp: int) -> np.ndarray:
    """(F, 3) pushes eased in time: the size spread over ``ramp`` frames (`spread_max`: never below a
    frame's own but within ``ramp`` of the clip's ends, where it fades to nothing; growing and fading over
    ``ramp``, zero ``2 ramp`` frames from any push) along the
    pushes' directions smoothed by their own size (a Gaussian reaching past the spread: where it stopped
    short the push dropped from a third of its size to nothing in a frame)."""
    size = vector_norm(push)
    if not np.any(size > 0):
        return push
    radius = max(1, int(ramp))
    # Nothing at the clip's first and last frames, where the exaggeration is nothing either (and kept
    # rest-pose frames meet the motion).
    # (never below a frame's own size, though: a run's part in the chest six frames in stayed there)
    spread = np.maximum(spread_max(size, radius) * end_ramp(len(push), min(max(2.0, radius / 4), len(push) / 4)),
                        size)
    direction = gaussian_average(push, radius / 3.0, ends="nearest", truncate=6.5)
    length = vector_norm(direction, keepdims=True)
    return np.where(length > 0, spread[:, None] * direction / np.maximum(length, 1e-300), 0.0)


class Body(NamedTuple):
    """What the body pass needs of the capture, found once per run (`prepare_body`).

    capsules, parts : the body's capsules and the moving parts (`mocap_exaggerate.analysis.body`)
    captured_depth : part -> (F,) how deep the captured part is (0 outside)
    sides : `CapturedSides`, the way from each capsule's axis to each captured part
    margin : how far past the surface a part is pushed (5 % of the thinnest capsule)
    limbs : the limbs with parts, in a fixed order (each one's push moves the next one's body)
    hips, root : the legs' base joints and where the capture has their middle (F, 3): a body moved
        off a knelt-on shin goes at most back to it, and ``slack`` past it (10 % of the longer captured
        leg, about 5 % of the height; `_back_to`); no move without legs
    """

    capsules: list
    parts: list
    captured_depth: dict[str, np.ndarray]
    sides: CapturedSides
    margin: float
    limbs: tuple[str, ...]
    hips: tuple[int, ...]
    root: np.ndarray
    slack: float


def prepare_body(limbs: dict, captured_pos: np.ndarray) -> Body | None:
    """The capture's side of the body pass; None for a skeleton without both arms or both legs."""
    capsules = body_capsules(limbs, captured_pos)
    if not capsules:
        return None
    parts = limb_parts(limbs)
    depth = {name: np.maximum(found[0], 0.0) for name, found in penetrations(captured_pos, capsules, parts).items()}
    legs = [limbs[name].joints for name in ("left_leg", "right_leg") if name in limbs]
    leg = max((float(vector_norm(np.diff(captured_pos[0, list(joints)], axis=0)).sum()) for joints in legs),
              default=0.0)
    hips = tuple(int(joints[0]) for joints in legs)
    root = captured_pos[:, list(hips)].mean(axis=1) if hips else captured_pos[:, 0]
    return Body(capsules, parts, depth, CapturedSides(captured_pos),
                0.05 * min(capsule.radius for capsule in capsules), tuple(dict.fromkeys(p.limb for p in parts)),
                hips, root, 0.1 * leg)


def keep_out(out: np.ndarray, hierarchy, limbs: dict, effectors: dict, body: Body, ramp: float,
             pins: dict[int, np.ndarray], move_end: Callable[[np.ndarray, object, np.ndarray], None],
             chain_of: Callable[[tuple[int, ...]], np.ndarray], rounds: int = 6,
             asked: dict[int, np.ndarray] | None = None) -> dict[str, int]:
    """Push the limbs out of the body (in place on ``out (F, J', 3)``, the rubber hierarchy's positions).

    ``move_end(out, effector, goal)`` bends an effector's chain so its end reaches ``goal (F, 3)``;
    ``chain_of`` gives the rubber chain of an original one. A planted end (``pins``, joint -> (F,)
    weight) is not moved on its planted frames: its knee (or elbow) moves the part out instead. An end
    the user put somewhere (``asked``: a target, a stretch's length; joint -> (F,) weight) is left there.
    A shin knelt on moves the body off it, at most back to where the capture has the root (`Body`).
    Returns the frames each part was pushed on, by part.
    """
    original = hierarchy.original
    pushed: dict[str, int] = {}
    # A push may swing a limb out, or lengthen it to at most its longest elsewhere in the clip.
    longest = {name: float(vector_norm(out[:, original[limbs[name].end]] - out[:, original[limbs[name].base]]).max())
               for name in body.limbs}
    # and a knee or elbow moved for a held end keeps each of its links to its longest in the clip.
    longest_links = {name: [float(vector_norm(out[:, original[b]] - out[:, original[a]]).max())
                            for a, b in zip(limbs[name].joints, limbs[name].joints[1:])] for name in body.limbs}
    span = int(round(EASE * ramp))
    nothing = np.zeros(len(out))
    for _ in range(rounds):
        found = penetrations(np.take(out, original, axis=1), body.capsules, body.parts, reference=body.sides)
        moved = False
        for limb_name in body.limbs:
            limb = limbs[limb_name]
            if limb.end not in effectors:
                continue
            upper = vector_norm(out[:, original[limb.joints[1]]] - out[:, original[limb.joints[0]]])
            lower = vector_norm(out[:, original[limb.joints[2]]] - out[:, original[limb.joints[1]]])
            toward_root = body.root - out[:, original[list(body.hips)]].mean(axis=1) if body.hips else None
            push = np.zeros((len(out), 3))
            bend = np.zeros((len(out), 3))  # the middle joint's, for a planted end that cannot move
            lift = np.zeros((len(out), 3))  # the body's, for a planted shin in the trunk (sat down onto it)
            for part in (p for p in body.parts if p.limb == limb_name):
                depth, away, along, trunk = found[part.name]
                # Deeper than the capture goes: out to it and a little past (the floor and the evening of
                # sub-links come after); nothing where it is no deeper.
                excess = depth - body.captured_depth[part.name]
                need = np.where((depth > 0) & (excess > 0), excess + body.margin, 0.0)
                if not np.any(need > 0):
                    continue
                pushed[part.name] = pushed.get(part.name, 0) + int(np.sum(need > 0))
                out_of = need[:, None] * away
                if part.a == part.b:
                    # An end folded into its own upper bone: the middle joint follows the end by its share
                    # of the chain, so they part by the rest.
                    share = lower / np.maximum(upper + lower, 1e-12)
                else:
                    # A point along a forearm or shin moves by about its share of the chain's length of the
                    # end's move (the chain bends by shares of it): the end moves that much further. (Moving
                    # the elbow or knee out as well bent it backwards.)
                    share = (upper + along * lower) / np.maximum(upper + lower, 1e-12)
                    # With the end held, the middle joint moves it: by 1 - along of the way.
                    bend = _larger(bend, (need / np.maximum(1.0 - along, 0.5))[:, None] * away)
                push = _larger(push, out_of / np.maximum(share, 0.5)[:, None])
                # Near its held end (a foot, or the shin's lower half in the trunk: sat down onto it) the knee
                # cannot take it out: the body moves off it instead.
                near_end = np.ones(len(out), bool) if part.a == part.b else trunk & (along > 0.5)
                lift = _larger(lift, np.where(near_end[:, None], _off(out_of, toward_root), 0.0))
            if not np.any(push):
                continue
            held = pins.get(limb.end, nothing)
            left_alone = 1.0 - (asked or {}).get(limb.end, nothing)
            # (the eased push spreads in time: weighed again so a target's own frames stay exact)
            free = ((1.0 - held) * left_alone)[:, None]
            move_end(out, effectors[limb.end], _no_longer(out[:, original[limb.joints[0]]], out[:, original[limb.end]],
                                                          eased_push(push * free, span) * free, longest[limb_name]))
            if np.any(bend * held[:, None]):
                base, middle, end = (out[:, original[j]] for j in limb.joints[:3])
                move = eased_push(bend * held[:, None], 2 * span)
                move_middle(out, chain_of(tuple(limb.joints)), original[limb.joints[1]],
                            _links_no_longer(base, middle, end, move, *longest_links[limb_name][:2]))
            if np.any(lift * held[:, None]) and body.hips:
                shift = _back_to(out[:, original[list(body.hips)]].mean(axis=1), body.root,
                                 eased_push(lift * held[:, None], 2 * span), body.slack)
                if np.any(shift):
                    _move_body(out, original, limbs, effectors, pins, shift, move_end)
            moved = True
        if not moved:
            break
    return pushed


def deeper_than_captured(positions: np.ndarray, body: Body) -> bool:
    """Whether any part is inside the body in ``positions (F, J, 3)`` (original joints) at a frame where it
    is deeper than the captured one (the frames `keep_out` would push)."""
    found = penetrations(positions, body.capsules, body.parts, reference=body.sides)
    return any(np.any((depth > 0) & (depth > body.captured_depth[name])) for name, (depth, *_) in found.items())


def _off(out_of: np.ndarray, toward_root: np.ndarray | None) -> np.ndarray:
    """(F, 3) the body's move off a part ``out_of (F, 3)`` of it: back toward where the capture has the root
    (``toward_root``), as far as takes it off by ``|out_of|``, where that way takes it off at all (more than
    half of it); else straight away from the part. (Straight away from a heel sat on, a boxer's pelvis
    could not move without stretching his other, planted leg; up toward the captured crouch it could.)"""
    if toward_root is None:
        return -out_of
    need = vector_norm(out_of)
    unit = np.divide(out_of, need[:, None], out=np.zeros_like(out_of), where=need[:, None] > 0)
    off = -np.einsum("fc,fc->f", toward_root, unit)  # how far the way back takes the body off the part
    scale = np.divide(need, off, out=np.zeros_like(need), where=off > 0)
    return np.where(((off > 0.5 * need) & (need > 0))[:, None], toward_root * np.minimum(scale, 1.0)[:, None],
                    -out_of)


def _larger(now: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """(F, 3) per frame the longer of two pushes."""
    return np.where((vector_norm(wanted) > vector_norm(now))[:, None], wanted, now)


def _no_longer(base: np.ndarray, end: np.ndarray, push: np.ndarray, longest: float) -> np.ndarray:
    """Where a limb's end goes when pushed: ``end + push``, brought back toward ``base`` where the push
    would make the limb longer than ``longest`` (its longest in the clip) or than it is now, whichever
    is more (it swings out of the body; pushed straight out, it stretched an arm past the preset's range)."""
    goal = end + push
    now = np.maximum(vector_norm(end - base, keepdims=True), longest)
    then = vector_norm(goal - base, keepdims=True)
    return np.where(then > now, base + (goal - base) * np.divide(now, then, out=np.ones_like(now), where=then > 0),
                    goal)


#: Rounds of `_links_no_longer`'s alternating projections.
LINK_ROUNDS = 8


def _links_no_longer(base: np.ndarray, middle: np.ndarray, end: np.ndarray, move: np.ndarray, upper: float,
                     lower: float) -> np.ndarray:
    """The ``move (F, 3)`` of a chain's middle joint, shortened so neither link gets longer than it is now
    or than ``upper``/``lower`` (its longest in the clip), whichever is more: the knee swings round
    instead. (Moved straight out of the trunk for a boxer kneeling on the canvas at looney, a knee
    stretched his thigh to 2.96x its length and tore the skin.)"""
    goal = middle + move
    # Each link's ball round its anchor; the middle joint is held in both by alternating projections
    # (they meet, as the joint is in both now; a few rounds take it within a hair of their common part).
    balls = [(anchor, np.maximum(vector_norm(middle - anchor, keepdims=True), longest))
             for anchor, longest in ((base, upper), (end, lower))]
    for _ in range(LINK_ROUNDS):
        for anchor, radius in balls:
            reach = goal - anchor
            then = vector_norm(reach, keepdims=True)
            goal = np.where(then > radius, anchor + reach * np.divide(radius, then, out=np.ones_like(then),
                                                                      where=then > 0), goal)
    return goal - middle


def _back_to(root: np.ndarray, captured_root: np.ndarray, shift: np.ndarray, slack: float) -> np.ndarray:
    """``shift (F, 3)`` of the body, cut to go no further along its own direction than the way back from
    ``root`` to ``captured_root`` (F, 3) and ``slack`` past it: nothing where the root is already that far.
    (Lifted off a knelt-on shin once per round, a looney boxer's hips rose 0.31 heights above the
    crouch the capture had, on thighs stretched 1.9x; held to the capture itself, an elbow folded in
    at his kneel popped 2.25x its largest captured step.)"""
    length = vector_norm(shift)
    way = np.einsum("fc,fc->f", captured_root - root, shift) / np.where(length > 0, length, 1.0) + slack
    scale = np.divide(np.clip(way, 0.0, None), length, out=np.zeros_like(length), where=length > 0)
    return shift * np.minimum(scale, 1.0)[:, None]


def _move_body(out: np.ndarray, original: np.ndarray, limbs: dict, effectors: dict, pins: dict[int, np.ndarray],
               shift: np.ndarray, move_end) -> np.ndarray:
    """Move the whole body by ``shift (F, 3)`` (in place), the planted feet staying by their own legs;
    returns the shift made.

    The body moves only as far as each planted leg reaches without stretching (straight at its
    lengths): lifted off a shin it knelt on, a looney boxer rose a quarter of his height above the
    capture on legs stretched to 1.9x, where the capture was still crouching.
    """
    stay = {}
    for name in ("left_leg", "right_leg"):
        limb = limbs.get(name)
        if limb is not None and limb.end in pins and limb.end in effectors:
            stay[limb.end] = out[:, original[limb.end]].copy()
            hip, knee = out[:, original[limb.joints[0]]], out[:, original[limb.joints[1]]]
            straight = vector_norm(knee - hip) + vector_norm(stay[limb.end] - knee)
            held = pins[limb.end] > 0
            share = _share_within(hip - stay[limb.end], shift, straight)
            shift = shift * np.where(held, share, 1.0)[:, None]
    out += shift[:, None]
    for end, where in stay.items():
        weight = pins[end][:, None]
        move_end(out, effectors[end], out[:, original[end]] + weight * (where - out[:, original[end]]))
    return shift


def _share_within(offset: np.ndarray, shift: np.ndarray, most: np.ndarray) -> np.ndarray:
    """(F,) the largest share ``t`` in [0, 1] of ``shift (F, 3)`` that keeps ``|offset + t shift|`` within
    ``most (F,)`` (or within ``|offset|``, where that is already more)."""
    most = np.maximum(most, vector_norm(offset))
    a = np.einsum("fc,fc->f", shift, shift)
    b = np.einsum("fc,fc->f", offset, shift)
    c = np.einsum("fc,fc->f", offset, offset) - most**2  # <= 0
    root = (-b + np.sqrt(np.maximum(b * b - a * c, 0.0))) / np.where(a > 0, a, 1.0)
    return np.where(a > 0, np.clip(root, 0.0, 1.0), 1.0)


def unbend_hinges(out: np.ndarray, hierarchy, limbs: dict, poles: dict[str, tuple[np.ndarray, np.ndarray]],
                  chain_of: Callable[[tuple[int, ...]], np.ndarray]) -> dict[str, int]:
    """Bring knees and elbows bent the wrong way back to their limb's line (in place on ``out``).

    poles : limb name -> ((F, 3) the side its middle joint bends to (`hinge_pole`, from the capture),
    (F,) how far the captured joint is behind its line (`behind_line`)): a joint is brought back only
    as far as it is further behind than the captured one (the capture's own overextension stays);
    chain_of : the rubber chain (hierarchy indices, base to end) of an original chain. Returns the
    frames each limb was unbent on.
    """
    original = hierarchy.original
    done: dict[str, int] = {}
    for name, (pole, captured) in poles.items():
        limb = limbs[name]
        behind, side = behind_line(out[:, original[list(limb.joints[:3])]], (0, 1, 2), pole)
        excess = behind - np.maximum(captured, 0.0)
        if not np.any(excess > 0):
            continue
        done[name] = int(np.sum(excess > 0))
        # A C1 clip of the excess: 0 up to the line, easing in over 1 % of the limb's reach, then all of
        # it but half that (smooth where the joint crosses the line: easing it in time as the pushes are
        # bent joints already forward further forward, and stretched an arm past the preset's range).
        width = 0.01 * float(vector_norm(out[:, original[limb.end]] - out[:, original[limb.base]]).max())
        amount = np.where(excess < width, np.maximum(excess, 0.0) ** 2 / (2 * width), excess - width / 2)
        frames = np.flatnonzero(amount > 0)  # (only these move: the others would add zeros)
        chain = chain_of(tuple(limb.joints))
        part = out[frames[:, None], chain]
        move_middle(part, np.arange(len(chain)), int(np.flatnonzero(chain == original[limb.joints[1]])[0]),
                    amount[frames, None] * side[frames])
        out[frames[:, None], chain] = part
    return done


def move_middle(out: np.ndarray, chain: np.ndarray, middle: int, move: np.ndarray) -> None:
    """Move a chain's middle joint by ``move (F, 3)`` (in place), its base and end staying: the sub-joints on
    its two links move by their share of the way (along the chain) from the base or the end to it."""
    run = consecutive(chain, out.shape[1])
    points = out[:, run]
    steps = vector_norm(np.diff(points, axis=1))
    at = np.concatenate([np.zeros((len(out), 1)), np.cumsum(steps, axis=1)], axis=1)
    knee = int(np.flatnonzero(chain == middle)[0])
    up = np.divide(at, at[:, knee:knee + 1], out=np.zeros_like(at), where=at[:, knee:knee + 1] > 1e-12)
    down = np.divide(at[:, -1:] - at, at[:, -1:] - at[:, knee:knee + 1], out=np.zeros_like(at),
                     where=(at[:, -1:] - at[:, knee:knee + 1]) > 1e-12)
    weight = np.where(np.arange(len(chain)) <= knee, up, down)
    weight[:, 0] = weight[:, -1] = 0.0
    out[:, run] += weight[..., None] * move[:, None]
