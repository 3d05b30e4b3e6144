"""What rides on what: minor branches, the joints riding rigidly, rubber groups, the link that turns a joint.

Found on the skeleton alone. The sub-joint block cuts only what is not a
minor branch, the springs and orientation recovery carry riders rigidly,
and the contacts block predicts how orientation recovery will turn an end
effector (`incoming_joint`) from the same functions, so the two cannot drift.
"""

from __future__ import annotations

import functools
import re

import numpy as np

from ..core.errors import ConfigError
from ..core.skeleton import Skeleton
from .limbs import find_limbs

__all__ = [
    "minor_branches",
    "riders",
    "rider_joints",
    "rubber_groups",
    "incoming_joint",
    "effective_lengths",
    "first_below_at_distance",
    "first_above_at_distance",
    "MINOR_REACH",
]


#: Names of branches that never carry a rubber limb: digits, face, helpers.
_MINOR_NAME = re.compile(
    r"finger|thumb|index|middle|ring|pinky|toe|eye|jaw|tongue|teeth|facial|twist|share|^__|nub$|_end$",
    re.IGNORECASE,
)
#: A side branch whose reach is under this share of its longest sibling's is minor.
MINOR_REACH = 0.35


def minor_branches(skeleton: Skeleton, extra_rigid: tuple[str, ...] = ()) -> np.ndarray:
    """(J,) bool: joints on minor branches, which ride rigidly on their parent.

    Pruned: everything below a found arm or leg end (hands' fingers, feet's
    toes); subtrees named like fingers, toes, eyes, jaws, twist or share bones
    or helpers, unless they lead to a limb; side branches much shorter than
    their longest sibling (the same limb-guard applies); ``extra_rigid``
    patterns.
    """
    count = skeleton.num_joints
    limbs = find_limbs(skeleton)
    protected = np.zeros(count, bool)
    for limb in limbs.values():
        for j in limb.joints:
            protected[skeleton.ancestors(j)] = True
    rigid = np.zeros(count, bool)
    for name, limb in limbs.items():
        if name.endswith(("_arm", "_leg")):
            below = skeleton.descendants(limb.end)[1:]
            rigid[below] = True
    # Each branch's reach from its parent, and the longest among each joint's children: once,
    # not per joint (a root with thousands of children made this quadratic).
    through = _reach(skeleton) + skeleton.link_lengths()
    parents = skeleton.parents
    longest = np.zeros(count)
    np.maximum.at(longest, parents[1:], through[1:])
    siblings = np.bincount(parents[1:], minlength=count)
    minor = np.zeros(count, bool)
    for j in range(1, count):
        if protected[j]:
            continue
        if _MINOR_NAME.search(skeleton.names[j]):
            minor[j] = True
        elif siblings[parents[j]] > 1 and through[j] < MINOR_REACH * longest[parents[j]]:
            minor[j] = True
    # A minor joint takes its whole subtree with it (parents come before children).
    for j in range(1, count):
        rigid[j] |= minor[j] or rigid[parents[j]] and not protected[j]
    for pattern in extra_rigid:
        matched = skeleton.match(pattern)
        if not len(matched):
            raise ConfigError(f"subjoints.rigid: no joint matches {pattern!r}")
        for j in matched:
            rigid[skeleton.descendants(int(j))] = True
    rigid[0] = False
    return rigid


def _reach(skeleton: Skeleton) -> np.ndarray:
    """Longest rest path from each joint down to a leaf or End Site, ``(J,)``."""
    lengths = skeleton.link_lengths()
    ends = np.where(np.isfinite(skeleton.end_sites[:, 0]), np.linalg.norm(np.nan_to_num(skeleton.end_sites), axis=1), 0.0)
    reach = ends.copy()
    for j in range(skeleton.num_joints - 1, 0, -1):
        p = skeleton.parents[j]
        reach[p] = max(reach[p], reach[j] + lengths[j])
    return reach


def riders(skeleton: Skeleton, rigid: np.ndarray) -> dict[int, list[int]]:
    """Joint -> the rigid joints riding on it: those whose nearest non-rigid ancestor it is
    (toes on a foot, fingers on a hand; a hip has none, though toes hang far below it)."""
    out: dict[int, list[int]] = {}
    for j in np.flatnonzero(rigid):
        p = int(skeleton.parents[j])
        while p > 0 and rigid[p]:
            p = int(skeleton.parents[p])
        out.setdefault(p, []).append(int(j))
    return out


def rubber_groups(skeleton: Skeleton, rigid: np.ndarray) -> tuple[tuple[int, ...], ...]:
    """Chains of original joints that bend as one rubber hose.

    Each chain runs from the joint it hangs from (a branch joint, or the root)
    down to an end effector of the pruned tree.
    """
    kept_children = [[int(c) for c in skeleton.children(j) if not rigid[c]] for j in range(skeleton.num_joints)]
    groups = []
    for end in range(1, skeleton.num_joints):
        if rigid[end] or kept_children[end]:
            continue
        chain = [end]
        joint = end
        while skeleton.parents[joint] > 0 and len(kept_children[skeleton.parents[joint]]) == 1:
            joint = int(skeleton.parents[joint])
            chain.append(joint)
        chain.append(int(skeleton.parents[joint]))  # the branch joint the group hangs from
        groups.append(tuple(chain[::-1]))
    return tuple(groups)


def effective_lengths(skeleton) -> np.ndarray:
    """Rest link lengths, with links under 1e-4 of the skeleton height counted as zero.

    Some rigs park a joint a hair from its parent (Reallusion's pelvis sits
    1e-5 cm from the hip); its direction means nothing.
    """
    lengths = skeleton.link_lengths()
    return np.where(lengths < 1e-4 * skeleton.height(), 0.0, lengths)


def first_below_at_distance(skeleton, joint: int, rigid: np.ndarray, lengths: np.ndarray) -> list[int]:
    """For each kept child branch of ``joint``, the first joint down it at non-zero rest distance."""
    out = []
    for child in skeleton.children(joint):
        if rigid[child]:
            continue
        current = int(child)
        while lengths[current] <= 0:
            below = [int(c) for c in skeleton.children(current) if not rigid[c]]
            if len(below) != 1:
                break
            current = below[0]
        if lengths[current] > 0 or current != child:
            out.append(current)
    return out


def first_above_at_distance(skeleton, joint: int, lengths: np.ndarray) -> int:
    """The first joint above ``joint`` at non-zero rest distance from it; -1 when there is none."""
    current = joint
    while current > 0 and lengths[current] <= 0:
        current = int(skeleton.parents[current])
    return int(skeleton.parents[current]) if current > 0 else -1


def incoming_joint(skeleton, joint: int) -> int:
    """The joint whose link into ``joint`` turns it when it ends a chain (zero-length links
    looked through); -1 when there is none."""
    return first_above_at_distance(skeleton, joint, effective_lengths(skeleton))


@functools.lru_cache(maxsize=16)
def rider_joints(skeleton: Skeleton) -> dict[int, list[int]]:
    """Joint -> the joints of minor branches riding rigidly on it (toes on a foot, fingers on a hand).

    Found once per skeleton (three stages ask); the mapping is shared, so read it, do not change it.
    """
    return riders(skeleton, minor_branches(skeleton))
