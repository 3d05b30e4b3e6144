"""Finding a humanoid's limbs from joint names and topology.

A limb runs from its base joint to its end effector, as the Stretch-Engine
thesis's distance ruler does: arm = upper-arm joint (the shoulder ball, not
the clavicle) to wrist/hand; leg = thigh to ankle/foot; spine = first spine
joint above the pelvis to the neck base; neck = neck base to head.

The middle joints (elbow, knee) have the least ambiguous names across
exporters (CMU ``LeftForeArm``/``LeftElbow``/``lradius``, Daz ``lForeArm``,
Reallusion ``CC_Base_L_Forearm``, MakeHuman ``LoArm_L``, Rigify
``forearm.L``); the limb is then that joint's parent and its main child.
Left and right come from the names, or from the side of the body.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ..core.rotations import quat_inv, quat_rotate, sum_last, vector_norm
from ..core.skeleton import Skeleton
from ..core.timing import smootherstep

__all__ = ["Limb", "LIMB_NAMES", "find_limbs", "limb_joints", "limb_length", "standing_up", "is_helper", "main_child",
           "hinge_pole", "offset_from_line", "behind_line"]

LIMB_NAMES = ("left_arm", "right_arm", "left_leg", "right_leg", "spine", "neck")

_PREFIX = re.compile(r"^(cc_base_|mixamorig\d*[:_]|def[-_]|bip\d*[ _]|b_|j_)", re.IGNORECASE)
_HELPER = re.compile(r"twist|share|roll|bend|helper|^__|corrective|adjust|nub|end$", re.IGNORECASE)
_ELBOW = re.compile(r"elbow|forearm|radius|loarm|lowerarm|lower_arm|ulna", re.IGNORECASE)
_KNEE = re.compile(r"knee|shin|tibia|calf|loleg|lowerleg|lower_leg|(?<!up)(?<!upper)(?<!upper_)leg$", re.IGNORECASE)
_NECK = re.compile(r"neck", re.IGNORECASE)
_HEAD = re.compile(r"^head$|head$|^head", re.IGNORECASE)


@dataclass(frozen=True)
class Limb:
    """A named chain of joints from ``joints[0]`` (base) to ``joints[-1]`` (end effector)."""

    name: str
    joints: tuple[int, ...]

    @property
    def base(self) -> int:
        return self.joints[0]

    @property
    def end(self) -> int:
        return self.joints[-1]


def _stem(name: str) -> str:
    return _PREFIX.sub("", name)


def _side_from_name(name: str) -> str | None:
    stem = _stem(name)
    low = stem.lower()
    if "left" in low:
        return "left"
    if "right" in low:
        return "right"
    if re.search(r"(^|[_.\s-])[lL]([_.\s-]|$)", stem):
        return "left"
    if re.search(r"(^|[_.\s-])[rR]([_.\s-]|$)", stem):
        return "right"
    if re.match(r"^l[A-Z]", stem) or re.match(r"^L[A-Z]", stem):
        return "left"
    if re.match(r"^r[A-Z]", stem) or re.match(r"^R[A-Z]", stem):
        return "right"
    return None


def is_helper(name: str) -> bool:
    """A twist, share, roll or corrective bone, an end nub or a ``__``-hidden joint: not a limb's bone."""
    return bool(_HELPER.search(name))


def main_child(skeleton: Skeleton, joint: int, sizes: np.ndarray | None = None, *,
               helpers: bool = True) -> int | None:
    """The child that carries the limb on: not a helper, largest subtree, then longest link.

    sizes : (J,) `Skeleton.subtree_sizes`, where the caller has them already
    helpers : where every child is a helper, take the largest of them (else None)
    """
    if sizes is None:
        sizes = skeleton.subtree_sizes()
    children = [c for c in skeleton.children(joint) if not _HELPER.search(skeleton.names[c])]
    if not children and helpers:
        children = list(skeleton.children(joint))
    if not children:
        return None
    lengths = skeleton.link_lengths()
    return max(children, key=lambda c: (sizes[c], lengths[c]))


def _path(skeleton: Skeleton, top: int, bottom: int) -> list[int]:
    """Joints from ``top`` down to ``bottom`` (``top`` must be an ancestor)."""
    chain = [bottom]
    while chain[-1] != top:
        parent = int(skeleton.parents[chain[-1]])
        if parent < 0:
            raise ValueError(f"{skeleton.names[top]} is not above {skeleton.names[bottom]}")
        chain.append(parent)
    return chain[::-1]


