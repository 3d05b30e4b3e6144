"""Suspended mass-spring follow-through (Kwon & Lee 2008, section 5.3).

Each sub-joint has an infinite-mass *follower* particle that moves with the
exaggerated motion, and a unit-mass *suspended* particle tied to it by a
zero-length spring (``stiffness``). Suspended particles of linked sub-joints
are tied by springs whose rest length is the sub-link's current length
(``link_stiffness``), and a drag (``damping``) acts on each suspended
particle's velocity relative to its follower, so a body gliding at constant
speed trails nothing while a limb that stops dead overshoots and settles.
The output is ``(1 - blend) * follower + blend * suspended``.

The integrator is the one loop over time in the project. The follower spring
and the drag are integrated implicitly (backward Euler, closed form per
particle), so any stiffness and damping are stable; the link springs are
explicit, with substeps chosen from their stiffness and the frame time so
that ``h * omega_max <= 1``. The loop is compiled with Numba.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..analysis.limbs import limb_hinges, limb_joints
from ..core.errors import ConfigError, check_flag, check_number
from ..core.kinematics import frame_blocks
from ..core.native import frame_halves, on_both_cores
from ..core.native import kernels as _kernels  # the compiled loops, where built (core/native.py)
from ..core.rotations import vector_norm
from ..core.settings import Flag, setting
from ..core.timing import smootherstep, soft_limit
from .bends import keep_bends_on_rubber
from .subjoints import even_out

if TYPE_CHECKING:
    from .state import State

__all__ = ["SpringConfig", "SpringLinks", "simulate_springs", "spring_links", "spring_substeps", "stable_link_stiffness",
           "substeps_for", "limit_stretch", "STIFFNESS_RANGE", "DAMPING_RANGE", "springs_stage", "hanging_links"]

STIFFNESS_RANGE = (0.0, 1e5)
DAMPING_RANGE = (0.0, 1e4)
#: Substeps never exceed this, whatever the parameters; the implicit parts stay stable anyway.
MAX_SUBSTEPS = 256


@dataclass(frozen=True, kw_only=True)
class SpringConfig:
    """Settings of the follow-through block.

    stiffness : zero-length spring to the follower, per unit mass (1/s^2);
        ``(2 pi f)^2`` makes the body wobble at f Hz (158 for 2 Hz)
    link_stiffness : springs between linked suspended particles (1/s^2),
        keeping the suspended body's sub-links near their current lengths
    damping : drag on velocity relative to the follower (1/s); the damping
        ratio is ``damping / (2 sqrt(stiffness))``
    blend : share of the suspended particles in the output; 0 is the identity
    max_stretch : the lag stretches no sub-link past this factor of its rest
        length, or past its length before the springs where a stretch or the
        correction already made it longer (`limit_stretch`)
    min_length : nor squashes one below this share of its rest length, or
        below its length before the springs where that is shorter (0: no
        floor; a hand lagging behind a fast elbow had squashed a looney
        upper arm from 0.55 to 0.26 of its length)
    """

    enabled: bool = setting(True, flag=Flag("--springs/--no-springs", "Switch the follow-through on or off."))
    stiffness: float = setting(150.0, flag=Flag(
        "--stiffness", "Follow-through spring to the motion, 1/s^2: (2 pi f)^2 wobbles at f Hz (158 = 2 Hz)."))
    link_stiffness: float = setting(150.0, flag=Flag(
        "--link-stiffness", "Springs between neighbouring sub-joints, 1/s^2."))
    damping: float = setting(8.0, flag=Flag("--damping", "Drag on the follow-through, 1/s; higher settles sooner."))
    blend: float = setting(0.5, flag=Flag(
        "--blend", "Share of the simulated follow-through in the result, 0 (none) to 1."))
    max_stretch: float = setting(2.0, flag=Flag(
        "--spring-max-stretch", "The follow-through stretches a sub-link at most to this factor of its rest "
        "length (or its length before the springs, if longer).", metavar="FACTOR"))
    min_length: float = 0.5

    def __post_init__(self) -> None:
        check_flag("springs.enabled", self.enabled)
        check_number("springs.stiffness", self.stiffness, *STIFFNESS_RANGE)
        check_number("springs.link_stiffness", self.link_stiffness, *STIFFNESS_RANGE)
        check_number("springs.damping", self.damping, *DAMPING_RANGE)
        check_number("springs.blend", self.blend, 0, 1)
        check_number("springs.max_stretch", self.max_stretch, 1, 10)
        check_number("springs.min_length", self.min_length, 0, 1)
        if self.stiffness == 0 and self.damping == 0 and self.blend > 0:
            raise ConfigError("springs: stiffness and damping are both 0, so nothing holds the body; raise one")


def substeps_for(frame_time: float, stiffness: float, link_stiffness: float, max_degree: int) -> int:
    """Substeps per frame that keep the explicit link springs stable and the rest accurate.

    The largest link-spring frequency is bounded by ``sqrt(2 * degree * k_link)``
    (Gershgorin on the graph Laplacian); the follower spring is implicit, but
    substeps also keep its phase error small where that is affordable.
    """
    omega = max(math.sqrt(2.0 * max(max_degree, 1) * link_stiffness), math.sqrt(stiffness))
    return int(min(MAX_SUBSTEPS, max(1, math.ceil(frame_time * omega))))


def stable_link_stiffness(frame_time: float, link_stiffness: float, max_degree: int, substeps: int) -> float:
    """The link stiffness the explicit link springs can carry at this step: ``link_stiffness`` or less.

    Stability needs ``h sqrt(2 degree k_link) <= 1`` with ``h = frame_time /
    substeps``. When even `MAX_SUBSTEPS` cannot give that (very stiff links on
    a slow clip: 10^5 at 1 fps), the links are softened to the stiffest stable
    value rather than left to blow up; the pipeline says so in its notes.
    """
    h = frame_time / substeps
    return min(link_stiffness, 1.0 / (2.0 * max(max_degree, 1) * h * h))


def _integrate(follow, link_a, link_b, frame_time, substeps, stiffness, link_stiffness, damping):  # pragma: no cover
    """The time loop, particle by particle in plain Python: the oracle for the NumPy version."""
    frames, count, _ = follow.shape
    links = link_a.shape[0]
    out = np.empty_like(follow)
    x = follow[0].copy()
    v = np.zeros((count, 3))
    if frames > 1:
        for i in range(count):
            for a in range(3):
                v[i, a] = (follow[1, i, a] - follow[0, i, a]) / frame_time
    out[0] = x
    h = frame_time / substeps
    denominator = 1.0 + h * damping + h * h * stiffness
    force = np.zeros((count, 3))
    anchor = np.empty((count, 3))
    for f in range(frames - 1):
        for s in range(substeps):
            alpha = (s + 1.0) / substeps
            for i in range(count):
                for a in range(3):
                    anchor[i, a] = follow[f, i, a] + alpha * (follow[f + 1, i, a] - follow[f, i, a])
                    force[i, a] = 0.0
            for e in range(links):
                p = link_a[e]
                c = link_b[e]
                rest = 0.0
                length = 0.0
                for a in range(3):
                    d_rest = anchor[c, a] - anchor[p, a]
                    rest += d_rest * d_rest
                    d = x[c, a] - x[p, a]
                    length += d * d
                rest = math.sqrt(rest)
                length = math.sqrt(length)
                if length > 0.0:
                    scale = link_stiffness * (length - rest) / length
                    for a in range(3):
                        pull = scale * (x[c, a] - x[p, a])
                        force[p, a] += pull
                        force[c, a] -= pull
            for i in range(count):
                for a in range(3):
                    velocity = (follow[f + 1, i, a] - follow[f, i, a]) / frame_time
                    v[i, a] = (
                        v[i, a] + h * (stiffness * (anchor[i, a] - x[i, a]) + damping * velocity + force[i, a])
                    ) / denominator
                    x[i, a] += h * v[i, a]
        out[f + 1] = x
    return out


def _integrate_vectorised(follow, link_a, link_b, frame_time, substeps, stiffness, link_stiffness, damping):
    """The same time loop as `_integrate`, each step one set of NumPy operations over all particles.

    Everything that does not depend on the simulated state (the anchors, the
    follower spring's pull toward them, the drag's share, the link springs'
    rest lengths) is computed for a block of frames and all their substeps
    at once; the loop over steps, the only one in Python, is left with the
    link springs and the update. Each particle's link pulls are summed by
    ``np.bincount``, in the links' order from zero, as ``core/_kernels.c``'s
    loop sums them, so the two give the same bits (with little drag the
    follow-through is chaotic: sums in another order, a BLAS product's, part
    from these by centimetres within seconds).
    """
    frames, count, _ = follow.shape
    out = np.empty_like(follow)
    out[0] = follow[0]
    if frames < 2:
        return out
    x = follow[0].copy()
    v = (follow[1] - follow[0]) / frame_time
    h = frame_time / substeps
    denominator = 1.0 + h * damping + h * h * stiffness
    links = len(link_a)
    strength = h * link_stiffness / denominator
    pull = h * stiffness / denominator
    shrink = 1.0 / denominator
    alpha = ((np.arange(substeps) + 1.0) / substeps)[None, :, None, None]
    block = max(1, 1024 // substeps)
    for begin in range(0, frames - 1, block):
        stop = min(frames - 1, begin + block)
        step = follow[begin + 1 : stop + 1] - follow[begin:stop]
        anchors = follow[begin:stop, None] + alpha * step[:, None]  # (B, S, P, 3)
        # v' = (v + h (k (anchor - x) + c u + F)) / d,  x' = x + h v'
        drive = ((h * stiffness * anchors + (h * damping / frame_time) * step[:, None]) / denominator)
        drive = drive.reshape(-1, count, 3)
        if links:
            rest = (anchors[:, :, link_b] - anchors[:, :, link_a]).reshape(-1, links, 3)
            rest = np.sqrt((rest[..., 0] * rest[..., 0] + rest[..., 1] * rest[..., 1]) + rest[..., 2] * rest[..., 2])
        else:
            rest = np.zeros((len(drive), 0))
        row = begin
        for k, (push, rest_k) in enumerate(zip(drive, rest), start=1):
            v *= shrink
            v += push
            v -= pull * x
            if links:
                e = x[link_b] - x[link_a]
                length = np.sqrt((e[:, 0] * e[:, 0] + e[:, 1] * e[:, 1]) + e[:, 2] * e[:, 2])
                # 1 - rest / length; a collapsed link (length 0) has e = 0 and pulls with nothing.
                scale = 1.0 - rest_k / np.maximum(length, 1e-300)
                pulled = strength * (scale[:, None] * e)
                for axis in range(3):
                    v[:, axis] += np.bincount(link_a, pulled[:, axis], count)
                    v[:, axis] -= np.bincount(link_b, pulled[:, axis], count)
            x = x + h * v
            if k % substeps == 0:
                row += 1
                out[row] = x
    return out


def _integrate_compiled(follow, link_a, link_b, frame_time, substeps, stiffness, link_stiffness, damping):
    """`_integrate_vectorised`'s time loop by ``core/_kernels.c``: each substep one pass over the particles
    and one over the links, in the CPU's cache (the same bits; 10,000 frames of 31 particles in 5 ms,
    the NumPy loop's 0.20 s)."""
    follow = np.ascontiguousarray(follow, dtype=np.float64)
    frames, count, _ = follow.shape
    out = np.empty_like(follow)
    _kernels.springs(follow, out, np.ascontiguousarray(link_a, dtype=np.int64),
                     np.ascontiguousarray(link_b, dtype=np.int64), frames, count, len(link_a), frame_time, substeps,
                     stiffness, link_stiffness, damping)
    return out


