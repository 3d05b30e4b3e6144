"""Sub-joint hierarchy and rubber-joint groups (Kwon & Lee 2008, sections 5.1 and 5.2).

Every link is cut into equal sub-links with a new sub-joint at the end of
each; the sub-joint that lands on an original joint keeps its name, the
others are called ``<Joint>_s1``, ``<Joint>_s2``, … after the joint their link
ends at (each link has exactly one), counted from the parent side.

Rubber-joint groups (RJG): an end effector is in a group, and so is a parent
whose only child is in it. Real skeletons have fingers, toes, twist bones and
face rigs that would cut every group at the hand or foot, so minor branches
are pruned first: they ride rigidly on their parent and get no sub-joints.
Within a group the positions of the original joints are interpolated, frame
by frame, by a C1 piecewise cubic Bézier curve parameterised by cumulative
rest link length, and each sub-joint sits on it at its own parameter.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from ..analysis.branches import minor_branches, rubber_groups
from ..core.errors import ConfigError, check_flag
from ..core.kinematics import cache_blocks
from ..core.native import by_frame_halves, frame_halves, on_both_cores
from ..core.settings import Flag, setting
from ..core.skeleton import POSITION_CHANNELS, Skeleton

if TYPE_CHECKING:
    from .state import State

__all__ = [
    "subjoints_stage",
    "SubjointConfig",
    "SubjointHierarchy",
    "build_hierarchy",
    "link_starts",
    "position_subjoints",
    "bezier_points",
    "even_out",
]

#: Most sub-links a link is cut into, by count or by length.
MAX_CUTS = 32
def length_value(text: str) -> float | str:
    """A ``--sublink-length`` word: a number of skeleton units, or a share such as ``'3%'``
    (anything else is kept as given, for `SubjointConfig` to name in its error)."""
    if text.strip().endswith("%"):
        return text
    try:
        return float(text)
    except ValueError:
        return text


@dataclass(frozen=True, kw_only=True)
class SubjointConfig:
    """Settings of the sub-joint block.

    per_link : every (non-rigid, non-zero) link is cut into this many equal sub-links
    sublink_length : if set, a target sub-link length instead, in skeleton units
        (a number) or as a share of the skeleton height (``"3%"``); each link
        gets ``max(1, round(length / target))`` sub-links
    groups : explicit rubber-joint groups, each a list of joint names from the
        top of the chain to its end; replaces the automatic grouping
    rigid : extra joint-name patterns whose subtrees ride rigidly (no sub-joints)
    """

    enabled: bool = setting(True, flag=Flag(
        "--no-subjoints", "Switch the rubber sub-joint hierarchy (Bézier groups) off.", sets=False))
    per_link: int = setting(4, flag=Flag(
        "--subjoints", "Cut every link into M rubber sub-links (default from the preset, 4 in cartoon).", metavar="M"))
    sublink_length: float | str | None = setting(None, flag=Flag(
        "--sublink-length", "Instead of M: target sub-link length, in skeleton units or as '3%' of the height.",
        metavar="LEN", parse=length_value))
    groups: tuple[tuple[str, ...], ...] = field(default=())
    rigid: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        check_flag("subjoints.enabled", self.enabled)
        if isinstance(self.per_link, bool) or not isinstance(self.per_link, int) or not 1 <= self.per_link <= MAX_CUTS:
            raise ConfigError(f"subjoints.per_link must be a whole number from 1 to {MAX_CUTS}, got {self.per_link!r}")
        if self.sublink_length is not None:
            self._target(1.0)
        object.__setattr__(self, "groups", tuple(tuple(str(n) for n in g) for g in self.groups))
        object.__setattr__(self, "rigid", tuple(str(p) for p in self.rigid))
        for group in self.groups:
            if len(group) < 2:
                raise ConfigError(f"subjoints.groups: a group needs at least two joints, got {list(group)}")

    def _target(self, height: float) -> float:
        value = self.sublink_length
        if isinstance(value, str) and value.strip().endswith("%"):
            try:
                share = float(value.strip()[:-1]) / 100.0
            except ValueError:
                share = -1.0
            target = share * height
        elif isinstance(value, (int, float)) and not isinstance(value, bool):
            target = float(value)
        else:
            target = -1.0
        if not np.isfinite(target) or target <= 0:
            raise ConfigError(f"subjoints.sublink_length must be a positive length or a share like '3%', got {value!r}")
        return target


@dataclass(frozen=True, eq=False)
class SubjointHierarchy:
    """The sub-joint skeleton and how it maps onto the original one.

    skeleton : Skeleton with J' joints, 6 channels each
    original : (J,) int, index in ``skeleton`` of each original joint
    link_child : (J',) int, original joint at the end of the link each joint lies on
        (an original joint: itself)
    link_parent : (J',) int, original joint at the start of that link (-1 for the root)
    fraction : (J',) float, position along the link, 1.0 on original joints
    rigid : (J,) bool, original joints that ride rigidly on their parent
    groups : tuple of chains of original joint indices; each starts with the
        branch joint the group hangs from (when there is one)
    """

    skeleton: Skeleton
    original: np.ndarray
    link_child: np.ndarray
    link_parent: np.ndarray
    fraction: np.ndarray
    rigid: np.ndarray
    groups: tuple[tuple[int, ...], ...]

    @property
    def is_original(self) -> np.ndarray:
        return self.fraction == 1.0


def build_hierarchy(skeleton: Skeleton, config: SubjointConfig | None = None) -> SubjointHierarchy:
    """Cut the links of ``skeleton`` into sub-links and find its rubber-joint groups."""
    config = config or SubjointConfig()
    rigid = minor_branches(skeleton, config.rigid)
    if config.groups:
        groups = []
        for names in config.groups:
            try:
                chain = [skeleton.index(n) for n in names]
            except KeyError as error:
                raise ConfigError(f"subjoints.groups: {error.args[0]}") from None
            for upper, lower in zip(chain, chain[1:]):
                if skeleton.parents[lower] != upper:
                    raise ConfigError(
                        f"subjoints.groups: {skeleton.names[lower]} is not a child of {skeleton.names[upper]}"
                    )
            groups.append(tuple(chain))
            rigid[chain[1:]] = False
        groups = tuple(groups)
    else:
        groups = rubber_groups(skeleton, rigid)

    lengths = skeleton.link_lengths()
    if config.sublink_length is not None:
        target = config._target(skeleton.height())
        most = float(np.max(lengths / target, initial=1.0))
        if most > MAX_CUTS:
            raise ConfigError(
                f"subjoints.sublink_length {config.sublink_length!r} would cut the longest link into {most:.3g} "
                f"sub-links; at most {MAX_CUTS} (a length of at least {lengths.max() / MAX_CUTS:.4g})"
            )
        cuts = np.maximum(1, np.rint(lengths / target)).astype(np.int64)
    else:
        cuts = np.full(skeleton.num_joints, config.per_link, dtype=np.int64)
    cuts[(lengths < 1e-4 * skeleton.height()) | rigid] = 1  # zero (or hair-thin) links are not cut
    cuts[0] = 1

    joints = _Joints(skeleton.names)
    original = np.empty(skeleton.num_joints, dtype=np.int64)
    for j in range(skeleton.num_joints):
        order = skeleton.rotation_order(j)
        joint_channels = POSITION_CHANNELS + tuple(f"{a}rotation" for a in order)
        parent = -1 if j == 0 else int(original[skeleton.parents[j]])
        step = skeleton.offsets[j] / cuts[j]
        above = int(skeleton.parents[j])
        for k in range(1, cuts[j]):
            parent = joints.add(joints.fresh(f"{skeleton.names[j]}_s{k}"), parent, step, joint_channels,
                                np.full(3, np.nan), j, above, k / cuts[j])
        original[j] = joints.add(skeleton.names[j], parent, step if j > 0 else skeleton.offsets[0], joint_channels,
                                 skeleton.end_sites[j], j, above, 1.0)
    return joints.hierarchy(skeleton, original, rigid, groups)


class _Joints:
    """A rubber skeleton's joints, added parent before child, and where each lies on the original."""

    def __init__(self, taken) -> None:
        self.rows: list[tuple] = []
        self.taken = set(taken)

    def fresh(self, name: str) -> str:
        """``name``, or ``name_``, ``name__`` ... where a joint already has it."""
        while name in self.taken:
            name += "_"
        self.taken.add(name)
        return name

    def add(self, name, parent, offset, channels, end_site, link_child, link_parent, fraction) -> int:
        self.rows.append((name, parent, offset, channels, end_site, link_child, link_parent, fraction))
        return len(self.rows) - 1

    def hierarchy(self, like: Skeleton, original, rigid, groups) -> SubjointHierarchy:
        names, parents, offsets, channels, ends, child, above, fraction = zip(*self.rows)
        skeleton = Skeleton(names, np.array(parents), np.array(offsets), channels, np.array(ends), like.positions,
                            like.up)
        return SubjointHierarchy(skeleton, np.asarray(original), np.array(child), np.array(above),
                                 np.array(fraction, dtype=np.float64), rigid, groups)


@functools.lru_cache(maxsize=16)
def link_starts(hierarchy: SubjointHierarchy) -> SubjointHierarchy:
    """``hierarchy`` with a zero-length joint ``<Joint>_s0`` at the start of every cut link.

    The rubber skeleton that is written out. The first sub-link of a link
    leaves its original joint along the curve, not along the straight link,
    so no single rotation of the original joint can both keep the captured
    orientation (what every tool that reads the joint by name expects) and
    point the first sub-link's bone where it goes (what a skin follows). The
    start joint sits on the original joint (its OFFSET is zero, its fraction
    0) and carries the curve's frame; the original joint keeps its own. A
    hierarchy with no cut link is returned as it is.
    """
    parents = hierarchy.skeleton.parents
    first = np.flatnonzero((hierarchy.fraction > 0) & ~hierarchy.is_original & (parents >= 0))
    first = first[hierarchy.is_original[parents[first]]]  # the first sub-joint of each cut link
    if not len(first):
        return hierarchy
    sub = hierarchy.skeleton
    starts = set(int(j) for j in first)
    new_index = np.empty(sub.num_joints, dtype=np.int64)
    joints = _Joints(sub.names)
    for j in range(sub.num_joints):
        parent = int(new_index[sub.parents[j]]) if j > 0 else -1
        child, above = int(hierarchy.link_child[j]), int(hierarchy.link_parent[j])
        if j in starts:
            name = joints.fresh(f"{hierarchy.skeleton.names[hierarchy.original[child]]}_s0")
            parent = joints.add(name, parent, np.zeros(3), sub.channels[j], np.full(3, np.nan), child, above, 0.0)
        new_index[j] = joints.add(sub.names[j], parent, sub.offsets[j], sub.channels[j], sub.end_sites[j], child,
                                  above, float(hierarchy.fraction[j]))
    return joints.hierarchy(sub, new_index[hierarchy.original], hierarchy.rigid, hierarchy.groups)


def bezier_points(points: np.ndarray, knots: np.ndarray, params: np.ndarray, *, even: bool = True) -> np.ndarray:
    """Evaluate the C1 piecewise cubic Bézier through ``points`` at ``params``.

    points : (F, n, 3) float64, the curve passes through each at its knot
    knots : (n,) float64, strictly increasing parameters (cumulative rest length)
    params : (S,) float64 within ``[knots[0], knots[-1]]``

    Tangents come from the neighbouring points (centred differences, one-sided
    at the ends), so a chain of points spaced in proportion to their knots
    lies on a line traversed at constant speed: its sub-joints are evenly
    spaced. Returns (F, S, 3).
    """
    n = len(knots)
    if n < 2:
        return np.repeat(points[:, :1], len(params), axis=1)
    tangents = np.empty_like(points)
    tangents[:, 0] = (points[:, 1] - points[:, 0]) / (knots[1] - knots[0])
    tangents[:, -1] = (points[:, -1] - points[:, -2]) / (knots[-1] - knots[-2])
    if n > 2:
        tangents[:, 1:-1] = (points[:, 2:] - points[:, :-2]) / (knots[2:] - knots[:-2])[:, None]
    segment = np.clip(np.searchsorted(knots, params, side="right") - 1, 0, n - 2)
    width = knots[1:] - knots[:-1]
    fraction = (params - knots[segment]) / width[segment]
    # Bézier control points of each segment: P_i, P_i + h T_i / 3, P_i+1 - h T_i+1 / 3, P_i+1.
    b0 = points[:, :-1]
    b3 = points[:, 1:]
    b1 = b0 + tangents[:, :-1] * (width / 3.0)[:, None]
    b2 = b3 - tangents[:, 1:] * (width / 3.0)[:, None]
    if even:
        u = _even_parameter(b0, b1, b2, b3, segment, fraction)
    else:
        u = np.broadcast_to(fraction, (points.shape[0], len(params)))
    return _bezier(b0[:, segment], b1[:, segment], b2[:, segment], b3[:, segment], u[..., None])


def _bezier(b0, b1, b2, b3, u):
    v = 1.0 - u
    return v**3 * b0 + 3 * v * v * u * b1 + 3 * v * u * u * b2 + u**3 * b3


#: Samples per segment of the arc-length table that spaces sub-joints evenly along their link.
_ARC_SAMPLES = 16


def _even_parameter(b0, b1, b2, b3, segment, fraction):
    """(F, S): the Bézier parameter at ``fraction`` (S,) of the arc length of its ``segment`` (S,),
    from a table of each segment's (F, n - 1) arc length at `_ARC_SAMPLES` steps."""
    u = np.linspace(0.0, 1.0, _ARC_SAMPLES + 1)
    basis = np.stack([(1 - u) ** 3, 3 * (1 - u) ** 2 * u, 3 * (1 - u) * u * u, u**3], axis=1)  # (K + 1, 4)
    steps = np.diff(basis, axis=0) @ np.stack([b0, b1, b2, b3], axis=2)  # (F, n - 1, K, 3): sample to sample
    arc = np.zeros(steps.shape[:2] + (_ARC_SAMPLES + 1,))
    np.cumsum(np.sqrt(np.einsum("fskc,fskc->fsk", steps, steps)), axis=2, out=arc[:, :, 1:])
    arc = arc[:, segment]  # (F, S, K + 1)
    target = fraction * arc[..., -1]
    below = np.clip(np.sum(arc[..., 1:] < target[..., None], axis=2), 0, _ARC_SAMPLES - 1)
    start = np.take_along_axis(arc, below[..., None], axis=2)[..., 0]
    step = np.take_along_axis(arc, below[..., None] + 1, axis=2)[..., 0] - start
    within = np.divide(target - start, step, out=np.zeros_like(step), where=step > 0)
    return (below + np.clip(within, 0.0, 1.0)) / _ARC_SAMPLES


def position_subjoints(world_pos: np.ndarray, hierarchy: SubjointHierarchy, rest_lengths: np.ndarray) -> np.ndarray:
    """Sub-joint positions ``(F, J', 3)`` from original-joint positions ``(F, J, 3)``.

    Original joints stay where they are. Sub-joints in a rubber-joint group
    lie on the group's Bézier curve; the others on the straight link. Each
    frame on its own: a long clip's two halves are made on two cores.
    """
    world_pos = np.asarray(world_pos, dtype=np.float64)
    return by_frame_halves(lambda part: _position_subjoints(world_pos[part], hierarchy, rest_lengths), len(world_pos))


def _position_subjoints(world_pos: np.ndarray, hierarchy: SubjointHierarchy, rest_lengths: np.ndarray) -> np.ndarray:
    frames = world_pos.shape[0]
    count = hierarchy.skeleton.num_joints
    out = np.empty((frames, count, 3))
    out[:, hierarchy.original] = world_pos
    sub = np.flatnonzero(~hierarchy.is_original)
    if not len(sub):
        return out
    # Groups whose original joints are all at one point (zero-length links) have no curve.
    curved = [np.asarray(c) for c in hierarchy.groups if np.sum(rest_lengths[np.asarray(c[1:])] > 0) >= 1]
    in_group = np.zeros(len(sub), bool)
    for chain in curved:
        in_group |= np.isin(hierarchy.link_child[sub], chain[1:])
    straight = sub[~in_group]
    if len(straight):
        f = hierarchy.fraction[straight][:, None]
        out[:, straight] = (1 - f) * world_pos[:, hierarchy.link_parent[straight]] + f * world_pos[
            :, hierarchy.link_child[straight]
        ]
    for chain in curved:
        along = np.concatenate([[0.0], np.cumsum(rest_lengths[chain[1:]])])
        # Joints at the end of a zero-length link coincide with the previous knot: keep the first.
        # (and so do joints a hair away: a 1e-5 link would make a wild tangent).
        knot_mask = np.concatenate([[True], rest_lengths[chain[1:]] > 1e-4 * along[-1]])
        knots = along[knot_mask]
        on_chain = np.isin(hierarchy.link_child[sub], chain[1:])
        members = sub[on_chain]
        if not len(members):
            continue
        index = {int(j): k for k, j in enumerate(chain)}
        child_at = np.array([index[int(c)] for c in hierarchy.link_child[members]])
        params = along[child_at - 1] + hierarchy.fraction[members] * rest_lengths[hierarchy.link_child[members]]
        out[:, members] = bezier_points(world_pos[:, chain[knot_mask]], knots, params)
    return out


def even_out(positions: np.ndarray, hierarchy: SubjointHierarchy, links: np.ndarray, *,
             in_place: bool = False) -> np.ndarray:
    """``positions`` (F, J', 3) with the sub-links of the links ending at ``links`` (original
    joints) made even in length, each keeping its direction (``in_place``: in ``positions`` itself).

    The springs' lag bends a limb (the follow-through) and also bunches its sub-joints along it:
    a middle sub-link stretched 2.3x where its link's chord was 1.85x tore the skin on it. Each
    sub-link is given its share of the chain's length along its own direction, and what that
    leaves between the chain's end and the original joint is spread along it in proportion, so
    the bend and its motion stay as the springs made them (sliding sub-joints along the bent
    polyline instead carried them round its corners: a forearm's sub-joints turned 63-72
    degrees in a frame). The original joints and the start joints do not move.
    """
    out = positions if in_place else positions.copy()
    sub = np.flatnonzero(~hierarchy.is_original & (hierarchy.fraction > 0))
    sub = sub[np.isin(hierarchy.link_child[sub], links)]
    if not len(sub):
        return out
    by_link: dict[int, list[int]] = {}
    for j in sub[np.lexsort((hierarchy.fraction[sub], hierarchy.link_child[sub]))]:
        by_link.setdefault(int(hierarchy.link_child[j]), []).append(int(j))
    by_size: dict[int, list[list[int]]] = {}
    for child, members in by_link.items():
        head = int(hierarchy.original[hierarchy.link_parent[members[0]]])
        by_size.setdefault(len(members), []).append([head, *members, int(hierarchy.original[child])])
    chains = []
    for rows in by_size.values():
        chain = np.array(rows)  # (L, m + 2): head, sub-joints, tail
        fraction = np.concatenate([np.zeros((len(chain), 1)), hierarchy.fraction[chain[:, 1:-1]],
                                   np.ones((len(chain), 1))], axis=1)
        chains.append((chain, fraction, np.diff(fraction, axis=1)[None]))  # share: (1, L, m + 1) of the length

    def even(frames: slice) -> None:  # each frame on its own: a long clip's halves on two cores
        view = out[frames]
        for chain, fraction, share in chains:
            for part in cache_blocks(len(view), chain.size):  # (memory stays flat)
                points = view[part][:, chain]  # (F, L, m + 2, 3); the heads and tails are never moved
                steps = np.diff(points, axis=2)
                lengths = np.sqrt(np.einsum("flkc,flkc->flk", steps, steps))
                scale = np.divide(share * lengths.sum(axis=2, keepdims=True), lengths, out=np.zeros_like(lengths),
                                  where=lengths > 0)
                even = steps * scale[..., None]
                built = np.cumsum(even, axis=2)[:, :, :-1]  # from the head to each sub-joint
                miss = (points[:, :, -1] - points[:, :, 0] - even.sum(axis=2))[:, :, None]
                view[part, chain[:, 1:-1]] = points[:, :, :1] + built + fraction[None, :, 1:-1, None] * miss

    on_both_cores(even, frame_halves(len(out)))
    return out


# ---------------------------------------------------------------------------- the stage


def subjoints_stage(state: State, config: SubjointConfig) -> State:
    """The block: every link cut into sub-links, the sub-joints placed on Bézier curves. Adds ``hierarchy``
    and ``sub_positions``."""
    skeleton = state.motion.skeleton
    hierarchy = build_hierarchy(skeleton, config)
    return replace(state, hierarchy=hierarchy,
                   sub_positions=position_subjoints(state.positions, hierarchy, skeleton.link_lengths()))