def _common_ancestor(skeleton: Skeleton, a: int, b: int) -> int:
    above_a = set(_path(skeleton, 0, a))
    for j in _path(skeleton, 0, b)[::-1]:
        if j in above_a:
            return j
    return 0


def _pair(skeleton: Skeleton, pattern: re.Pattern, lateral: int) -> tuple[int, int] | None:
    """(left, right) joints whose names match ``pattern``, sides from names or position."""
    found = [
        j
        for j, name in enumerate(skeleton.names)
        if j > 0 and pattern.search(_stem(name)) and not _HELPER.search(name)
    ]
    # Keep the highest matching joint of each branch (e.g. "LeftLeg" not a toe below it).
    found = [j for j in found if not any(a in found for a in _path(skeleton, 0, j)[:-1])]
    if len(found) != 2:
        return None
    sides = [_side_from_name(skeleton.names[j]) for j in found]
    if sorted(s or "" for s in sides) != ["left", "right"]:
        rest = skeleton.rest_positions()
        # BVH humanoids face +Z with Y up (or -Y with Z up): the left side is +X.
        order = np.argsort([-rest[j, lateral] for j in found])
        sides = ["left" if k == order[0] else "right" for k in range(2)]
    left = found[sides.index("left")]
    right = found[sides.index("right")]
    return left, right


def find_limbs(skeleton: Skeleton, explicit: dict[str, list[str]] | None = None) -> dict[str, Limb]:
    """Limbs of a humanoid skeleton, by limb name (those of `LIMB_NAMES` that were found).

    ``explicit`` maps limb names to joint-name chains (base to end) for
    skeletons the heuristics do not understand; those win over detection.
    """
    limbs: dict[str, Limb] = {}
    sizes = skeleton.subtree_sizes()
    lateral = 0
    for kind, pattern in (("arm", _ELBOW), ("leg", _KNEE)):
        pair = _pair(skeleton, pattern, lateral)
        if pair is None:
            continue
        for side, middle in zip(("left", "right"), pair):
            base = int(skeleton.parents[middle])
            end = main_child(skeleton, middle, sizes)
            if base <= 0 or end is None:
                continue
            limbs[f"{side}_{kind}"] = Limb(f"{side}_{kind}", (base, middle, end))
    if "left_leg" not in limbs and "right_leg" not in limbs:
        limbs.update(_legs_by_shape(skeleton, limbs, lateral))

    if "left_arm" in limbs and "right_arm" in limbs:
        chest = _common_ancestor(skeleton, limbs["left_arm"].base, limbs["right_arm"].base)
        pelvis = (
            _common_ancestor(skeleton, limbs["left_leg"].base, limbs["right_leg"].base)
            if "left_leg" in limbs and "right_leg" in limbs
            else 0
        )
        torso_root = _common_ancestor(skeleton, pelvis, chest)
        head = _find_head(skeleton, chest, sizes)
        if head is not None:
            up_path = _path(skeleton, torso_root, head)
            neck_base = next(
                (j for j in up_path
                 if j != torso_root and _NECK.search(skeleton.names[j]) and up_path.index(j) > up_path.index(chest)),
                None,
            )
            if neck_base is None:
                after_chest = up_path[up_path.index(chest) + 1 :]
                neck_base = after_chest[0] if len(after_chest) > 1 else None
            if neck_base is not None and len(up_path) > 2:
                spine = up_path[1 : up_path.index(neck_base) + 1]
                if len(spine) >= 2:
                    limbs["spine"] = Limb("spine", tuple(spine))
                neck = up_path[up_path.index(neck_base) :]
                if len(neck) >= 2:
                    limbs["neck"] = Limb("neck", tuple(neck))

    for name, chain in (explicit or {}).items():
        joints = tuple(skeleton.index(n) for n in chain)
        for upper, lower in zip(joints, joints[1:]):
            if upper not in _path(skeleton, 0, lower):
                raise ValueError(f"limb {name}: {skeleton.names[upper]} is not above {skeleton.names[lower]}")
        limbs[name] = Limb(name, joints)
    return {name: limbs[name] for name in sorted(limbs, key=lambda n: (LIMB_NAMES + (n,)).index(n))}


#: A chain stands on the floor when its end rests within this share of the height of the lowest end.
STANDING = 0.15