class SpringLinks(NamedTuple):
    """Which joints get a suspended particle and which particle pairs are tied by link springs.

    members : (P,) int, the simulated joints
    link_a, link_b : (L,) int, parent and child particle (indices into members) of each link spring
    degree : the largest number of link springs on one particle
    """

    members: np.ndarray
    link_a: np.ndarray
    link_b: np.ndarray
    degree: int


def spring_links(parents: np.ndarray, active: np.ndarray | None = None) -> SpringLinks:
    """The spring topology of a hierarchy: a particle per active joint, a link spring per active link."""
    parents = np.asarray(parents)
    count = len(parents)
    active = np.ones(count, bool) if active is None else np.asarray(active, bool)
    members = np.flatnonzero(active)
    local = np.full(count, -1)
    local[members] = np.arange(len(members))
    child = members[parents[members] >= 0]
    child = child[active[parents[child]]]
    link_a = local[parents[child]].astype(np.int64)
    link_b = local[child].astype(np.int64)
    degree = np.bincount(np.concatenate([link_a, link_b]), minlength=max(len(members), 1))
    return SpringLinks(members, link_a, link_b, int(degree.max(initial=1)))


def spring_substeps(parents: np.ndarray, frame_time: float, config: SpringConfig, active: np.ndarray | None = None,
                    *, links: SpringLinks | None = None) -> int:
    """Substeps per frame `simulate_springs` will take for these settings."""
    links = links or spring_links(parents, active)
    return substeps_for(frame_time, config.stiffness, config.link_stiffness, links.degree)


