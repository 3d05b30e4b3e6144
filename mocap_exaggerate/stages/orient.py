"""Orientation recovery (Kwon & Lee 2008, section 6): from positions back to joint channels.

Original joints take their captured world orientation turned by the
smallest rotation that carries their original link direction onto the new
one. The sub-joints of a cut link follow the curve: a zero-length start
joint on the original joint (`link_starts`) and each sub-joint after it
carry their rest sub-link onto the current one, with the twist between the
link's two ends spread along it (`curve_frames`). Kwon and Lee slerp between
the original joints' orientations instead, which points a sub-joint's bone
up to 47-85 degrees (170 on iClone thighs) away from where its sub-link goes
even with no exaggeration: positions were right, a mesh was not. Because link
lengths change, every output joint carries position and rotation channels (6
DOF), and forward kinematics of the result reproduces the positions exactly.

Which "link" turns a joint: its one outgoing link; at a branch joint (hips,
chest) the rotation that best carries all of its outgoing links (a Kabsch
fit; the smallest rotation when the links are collinear); at an end
effector its incoming link. Zero-length links are looked through to the
first joint at a distance. Branches pruned as minor (fingers, toes, face)
ride rigidly: their captured local transforms are applied under the
recovered parent.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ..analysis.branches import effective_lengths, first_above_at_distance, first_below_at_distance, riders
from ..core.kinematics import cache_blocks, local_from_world
from ..core.motion import Motion
from ..core.native import frame_halves, on_both_cores
from ..core.native import kernels as _kernels  # the compiled loops, where built (core/native.py)
from ..core.rotations import (
    quat_between,
    quat_from_matrix,
    quat_inv,
    quat_mul,
    quat_normalize,
    quat_pow,
    quat_rotate,
    quat_slerp,
    sum_last,
    vector_norm,
)
from ..core.timing import gaussian_average, smootherstep, step_gain
from .state import Output
from .subjoints import SubjointHierarchy, link_starts

if TYPE_CHECKING:
    from ..config import OutputConfig
    from .state import State

__all__ = ["recover_orientations", "curve_frames", "motion_from_world", "orient_stage"]


def motion_from_world(world_pos, world_rot, skeleton, frame_time, euler_hint=None, *,
                      overwrite_rotations: bool = False) -> Motion:
    """A Motion whose local 6-DOF channels reproduce world transforms ``(F, J, 3)`` and ``(F, J, 4)``
    (its local rotations written over ``world_rot`` with ``overwrite_rotations``, `local_from_world`)."""
    local_rot, local_pos = local_from_world(skeleton.parents, world_rot, world_pos,
                                            overwrite_rotations=overwrite_rotations)
    return Motion(skeleton, frame_time, local_rot, local_pos, euler_hint)


def _centred(u: np.ndarray) -> bool:
    """Whether `_fit_turn` fits the vectors ``u (F, n, 3)`` about their centroid: where they do not all start at
    one point (told from the clip's middle frame)."""
    middle = u[len(u) // 2]
    centred = middle - middle.mean(axis=0)
    return bool(vector_norm(centred).max() > 0.1 * vector_norm(middle).max())


#: Weight of the pull toward "no turn" in `_fit_turn`, relative to the vectors' summed squared length.
_STEADY = 0.001


def _fit_turn(u: np.ndarray, v: np.ndarray, centre: bool | None = None) -> np.ndarray:
    """Rotations ``(F, 4)`` carrying vector sets ``u (F, n, 3)`` onto ``v (F, n, 3)``: Kabsch, held steady.

    The least-squares rotation of the vectors about their centroid (an SVD of
    ``sum v u^T`` per frame): the children moving together relative to the
    joint is a shift, not a turn. (Children that all start at one point, a
    chest whose neck and collars share an offset, are fitted as they are.) With a small pull toward the identity
    (three extra pairs ``(s e_k, s e_k)``), a set the vectors barely span (a
    pelvis seen from its two hips) leaves the turn about their common line to
    that pull, the smallest turn, instead of to noise: a TRIAD spun an
    exaggerated pelvis whose hips rose past it by 60 to 140 degrees in a frame.
    """
    if centre is None:
        centre = _centred(u)
    if centre:
        u = u - u.mean(axis=1, keepdims=True)  # a shift of all the children together is not a turn
        v = v - v.mean(axis=1, keepdims=True)
    cross_cov = np.einsum("fni,fnj->fij", v, u)
    scale = _STEADY * np.einsum("fni,fni->f", u, u)
    cross_cov += scale[:, None, None] * np.eye(3)
    left, _, right = np.linalg.svd(cross_cov)
    sign = np.sign(np.linalg.det(left @ right))
    left[:, :, 2] *= np.where(sign == 0, 1.0, sign)[:, None]
    return quat_from_matrix(left @ right)


def recover_orientations(
    sub_pos: np.ndarray,
    hierarchy: SubjointHierarchy,
    source: Motion,
    source_rot: np.ndarray,
    source_pos: np.ndarray,
    pins: tuple[np.ndarray, np.ndarray] | None = None,
    max_speed: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """World orientations and positions ``(F, J'', 4)``, ``(F, J'', 3)`` on the rubber skeleton
    written out, ``link_starts(hierarchy)`` (a start joint on each cut link), rigid branches placed.

    sub_pos : (F, J', 3) float64 positions on ``hierarchy`` (rigid branches' entries are replaced)
    hierarchy : the sub-joint hierarchy of ``source.skeleton``
    source : the captured Motion (its local transforms place rigid branches)
    source_rot, source_pos : (F, J, 4) and (F, J, 3) captured world transforms
    pins : original joints ``(k,)`` that turn back to their captured orientation by
        weights ``(F, k)`` (a planted foot keeps its toes down)
    max_speed : when > 0, a joint carrying a rigid branch turns away from its captured
        orientation only so fast that no joint of the branch moves more in a frame than
        ``max_speed`` times its own largest captured one-frame move (see `_calm_riders`)
    """
    skeleton = source.skeleton
    original = hierarchy.original
    rigid = hierarchy.rigid
    sub_pos = np.array(sub_pos, dtype=np.float64)
    new_pos = np.take(sub_pos, original, axis=1)
    frames = sub_pos.shape[0]
    world = np.zeros((frames, skeleton.num_joints, 4))
    world[..., 3] = 1.0

    lengths = effective_lengths(skeleton)
    fitted, kept = [], []  # (joint, its children at distance, fitted about their centroid); joints kept as captured
    single_joint, single_from, single_to = [], [], []
    for j in range(skeleton.num_joints):
        if rigid[j]:
            continue
        targets = first_below_at_distance(skeleton, j, rigid, lengths)
        if len(targets) >= 2:
            middle = source_pos[frames // 2 : frames // 2 + 1]  # (what `_centred` reads of the whole clip)
            fitted.append((j, targets, _centred(middle[:, targets] - middle[:, j : j + 1])))
            continue
        if len(targets) == 1:
            single_joint.append(j)
            single_from.append(j)
            single_to.append(targets[0])
        else:
            above = first_above_at_distance(skeleton, j, lengths)
            if above >= 0:
                single_joint.append(j)
                single_from.append(above)
                single_to.append(j)
            else:
                kept.append(j)

    single = np.array([single_from, single_to, single_joint], dtype=np.int64).reshape(3, -1)
    # (the captured transforms are the forward kinematics' joint-major arrays: each half copied into frame order
    # for the compiled pass, a few ms)
    compiled = _kernels is not None and all(a.dtype == np.float64 for a in (source_pos, source_rot)) and all(
        a.dtype == np.float64 and a.flags.c_contiguous for a in (new_pos, world))

    def fit(rows: slice, placed: np.ndarray = new_pos) -> None:  # each frame on its own: halves on two cores
        part = world[rows]
        was, now, turned = source_pos[rows], placed[rows], source_rot[rows]
        for j, targets, centre in fitted:
            u = was[:, targets] - was[:, j : j + 1]
            v = now[:, targets] - now[:, j : j + 1]
            part[:, j] = quat_mul(_fit_turn(u, v, centre), turned[:, j])
        part[:, kept] = turned[:, kept]
        if single_joint and compiled and placed.dtype == np.float64 and placed.flags.c_contiguous:  # every joint
            # turned by a single link, in one compiled pass: the same bits
            _kernels.single_turns(np.ascontiguousarray(was), now, np.ascontiguousarray(turned), part, *single,
                                  len(part), skeleton.num_joints, len(single_joint))
        elif single_joint:  # one vectorised call for them all
            turn = quat_between(was[:, single_to] - was[:, single_from], now[:, single_to] - now[:, single_from])
            part[:, single_joint] = quat_normalize(quat_mul(turn, turned[:, single_joint]))
        if pins is not None and len(pins[0]):
            joints, weights = pins
            part[:, joints] = quat_slerp(part[:, joints], turned[:, joints], weights[rows])

    on_both_cores(fit, frame_halves(frames))
    del fit  # (it holds ``new_pos``, which is let go below)
    if max_speed > 0 and frames > 2:
        _calm_riders(world, new_pos, source_rot, source_pos, skeleton, rigid, max_speed,
                     max(int(round(0.05 / source.frame_time)), 2))

    # Rigid branches: captured local transforms under the recovered parent.
    placed = np.flatnonzero(rigid[1:]) + 1
    local_rot, local_pos = source.local_rotations, source.local_positions
    if _kernels is not None and len(placed) and all(a.dtype == np.float64 and a.flags.c_contiguous
                                                    for a in (local_rot, local_pos, world, new_pos)):
        _kernels.rigid_branches(world, new_pos, local_rot, local_pos, placed, skeleton.parents[placed].astype(np.int64),
                                frames, skeleton.num_joints, len(placed))  # (in one pass: the same bits)
    else:
        for j in placed:
            p = skeleton.parents[j]
            world[:, j] = quat_mul(world[:, p], local_rot[:, j])
            new_pos[:, j] = new_pos[:, p] + quat_rotate(world[:, p], local_pos[:, j])
    sub_pos[:, original] = new_pos

    # The rubber skeleton written out: a start joint on each cut link (see `link_starts`).
    rubber = link_starts(hierarchy)
    if rubber is hierarchy:
        positions = sub_pos
    else:
        # Each written joint's column of sub_pos (a start joint: its link's parent's), gathered at once.
        starts = rubber.fraction == 0.0
        column = np.empty(rubber.skeleton.num_joints, dtype=np.int64)
        column[~starts] = np.arange(sub_pos.shape[1])
        column[starts] = column[rubber.original[rubber.link_parent[starts]]]
        positions = np.take(sub_pos, column, axis=1)
    del sub_pos, new_pos  # (a long clip's copies, not needed past here)
    return curve_frames(world, positions, rubber), positions


#: Passes of the riders' speed limit (each leaves less over budget, as in extrapolation's).
_RIDER_PASSES = 6


def _calm_riders(world, new_pos, source_rot, source_pos, skeleton, rigid, max_speed: float, radius: int) -> None:
    """Slow the turn of joints that carry rigid branches (feet with toes, hands with fingers), in place.

    A rigid branch rides its parent's recovered turn ``D = world source_rot^-1``:
    a toe sits at ``ankle + D (toe - ankle)_captured``, so a shin swung faster
    than captured swings the toes faster still, past the speed limit the
    extrapolation keeps on every joint it moves. Where a rider's one-frame move
    is over ``max_speed`` times its captured largest, the parent's turn is
    scaled down (``D^g``, ``g`` from the rider's budget over its step, spread
    in time like extrapolation's gains so it eases in and out) and measured
    again. The parent's position is never moved; where its own move uses the
    budget up, the turn goes as far as back to the captured orientation.
    """
    for p, below in riders(skeleton, rigid).items():
        budget = max_speed * vector_norm(np.diff(source_pos[:, below], axis=0)).max(axis=0)
        turn = quat_mul(world[:, p], quat_inv(source_rot[:, p]))
        turn = turn * np.where(turn[:, 3:] < 0, -1.0, 1.0)  # the shorter way: D^0 = 1, D^1 = D
        offsets = source_pos[:, below] - source_pos[:, p : p + 1]
        gain = np.ones(len(turn))
        for _ in range(_RIDER_PASSES):
            placed = quat_rotate(quat_pow(turn, gain)[:, None], offsets) + new_pos[:, p : p + 1]
            step = vector_norm(np.diff(placed, axis=0))  # (F-1, riders)
            share = np.min(np.where(step > budget, 0.98 * budget / np.maximum(step, 1e-300), 1.0), axis=1)
            if share.min() >= 1.0:  # (only the frames over the budget are calmed, a little under it)
                break
            gain = gain * step_gain(share, radius)
        if gain.min() < 1.0:
            world[:, p] = quat_normalize(quat_mul(quat_pow(turn, gain), source_rot[:, p]))


#: Cosines of the fold at a link's end joint between which its twist fades out (165 and 120 degrees).
_FOLDED, _UNFOLDED = np.cos(np.radians(165.0)), np.cos(np.radians(120.0))

#: Twists (radians) past which a link's twist fades out, gone at half a turn.
_TWIST_FADE = np.radians(120.0)


def curve_frames(world: np.ndarray, positions: np.ndarray, hierarchy: SubjointHierarchy, *,
                 compiled: bool = True) -> np.ndarray:
    """World orientations ``(F, J', 4)`` of a rubber skeleton whose bones follow their sub-links.

    world : (F, J, 4) orientations of the original joints, kept as they are
    positions : (F, J', 3) positions on ``hierarchy``, a `link_starts` hierarchy
        (each cut link's joints are consecutive: its start ``s0``, ``s1`` ... and the joint it ends at)

    Along each cut link, a frame is carried from one sub-link to the next by
    the smallest turn (a discrete rotation-minimising frame, as spline-IK and
    ribbon rigs do), starting from the original joint's orientation turned
    onto the first sub-link, so every sub-joint's rest sub-link points along
    its current one. The twist that frame is missing at the far end, about the
    last sub-link, against the frame the link blends into there (the next
    link's start where the chain goes on through one link, else the end
    joint's own), is spread along the link in proportion to each sub-joint's
    place. Where that twist is ill-defined (the end's frame folds the last
    sub-link back past 120 degrees) or near half a turn, it fades out
    smoothly, and it is eased over a frame either way, so every frame follows
    from its neighbours. ``compiled``: the frames carried along the links and the twist spread
    along them by ``core/_kernels.c`` where it was built (the same bits, a third of the time).
    """
    sub = hierarchy.skeleton
    out = np.empty(positions.shape[:2] + (4,))
    out[:, hierarchy.original] = world
    starts = np.flatnonzero(hierarchy.fraction == 0.0)
    if not len(starts):
        return out
    counts = np.bincount(hierarchy.link_child[~hierarchy.is_original], minlength=len(hierarchy.original))
    cuts = counts[hierarchy.link_child[starts]]  # sub-links on each link: s0 ... s(n-1), then its end joint
    direction = sub.offsets[starts + 1]  # every sub-link of a link rests along the same direction
    direction = direction / np.maximum(vector_norm(direction, keepdims=True), 1e-300)
    head = hierarchy.original[hierarchy.link_parent[starts]]
    end = hierarchy.original[hierarchy.link_child[starts]]
    # The twist left at the far end, against the end's frame: the next link's start where the chain
    # goes on through one link (what the skin blends this link into), else the end joint's own.
    following = np.bincount(hierarchy.link_parent[starts], minlength=len(hierarchy.original))
    after = {int(hierarchy.link_parent[j]): int(j) for j in starts if following[hierarchy.link_parent[j]] == 1}
    ends = np.array([after.get(int(c), int(e)) for c, e in zip(hierarchy.link_child[starts], end)], dtype=np.int64)
    steps = [(np.flatnonzero(cuts > k), starts[cuts > k] + k) for k in range(int(cuts.max()))]
    # Every frame on its own but for the twist's easing in time: two passes over blocks of frames, whose
    # chains of quaternion products then stay in the CPU's cache (the same arithmetic as whole clips).
    angle = np.empty((len(out), len(starts)))
    kernel = compiled and _kernels is not None and positions.dtype == np.float64 and positions.flags.c_contiguous
    if kernel:
        heads, firsts, counts = head.astype(np.int64), starts.astype(np.int64), cuts.astype(np.int64)
        direction = np.ascontiguousarray(direction, dtype=np.float64)
        on_both_cores(lambda part: _kernels.chain_frames(
            out[part], positions[part], heads, firsts, counts, direction, part.stop - part.start, out.shape[1],
            len(starts)), frame_halves(len(out)))

    def carried(rows: slice) -> None:  # each frame on its own: a long clip's halves on two cores
        for block in cache_blocks(rows.stop - rows.start, len(starts)):
            part = slice(rows.start + block.start, rows.start + block.stop)
            if kernel:
                frame = out[part, starts + cuts - 1]
            else:
                frame = out[part, head]
                for on, joint in steps:
                    along = positions[part, joint + 1] - positions[part, joint]
                    frame[:, on] = quat_normalize(quat_mul(quat_between(quat_rotate(frame[:, on], direction[on]),
                                                                        along), frame[:, on]))
                    out[part, joint] = frame[:, on]
            # Their turn relative to the carried frame, split into a swing and a twist about the last sub-link.
            last = positions[part, end] - positions[part, starts + cuts - 1]
            axis = last / np.maximum(vector_norm(last, keepdims=True), 1e-300)
            gap = quat_mul(out[part, ends], quat_inv(frame))
            sign = np.where(gap[..., 3] < 0.0, -1.0, 1.0)  # q and -q are one turn: take the one within half a turn
            twisted = 2.0 * np.arctan2(sign * sum_last(gap[..., :3] * axis), np.abs(gap[..., 3]))
            pointing = quat_rotate(gap, axis)
            fold = sum_last(pointing * axis) / np.maximum(vector_norm(pointing), 1e-300)
            angle[part] = twisted * (smootherstep((fold - _FOLDED) / (_UNFOLDED - _FOLDED))
                                     * smootherstep((np.pi - np.abs(twisted)) / (np.pi - _TWIST_FADE)))

    on_both_cores(carried, frame_halves(len(out)))
    angle = gaussian_average(angle, 1.0, ends="nearest")  # where the fades pass quickly, over a few frames
    if kernel:
        angle = np.ascontiguousarray(angle)
        on_both_cores(lambda part: _kernels.twist_frames(
            out[part], angle[part], firsts, counts, direction, part.stop - part.start, out.shape[1], len(starts)),
            frame_halves(len(out)))
        return out
    for part in cache_blocks(len(out), len(starts)):
        for k, (on, joint) in enumerate(steps[1:], start=1):
            # A turn about the sub-link is a turn about the rest direction in the bone's own frame.
            half = 0.5 * angle[part][:, on] * (k / cuts[on])
            twist = np.concatenate([direction[on] * np.sin(half)[..., None], np.cos(half)[..., None]], axis=-1)
            out[part, joint] = quat_normalize(quat_mul(out[part, joint], twist))
    return out


# ---------------------------------------------------------------------------- the stage


def orient_stage(state: State, config: OutputConfig) -> State:
    """The block: orientations recovered on the rubber skeleton (planted feet pinned, ``speed_limit`` kept),
    and the output Motion on the skeleton ``config.skeleton`` asks for. Adds ``output``."""
    motion = state.motion
    hierarchy, positions = state.rubber()
    sub_rot, sub_pos = recover_orientations(positions, hierarchy, motion, state.captured_rot, state.captured_pos,
                                            state.pins, max_speed=state.speed_limit)
    rubber = link_starts(hierarchy)  # the skeleton sub_rot and sub_pos are on
    # The world rotations become the local ones in place: the output's FK gives them back
    # (`PipelineResult.world_rotations`), and a long clip does not hold both.
    if config.skeleton == "original":
        keep = rubber.original
        out_pos = sub_pos[:, keep]
        out = motion_from_world(out_pos, sub_rot[:, keep], motion.skeleton.with_full_channels(), motion.frame_time,
                                motion.euler_hint, overwrite_rotations=True)
        original_index = np.arange(motion.skeleton.num_joints)
    else:
        out_pos = sub_pos
        out = motion_from_world(out_pos, sub_rot, rubber.skeleton, motion.frame_time, overwrite_rotations=True)
        original_index = rubber.original
    del sub_rot
    return replace(state, output=Output(out, out_pos, original_index))