def _legs_by_shape(skeleton: Skeleton, found: dict[str, Limb], lateral: int) -> dict[str, Limb]:
    """Legs where their names do not say so (a fox's ``b_LeftLeg01_015``), from the rest pose's shape.

    A leg is a chain of at least three joints hanging from a branch joint (hips) to an end that
    rests on the floor: within `STANDING` of the height of the lowest chain end. Chains already
    taken as arms (a quadruped's front legs, named as arms) are not legs again. Exactly two
    left make the pair, sided by which way they lie across the body; the limb is the chain's
    first three joints (hip, knee, ankle), what is below the ankle rides on it as toes do.
    """
    rest = skeleton.rest_positions()
    up = skeleton.up_axis()
    height = max(skeleton.height(), 1e-12)
    children = [list(skeleton.children(j)) for j in range(skeleton.num_joints)]
    chains = []
    for leaf in range(1, skeleton.num_joints):
        if children[leaf] or _HELPER.search(skeleton.names[leaf]):
            continue
        chain = [leaf]
        while skeleton.parents[chain[-1]] > 0 and len(children[skeleton.parents[chain[-1]]]) == 1:
            chain.append(int(skeleton.parents[chain[-1]]))
        chains.append(chain[::-1])
    if not chains:
        return {}
    low = min(rest[c[-1], up] for c in chains)  # rest poses stand along +up (the GLB turns the rest)
    taken = {j for limb in found.values() for j in limb.joints}
    legs = [c for c in chains if len(c) >= 3 and not taken & set(c)
            and rest[c[-1], up] <= low + STANDING * height
            and rest[c[0], up] - rest[c[-1], up] > 0.25 * height]
    if len(legs) != 2:
        return {}
    order = np.argsort([-rest[c[0], lateral] for c in legs])  # +X is the left of a body facing +Z
    return {f"{side}_leg": Limb(f"{side}_leg", tuple(legs[k][:3])) for side, k in zip(("left", "right"), order)}


def standing_ends(skeleton: Skeleton, limbs: dict[str, Limb], heights: np.ndarray | None = None) -> list[int]:
    """The ends the body stands on: the legs', and an arm's whose end goes about as low as theirs
    over the clip (a quadruped's front paws, found as arms; a crawl's hands).

    heights : (F, J) each joint's height above the floor over the clip (up along the ground's
        axis); without them, the legs' ends alone (rest poses cannot tell: iClone's rest has the
        arms and legs pointing up beside the spine)
    """
    feet = [limbs[name].end for name in ("left_leg", "right_leg") if name in limbs]
    if not feet or heights is None or not len(heights):
        return feet
    low = float(np.median(heights[:, feet]))
    more = [limbs[name].end for name in ("left_arm", "right_arm") if name in limbs
            and float(np.median(heights[:, limbs[name].end])) <= low + STANDING * skeleton.height()]
    return feet + more


def _find_head(skeleton: Skeleton, chest: int, sizes: np.ndarray) -> int | None:
    below = set(skeleton.descendants(chest).tolist())
    heads = [j for j in below if _HEAD.search(_stem(skeleton.names[j])) and not _HELPER.search(skeleton.names[j])]
    if heads:
        return min(heads, key=lambda j: skeleton.depth()[j])
    return None


def limb_joints(skeleton: Skeleton, limb: Limb, *, with_descendants: bool = True) -> np.ndarray:
    """Joints a limb moves: its chain, and with ``with_descendants`` all below its end (hand, fingers)."""
    joints = set(limb.joints)
    if with_descendants:
        joints.update(skeleton.descendants(limb.end).tolist())
    return np.array(sorted(joints), dtype=np.int64)


def limb_length(skeleton: Skeleton, limb: Limb) -> float:
    """A limb's full length: the rest lengths of its links, base to end."""
    lengths = skeleton.link_lengths()
    return float(sum(lengths[j] for j in limb.joints[1:]))


def standing_up(skeleton: Skeleton, world: np.ndarray) -> tuple[int, float]:
    """The axis the body stands along (`Skeleton.up_axis`) and its sign: +1 when the head
    is above the feet along it over most of the clip, -1 when below.

    world : (F, J, 3) the clip's world positions (a sample of frames will do).
    Read from the motion, not the rest pose: some rigs (Reallusion) rest with the
    legs pointing up and are turned upright by the root's rotation in every frame.
    """
    axis = skeleton.up_axis()
    limbs = find_limbs(skeleton)
    top = limbs["neck"].end if "neck" in limbs else limbs["spine"].end if "spine" in limbs else None
    feet = [limbs[n].end for n in ("left_leg", "right_leg") if n in limbs]
    if top is None or not feet:
        return axis, 1.0
    height = np.median(world[:, top, axis] - world[:, feet, axis].mean(axis=1))
    return axis, -1.0 if height < 0 else 1.0