def simulate_springs(
    positions: np.ndarray,
    parents: np.ndarray,
    frame_time: float,
    *,
    stiffness: float,
    link_stiffness: float,
    damping: float,
    blend: float | np.ndarray,
    active: np.ndarray | None = None,
    links: SpringLinks | None = None,
    compiled: bool = True,
    into: np.ndarray | None = None,
) -> np.ndarray:
    """Blend the suspended particles' motion into ``positions``.

    Parameters
    ----------
    positions : (F, J, 3) float64 follower (sub-joint) positions
    parents : (J,) int, the hierarchy whose links carry link springs
    frame_time : seconds per frame
    stiffness, link_stiffness, damping, blend : see `SpringConfig`; ``blend`` may also be (J,),
        per joint (a limb's follow-through growing from its root)
    active : (J,) bool, joints that get a suspended particle (others copied)
    links : the topology from `spring_links` (computed from parents and active when None)
    compiled : False runs the plain per-particle Python loop (the test oracle); True the time loop in
        ``core/_kernels.c`` where it was built, else the NumPy one
    into : a float64 array holding ``positions``' values (``positions`` itself, or a copy the caller keeps),
        to write the result into instead of a copy: only the suspended joints are written in it

    Returns
    -------
    (F, J, 3) float64 (``into`` when given). ``blend == 0`` returns a copy (or ``into`` as it was); a still
    pose stays still.
    """
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim != 3 or positions.shape[-1] != 3:
        raise ValueError(f"positions must be (F, J, 3), got {positions.shape}")
    out = positions.copy() if into is None else into
    blend = np.asarray(blend, dtype=np.float64)
    if not np.any(blend) or positions.shape[0] < 2:
        return out
    members, link_a, link_b, degree = links or spring_links(parents, active)
    if not len(members):  # no particle suspended: nothing swings
        return out
    substeps = substeps_for(frame_time, stiffness, link_stiffness, degree)
    link_stiffness = stable_link_stiffness(frame_time, link_stiffness, degree, substeps)
    follow = np.take(positions, members, axis=1)
    kernel = (_integrate_compiled if _kernels is not None else _integrate_vectorised) if compiled else _integrate
    suspended = kernel(follow, link_a, link_b, float(frame_time), substeps, float(stiffness),
                       float(link_stiffness), float(damping))
    share = blend[members][:, None] if blend.ndim else blend
    # (1 - share) follow + share suspended, its two products made in the arrays they are made from
    np.multiply(share, suspended, out=suspended)
    np.multiply(1.0 - share, follow, out=follow)
    follow += suspended
    out[:, members] = follow
    return out


# ---------------------------------------------------------------------------- the stage


def springs_stage(state: State, config: SpringConfig) -> State:
    """The block: follow-through on the arms and legs, knees and elbows bent back, sub-links evened out.

    Adds ``sub_positions`` and ``substeps``.
    """
    hierarchy, positions = state.rubber()
    parents = hierarchy.skeleton.parents
    frame_time = state.motion.frame_time
    active, blend = hanging_links(state.motion.skeleton, hierarchy, state.limbs, config.blend)
    links = spring_links(parents, active)
    out = positions.copy()
    simulate_springs(
        positions[state.first:], parents, frame_time, stiffness=config.stiffness,
        link_stiffness=config.link_stiffness, damping=config.damping, blend=blend, links=links, into=out[state.first:],
    )
    # The knees' and elbows' lag may carry them behind the line again: bend them back.
    hinges = limb_hinges(state.motion.skeleton, state.limbs)
    keep_bends_on_rubber(out[state.first:], hierarchy, state.captured_pos[state.first:], hinges, in_place=True)
    # The lag bunches sub-joints along a limb as well as bending it: make its sub-links even again.
    swung = np.flatnonzero(np.asarray(blend) * active > 0)
    swinging = np.unique(hierarchy.link_child[swung])
    even_out(out[state.first:], hierarchy, swinging, in_place=True)
    # A hand lagging behind a fast elbow stretched a looney forearm to 2.4x (the preset says 2x at
    # most) and tore the skin on it: the lag's stretch is held to max_stretch.
    limit_stretch(out[state.first:], positions[state.first:], parents, hierarchy.skeleton.link_lengths(), swung,
                  config.max_stretch, least=config.min_length, in_place=True)
    substeps = substeps_for(frame_time, config.stiffness, config.link_stiffness, links.degree)
    carried = stable_link_stiffness(frame_time, config.link_stiffness, links.degree, substeps)
    notes = state.notes
    if carried < config.link_stiffness:
        notes += (f"springs: link stiffness {config.link_stiffness:g} is more than {substeps} substeps per frame "
                  f"can carry at {1 / frame_time:g} fps; used {carried:.4g}",)
    return replace(state, sub_positions=out, substeps=substeps, notes=notes)