def limb_hinges(skeleton: Skeleton, limbs: dict) -> list[tuple[int, ...]]:
    """(base, middle, end) of every arm and leg, and for a leg its longest toe after them."""
    hinges = []
    lengths = skeleton.link_lengths()
    for name, limb in limbs.items():
        if name.endswith(("_arm", "_leg")) and len(limb.joints) >= 3:
            toes = [int(c) for c in skeleton.children(limb.joints[2])] if name.endswith("_leg") else []
            reach = [lengths[c] for c in toes]
            hinges.append(tuple(limb.joints[:3]) + ((toes[int(np.argmax(reach))],) if toes and max(reach) > 0 else ()))
    return hinges


def torso_joints(skeleton: Skeleton, limbs: dict) -> np.ndarray:
    """The torso: the spine chain and everything above it (neck, head, collars, shoulder balls), not the arms.

    With no spine found, the neck chain (and what hangs off it) if there is one.
    """
    base = limbs["spine"].base if "spine" in limbs else limbs["neck"].base if "neck" in limbs else None
    if base is None:
        return np.zeros(0, dtype=np.int64)
    torso = set(skeleton.descendants(base).tolist()) | {base}
    for name, limb in limbs.items():
        if name.endswith("_arm"):  # the arm below its shoulder ball: twist and share bones too
            torso -= set(skeleton.descendants(limb.base).tolist()) - {limb.base}
    return np.array(sorted(torso), dtype=np.int64)


def offset_from_line(base: np.ndarray, middle: np.ndarray, end: np.ndarray) -> np.ndarray:
    """(F, 3) the middle joint's offset from the base-to-end line: where the chain bends, and how far."""
    return _off_line(middle - base, _unit_line(base, end))


def _unit_line(base: np.ndarray, end: np.ndarray) -> np.ndarray:
    line = end - base
    return line / np.maximum(vector_norm(line), 1e-12)[:, None]


def _off_line(vectors: np.ndarray, line: np.ndarray) -> np.ndarray:
    """``vectors`` (F, 3) less their part along the unit ``line`` (F, 3) (the dot products in ``np.sum``'s order)."""
    return vectors - sum_last(vectors * line)[:, None] * line


def hinge_pole(chain: np.ndarray, base_rotation: np.ndarray) -> np.ndarray | None:
    """(F, 3) unit: the side a captured two-bone chain bends to (where a knee or elbow points).

    chain : (F, 3, 3) the captured base, middle and end; base_rotation : (F, 4) the base joint's
    captured world rotation. Where the capture bends clearly it is the capture's own bend; where
    it runs nearly straight (its bend there is noise) the clip's usual bend in the base joint's
    frame, turned with it: a knee is a hinge, it bends the same way in its thigh's frame all clip
    long. None for a chain that never bends.
    """
    own = offset_from_line(chain[:, 0], chain[:, 1], chain[:, 2])
    upper = np.maximum(vector_norm(chain[:, 1] - chain[:, 0]), 1e-12)
    bent = vector_norm(own) / upper
    local = quat_rotate(quat_inv(base_rotation), own)
    usual = np.sum(local * bent[:, None], axis=0)  # weighted by how clearly each frame bends
    if np.linalg.norm(usual) < 1e-9 * len(chain):
        return None
    usual = quat_rotate(base_rotation, np.broadcast_to(usual / np.linalg.norm(usual), own.shape))
    clear = smootherstep((bent - 0.05) / 0.15)[:, None]
    return clear * own / np.maximum(bent * upper, 1e-12)[:, None] + (1.0 - clear) * usual


def behind_line(positions: np.ndarray, joints, pole: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How far a limb's middle joint is behind its base-to-end line (F,) (negative: in front, the way
    ``pole`` (F, 3) points), and the unit way to the front across the line (F, 3)."""
    base, middle, end = (positions[:, j] for j in joints)
    line = _unit_line(base, end)
    offset = _off_line(middle - base, line)
    side = _off_line(pole, line)
    side = side / np.maximum(vector_norm(side, keepdims=True), 1e-12)
    return -sum_last(offset * side), side