#: Where `limit_stretch` starts to give: this share of the way from a sub-link's rest length to its most
#: (or at its length before the springs, if that is more).
LIMIT_KNEE = 0.5
#: The least room above that start, as a share of the way from rest to the most: a link a stretch had
#: already made nearly as long as the most still eases in rather than being clipped flat.
LIMIT_ROOM = 0.2


def limit_stretch(positions: np.ndarray, before: np.ndarray, parents: np.ndarray, rest: np.ndarray,
                  links: np.ndarray, most: float, *, least: float = 0.0, in_place: bool = False) -> np.ndarray:
    """``positions`` (F, J, 3) with the links ending at ``links`` no longer than ``most`` times their
    ``rest`` length, or than in ``before`` (F, J, 3) where that is longer, and (with ``least``) no
    shorter than ``least`` times it, or than in ``before`` where that is shorter; everything below follows.

    A link is shortened along its own direction, so its bend and turn stay as they were, and a
    shortened link carries its subtree with it (each joint is its parent plus its own, possibly
    shortened, link vector: one pass over the joints, parents first; a `Skeleton` keeps parents
    before children). The limit is soft: a link keeps its length up to ``rest + LIMIT_KNEE (most
    - 1) rest``, or up to its length before, whichever is more, and eases above that (a tanh, so the
    length and its speed stay continuous) into ``most * rest``, or into ``LIMIT_ROOM (most - 1)
    rest`` past where it starts to give where that is more (a link a strike had already made 2x
    long may swing a little past it rather than be clipped flat). The floor mirrors it: a link keeps its
    length down to ``rest - LIMIT_KNEE (1 - least) rest``, or down to its length before, whichever is
    less, and eases below that into ``least * rest`` (or ``LIMIT_ROOM (1 - least) rest`` below where it
    starts to give, where that is lower). ``in_place``: ``positions`` itself is changed and returned (a
    float64 array or a view of one).
    """
    if not len(links):
        return positions
    out = positions if in_place else positions.copy()
    limited = np.zeros(len(parents), bool)
    limited[links] = True
    limited = limited[1:]
    rest = rest[1:][limited]
    way = (most - 1.0) * rest

    def limit(frames: slice) -> None:  # each frame on its own: a long clip's halves on two cores
        view, was = out[frames], before[frames]
        for part in frame_blocks(len(view), 4096):  # in blocks, a long clip's temporaries stay small
            _limit_block(view[part], was[part], parents, limited, rest, way, most, least)

    on_both_cores(limit, frame_halves(len(out)))
    return out


def _limit_block(positions: np.ndarray, before: np.ndarray, parents: np.ndarray, limited: np.ndarray,
                 rest: np.ndarray, way: np.ndarray, most: float, least: float = 0.0) -> None:
    """`limit_stretch` on a block of frames, in place."""
    ends = np.flatnonzero(limited) + 1  # (only the limited links are measured: every other link's move is its parent's)
    vectors = np.take(positions, ends, axis=1) - np.take(positions, parents[ends], axis=1)
    length = np.sqrt(np.einsum("fjc,fjc->fj", vectors, vectors))
    had = vector_norm(np.take(before, ends, axis=1) - np.take(before, parents[ends], axis=1))
    knee = np.maximum(had, rest + LIMIT_KNEE * way)
    top = np.maximum(most * rest, knee + LIMIT_ROOM * way)
    new_length = soft_limit(length, knee, top)
    if least > 0:  # the floor: the same soft limit on how far a link is shorter than its rest length
        room = (1.0 - least) * rest
        low = np.minimum(had, rest - LIMIT_KNEE * room)
        bottom = np.minimum(least * rest, low - LIMIT_ROOM * room)
        new_length = np.where(new_length < low, low - soft_limit(low - new_length, 0.0, low - bottom), new_length)
    scale = np.divide(new_length, length, out=np.ones_like(new_length), where=length > 0)
    rows = np.flatnonzero(np.any(scale != 1.0, axis=1))  # the frames where something is shortened
    if not len(rows):
        return
    # Each joint's move: its parent's, plus its own link's shortening (joint by joint, each a contiguous
    # block of the frames that move). A shift is never -0.0 (the root's is +0.0, and a sum is -0.0 only of
    # two), so a link that is not limited adds nothing to its parent's. (Not even a NaN for an infinite link,
    # which 0 times it made once: such a clip is refused by the writer either way.)
    own = np.ascontiguousarray(((scale[rows] - 1.0)[..., None] * vectors[rows]).transpose(1, 0, 2))
    shift = np.zeros((len(parents), len(rows), 3))
    of = dict(zip(ends.tolist(), range(len(ends))))
    for joint in range(1, len(parents)):  # parents come before their children (the root's shift is 0)
        if joint in of:
            shift[joint] = shift[parents[joint]] + own[of[joint]]
        elif parents[joint] > 0:
            shift[joint] = shift[parents[joint]]
    positions[rows] += shift.transpose(1, 0, 2)


def hanging_links(skeleton, hierarchy, limbs: dict, blend: float) -> tuple[np.ndarray, np.ndarray | float]:
    """Which rubber joints swing ``(J',)`` bool, and how much of the follow-through each takes.

    Follow-through hangs off a solid body: the root, spine, neck, head, collars and the limbs'
    roots follow their (exaggerated) positions exactly; the arms and legs below the shoulder and
    hip swing. A lagging torso stretched more than the limbs (1.4x on a boxer's neck), which
    cartoon torsos do not (the Stretch-Engine thesis's Table 1), and a lagging collar spun the
    chest round. The follow-through grows along a limb's first link, from none at the shoulder
    or hip to all of it at the elbow or knee: a sub-joint next to a fixed root swinging fully
    kinked the limb there. A rubber chain that is neither a limb nor the body's own (the spine
    and the neck) hangs and swings too: a tail, long ears, a trunk (`tails`). Without arms or
    legs found, every non-rigid link swings by ``blend``.
    """
    active = ~hierarchy.rigid[hierarchy.link_child]
    hung = [limb for name, limb in limbs.items() if name.endswith(("_arm", "_leg"))]
    if not hung:
        return active, blend
    hanging = np.zeros(skeleton.num_joints, bool)
    for limb in hung:
        hanging[limb_joints(skeleton, limb)] = True
    hanging[[limb.base for limb in hung]] = False
    starts = [limb.joints[1] for limb in hung]
    for chain in tails(hierarchy.groups, limbs, hanging):
        hanging[list(chain[1:])] = True
        starts.append(chain[1])
    active &= hanging[hierarchy.link_child]
    weights = np.full(len(hierarchy.link_child), float(blend))
    for start in starts:
        first = hierarchy.link_child == start
        weights[first] *= smootherstep(hierarchy.fraction[first])
    return active, weights


def tails(groups, limbs: dict, hanging: np.ndarray) -> list[tuple[int, ...]]:
    """The rubber chains (`SubjointHierarchy.groups`: each from the joint it hangs off) that are
    neither a limb nor the body's own spine and neck: a fox's tail. A human's groups are its
    limbs, spine and neck, so none."""
    body = {j for name in ("spine", "neck") if name in limbs for j in limbs[name].joints}
    taken = body | {int(j) for j in np.flatnonzero(hanging)} | {limb.base for limb in limbs.values()}
    return [chain for chain in groups if len(chain) > 1 and not taken & set(chain[1:])]
