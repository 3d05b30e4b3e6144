"""Binding a character made for another rig to a clip: pair the joints, fit the mesh to the clip's rest pose.

A user's character (the MakeHuman body in its A-pose, Y up, in decimetres; a
GLB exported from Blender) rarely shares the clip's skeleton. `bind_skin`
turns it into a skin on the clip's own joints, in the clip's rest pose, which
is what the rest of the tool takes:

1. **Pair joints** (`pair_joints`). First what the user named (a joint map,
   ``clip joint = skin joint``); then the joints whose *role* both skeletons
   show: hips, spine and neck chains, head, and for each side clavicle, upper
   arm, forearm, hand, hip, thigh, shin, foot and toe, found by the limb
   finder (`mocap_exaggerate.limbs`), so CMU, Daz, iClone, MakeHuman,
   Mixamo, 3ds Max and assimp names pair without a table; spine and neck
   joints pair by where they sit along their chain; last, joints with the
   same name (fingers). Each joint pairs once.
2. **Place** the character over the clip: one scale, rotation and shift
   fitted to the paired trunk joints (Umeyama 1991), which differ little
   between an A-pose and a T-pose. This carries Y-up decimetres onto Z-up
   inches, and the character's front onto the clip's.
3. **Fit each bone.** Every paired clip joint gets an affine map that takes
   its paired skin joint onto it and the next paired joint down its chain
   onto that joint's place: a turn (the smallest one) and a stretch along the
   bone, the stretch held to 0.5-2 times the overall scale. The mesh follows
   by linear blend skinning with the character's own weights; a skin joint
   left unpaired moves with its nearest paired ancestor, and its weight goes
   there. Where neighbouring bones meet, both maps take the joint to the same
   place, so the mesh does not tear.

Why fit the character to the clip and not retarget the clip onto the
character: the clip's motion is what the tool makes, and its promises are
about that motion (the feet stay planted, the BVH written has the clip's
joints, forward kinematics of it gives the positions computed). Retargeting
changes the motion (bone lengths move the feet; contacts slide) before any of
that is measured. So the character takes the performer's bone lengths (an arm
longer by 10 % is 10 % longer in the GLB) and keeps its own girth; a user who
wants the character's proportions retargets in a DCC first and brings that BVH.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from .errors import ConfigError, InputError
from .limbs import find_limbs
from .rotations import quat_between, quat_to_matrix
from .skeleton import Skeleton
from .skinning import Skin, top_influences

__all__ = ["Binding", "joint_roles", "pair_joints", "bind_skin", "skin_skeleton", "read_joint_map", "needs_binding"]

# Roles whose joints sit in the trunk: where an A-pose and a T-pose agree, so the overall placement is fitted to them.
_TRUNK = re.compile(r"^(hips|pelvis|spine\d+|neck\d+|head|(left|right)_(clavicle|upper_arm|thigh))$")
# Roles found but not paired: exporters put the hip joint anywhere from the pelvis's centre (CMU's
# LHipJoint) to beside the thigh (Daz's lButtock), so a bone fitted to it would crush or tear the buttock.
_UNPAIRED = ("left_hip", "right_hip")
_SEGMENT = re.compile(r"\d+")
_HELPER = re.compile(r"twist|share|roll|bend|helper|corrective|adjust|nub|end$", re.IGNORECASE)
AXIAL_LIMIT = 2.0  # a bone stretches or shrinks at most this much beyond the overall scale


@dataclass(frozen=True)
class Binding:
    """How a skin was bound to a clip: the pairs (clip joint -> skin joint) and how each was found."""

    pairs: dict[str, str] = field(default_factory=dict)
    how: dict[str, str] = field(default_factory=dict)  # clip joint -> "map", "role" or "name"
    scale: float = 1.0
    unpaired_roles: tuple[str, ...] = ()

    def summary(self) -> dict:
        counts = {kind: sum(1 for h in self.how.values() if h == kind) for kind in ("map", "role", "name")}
        return {"pairs": len(self.pairs), "by": counts, "scale": round(self.scale, 6),
                "unpaired_roles": list(self.unpaired_roles)}


def _segment_stem(name: str) -> str:
    """A name without its numbers: ``upperarm01.L`` and ``upperarm02.L`` are one bone cut in two."""
    return _SEGMENT.sub("", name).lower()


def _main_child(skeleton: Skeleton, joint: int) -> int | None:
    children = [int(c) for c in skeleton.children(joint) if not _HELPER.search(skeleton.names[c])]
    if not children:
        return None
    return max(children, key=lambda c: (len(skeleton.descendants(c)), skeleton.link_lengths()[c]))


def _chain_top(skeleton: Skeleton, joint: int) -> int:
    """Up from ``joint`` over the segments of the same bone (MakeHuman's upperarm02.L -> upperarm01.L)."""
    while True:
        parent = int(skeleton.parents[joint])
        if parent <= 0 or _segment_stem(skeleton.names[parent]) != _segment_stem(skeleton.names[joint]):
            return joint
        joint = parent


def _chain_bottom(skeleton: Skeleton, joint: int) -> int:
    """Down from a limb's middle over its segments (lowerarm01.L -> lowerarm02.L) to the joint after them."""
    stem = _segment_stem(skeleton.names[joint])
    while True:
        child = _main_child(skeleton, joint)
        if child is None:
            return joint
        if _segment_stem(skeleton.names[child]) != stem:
            return child
        joint = child


def _arc_fractions(rest: np.ndarray, chain: list[int]) -> np.ndarray:
    """Where each joint of a chain sits along it, 0 at the first and 1 at the last (by rest length)."""
    steps = np.linalg.norm(np.diff(rest[chain], axis=0), axis=1)
    along = np.concatenate([[0.0], np.cumsum(steps)])
    return along / along[-1] if along[-1] > 0 else np.linspace(0.0, 1.0, len(chain))


def joint_roles(skeleton: Skeleton) -> tuple[dict[str, int], dict[str, list[int]]]:
    """The joints a humanoid's parts start at, by role, and its spine and neck chains.

    Roles: ``hips``, ``pelvis`` (where the legs branch, when that is not the
    hips), ``head``, and ``left_``/``right_`` + ``clavicle``, ``upper_arm``,
    ``forearm``, ``hand``, ``hip``, ``thigh``, ``shin``, ``foot``, ``toe``.
    Chains: ``spine`` (first joint above the hips up to below the neck) and
    ``neck`` (neck base up to below the head).
    """
    if skeleton.num_joints < 3:
        return {}, {}
    limbs = find_limbs(skeleton)
    roles: dict[str, int] = {}
    parents = skeleton.parents
    for side in ("left", "right"):
        for kind, parts in (("arm", ("upper_arm", "forearm", "hand")), ("leg", ("thigh", "shin", "foot"))):
            limb = limbs.get(f"{side}_{kind}")
            if limb is None:
                continue
            top = _chain_top(skeleton, limb.base)
            middle = limb.joints[1]
            end = _chain_bottom(skeleton, middle)
            if end == middle:
                continue
            roles.update({f"{side}_{parts[0]}": top, f"{side}_{parts[1]}": middle, f"{side}_{parts[2]}": end})
            above = int(parents[top])
            if above > 0:
                roles[f"{side}_{'clavicle' if kind == 'arm' else 'hip'}"] = above
            if kind == "leg":
                toe = _main_child(skeleton, end)
                if toe is not None:
                    roles[f"{side}_toe"] = toe
    chains: dict[str, list[int]] = {}
    spine, neck = limbs.get("spine"), limbs.get("neck")
    if spine is not None:
        hips = int(parents[spine.base])
        roles["hips"] = hips
        chains["spine"] = list(spine.joints[:-1])
        if neck is not None:
            chains["neck"] = list(neck.joints[:-1])
            roles["head"] = neck.end
        if "left_thigh" in roles and "right_thigh" in roles:
            from .limbs import _common_ancestor

            pelvis = _common_ancestor(skeleton, roles["left_thigh"], roles["right_thigh"])
            for side in ("left", "right"):  # a hip joint that is the pelvis itself is no side's own
                if roles.get(f"{side}_hip") == pelvis:
                    del roles[f"{side}_hip"]
            if pelvis != hips:
                roles["pelvis"] = pelvis
    # A clavicle (a hip) is the joint on the way to the arm (leg) that hangs off the trunk: MakeHuman's
    # clavicle.L, not the shoulder01.L below it. One that is a trunk joint itself is no clavicle.
    central = {roles.get("hips"), roles.get("pelvis"), *chains.get("spine", []), *chains.get("neck", [])}
    central.discard(None)
    for role in [f"{side}_{part}" for side in ("left", "right") for part in ("clavicle", "hip")]:
        if role not in roles:
            continue
        joint = roles[role]
        while int(parents[joint]) > 0 and int(parents[joint]) not in central:
            joint = int(parents[joint])
        if joint in central or int(parents[joint]) < 0:
            del roles[role]
        else:
            roles[role] = joint
    return roles, chains


def skin_skeleton(skin: Skin) -> Skeleton | None:
    """The skin's own rig as a `Skeleton` in its bind pose, from ``bind`` and ``parents``; None without them.

    Joints are listed parents first; several roots hang under one added root at the first's place.
    """
    names = [n for n in skin.bind]
    if len(names) < 3 or not skin.parents:
        return None
    known = set(names)
    parent_of = {n: (skin.parents.get(n) if skin.parents.get(n) in known else None) for n in names}
    children: dict[str | None, list[str]] = {}
    for n in names:
        children.setdefault(parent_of[n], []).append(n)
    order: list[str] = []
    stack = list(reversed(children.get(None, [])))
    while stack:
        n = stack.pop()
        order.append(n)
        stack.extend(reversed(children.get(n, [])))
    if len(order) != len(names):  # a loop in the hierarchy: no tree to read roles from
        return None
    roots = children.get(None, [])
    extra = len(roots) > 1
    listed = (["__skin_root__"] if extra else []) + order
    index = {n: k for k, n in enumerate(listed)}
    positions = np.array([np.asarray(skin.bind[n], dtype=np.float64) for n in order])
    if extra:
        positions = np.concatenate([positions[:1], positions])
    parents = np.array([-1 if k == 0 else index.get(parent_of.get(n), 0) for k, n in enumerate(listed)], dtype=np.int64)
    offsets = positions - np.where(parents[:, None] >= 0, positions[np.maximum(parents, 0)], 0.0)
    offsets[0] = positions[0]
    return Skeleton(tuple(listed), parents, offsets, tuple(() for _ in listed), np.full((len(listed), 3), np.nan))


def read_joint_map(path) -> dict[str, str]:
    """A joint map file: one ``clip joint = skin joint`` a line; ``#`` starts a comment.

    Names may hold spaces (``Bip01 L Thigh = thigh.L``). Each clip joint and
    each skin joint may be named once.
    """
    from pathlib import Path

    label = str(path)
    try:
        text = Path(path).read_bytes().decode("utf-8-sig")
    except FileNotFoundError:
        raise InputError("no such joint map file", source=label) from None
    except IsADirectoryError:
        raise InputError("is a folder, not a joint map file", source=label) from None
    except OSError as error:
        raise InputError(f"cannot read ({error.strerror or error})", source=label) from None
    except UnicodeDecodeError:
        raise InputError("not a text file (a joint map has lines 'clip joint = skin joint')", source=label) from None
    pairs: dict[str, str] = {}
    taken: dict[str, int] = {}
    for number, line in enumerate(text.splitlines(), start=1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        clip, sep, skin = (part.strip() for part in line.partition("="))
        if not sep or not clip or not skin or "=" in skin:
            raise InputError(f"expected 'clip joint = skin joint', got {line[:60]!r}", source=label, line=number)
        if clip in pairs:
            raise InputError(f"clip joint {clip!r} is named twice", source=label, line=number)
        if skin in taken:
            raise InputError(f"skin joint {skin!r} is named twice (first on line {taken[skin]})", source=label,
                             line=number)
        pairs[clip] = skin
        taken[skin] = number
    if not pairs:
        raise InputError("no 'clip joint = skin joint' lines", source=label)
    return pairs


def _close(name: str, names) -> str:
    import difflib

    close = difflib.get_close_matches(name, list(names), n=3, cutoff=0.5)
    return f" (close: {', '.join(close)})" if close else ""


def pair_joints(clip: Skeleton, skin: Skin, joint_map: dict[str, str] | None = None) -> Binding:
    """Pairs of clip and skin joints by the user's map, then by role, then by name (see module notes)."""
    pairs: dict[str, str] = {}
    how: dict[str, str] = {}
    bound = set(skin.bind)
    for clip_name, skin_name in (joint_map or {}).items():
        if clip_name not in clip.names:
            raise ConfigError(f"the joint map names {clip_name!r}, which is not a joint of the clip"
                              f"{_close(clip_name, clip.names)}")
        if skin_name not in bound:
            raise ConfigError(f"the joint map names {skin_name!r}, which is not a joint of the skin"
                              f"{_close(skin_name, bound)}")
        pairs[clip_name], how[clip_name] = skin_name, "map"

    def add(clip_name: str, skin_name: str, kind: str) -> None:
        if clip_name not in pairs and skin_name not in pairs.values() and skin_name in bound:
            pairs[clip_name], how[clip_name] = skin_name, kind

    # A skin made for the clip's own rig family (most names shared) pairs by name first: the roles
    # would only pick the same joints, or worse (a toe below a metatarsal). Otherwise roles come first:
    # the same name can mean another joint in another convention (3ds Max's LeftShoulder is CMU's LeftArm).
    same = [n for n in clip.names if n in bound]
    if len(same) >= 0.5 * min(clip.num_joints, len(bound)):
        for name in same:
            add(name, name, "name")
    rig = skin_skeleton(skin)
    unpaired: list[str] = []
    if rig is not None:
        clip_roles, clip_chains = joint_roles(clip)
        skin_roles, skin_chains = joint_roles(rig)
        for role, j in clip_roles.items():
            if role in _UNPAIRED:
                continue
            if role in skin_roles:
                add(clip.names[j], rig.names[skin_roles[role]], "role")
            elif not role.endswith(("toe", "_hip", "pelvis", "clavicle")):
                unpaired.append(role)
        for chain in ("spine", "neck"):
            ours, theirs = clip_chains.get(chain), skin_chains.get(chain)
            if not ours or not theirs:
                continue
            # Each clip joint of the chain takes the skin joint nearest its place along it, measured
            # from the joint below the chain (hips, neck base) to the one above (neck base, head).
            ends = {"spine": ("hips", "neck"), "neck": (None, "head")}[chain]
            def span(skeleton, roles, chains, joints):
                below = roles.get(ends[0]) if ends[0] else None
                above = (chains["neck"][0] if chains.get("neck") else None) if ends[1] == "neck" else roles.get("head")
                full = ([below] if below is not None else []) + joints + ([above] if above is not None else [])
                return _arc_fractions(skeleton.rest_positions(), full)[1 if below is not None else 0:][:len(joints)]
            at = span(clip, clip_roles, clip_chains, ours)
            their_at = span(rig, skin_roles, skin_chains, theirs)
            for j, f in sorted(zip(ours, at), key=lambda pair: pair[1]):
                free = [k for k in range(len(theirs)) if rig.names[theirs[k]] not in pairs.values()]
                if free:
                    k = min(free, key=lambda k: abs(their_at[k] - f))
                    if abs(their_at[k] - f) <= 0.35:
                        add(clip.names[j], rig.names[theirs[k]], "role")
    for name in clip.names:
        if name in bound:
            add(name, name, "name")
    return Binding(pairs, how, 1.0, tuple(unpaired))


def needs_binding(skin: Skin, clip: Skeleton, joint_map: dict | None = None) -> bool:
    """Whether ``skin`` must be fitted to the clip: it has a bind pose that is not the clip's rest pose
    (or its joints are not all the clip's), or the user gave a joint map."""
    if joint_map:
        return True
    if not skin.bind:
        return False
    if any(n not in clip.names for n in skin.joint_names):
        return True
    rest = clip.rest_positions()
    off = [np.linalg.norm(np.asarray(p, dtype=np.float64) - rest[clip.index(n)]) for n, p in skin.bind.items()
           if n in clip.names]
    return not off or max(off) > 1e-3 * clip.height()


def _similarity(source: np.ndarray, target: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Scale, rotation and shift taking points ``source`` onto ``target`` by least squares (Umeyama 1991).

    Points in a plane (a trunk seen from the front) still give a proper
    rotation: the reflection the SVD may suggest is turned back.
    """
    mu_s, mu_t = source.mean(axis=0), target.mean(axis=0)
    a, b = source - mu_s, target - mu_t
    u, singular, vt = np.linalg.svd(b.T @ a / len(a))
    d = np.ones(3)
    d[2] = np.sign(np.linalg.det(u) * np.linalg.det(vt)) or 1.0
    rotation = u @ np.diag(d) @ vt
    spread = np.sum(a * a) / len(a)
    scale = float(np.sum(singular * d) / spread) if spread > 0 else 1.0
    return scale, rotation, mu_t - scale * rotation @ mu_s


def bind_skin(skin: Skin, clip: Skeleton, joint_map: dict[str, str] | None = None) -> tuple[Skin, Binding | None]:
    """``skin`` on ``clip``'s joints in its rest pose, and how it was bound (None when it already was).

    A skin without a bind pose of its own (an ``.npz``) must already be bound
    to the clip's joints in its rest pose; one whose bind pose is the clip's
    rest pose is taken as it is. Any other is fitted (module notes).
    """
    if not needs_binding(skin, clip, joint_map):
        return skin, None
    binding = pair_joints(clip, skin, joint_map)
    if len(binding.pairs) < 3:
        shown = ", ".join(list(skin.bind)[:6]) + (", ..." if len(skin.bind) > 6 else "")
        raise ConfigError(
            f"only {len(binding.pairs)} of the skin's joints could be paired with the clip's (the skin has "
            f"{len(skin.bind)}: {shown}; the clip's root is {clip.names[0]}); name the pairs in a --joint-map "
            "file, one 'clip joint = skin joint' a line")
    rest = clip.rest_positions()
    clip_index = np.array([clip.index(c) for c in binding.pairs], dtype=np.int64)
    bind = np.array([np.asarray(skin.bind[s], dtype=np.float64) for s in binding.pairs.values()])
    roles, _ = joint_roles(clip)
    by_joint = {j: r for r, j in roles.items()}
    chains = joint_roles(clip)[1]
    for k, j in enumerate(chains.get("spine", []) + chains.get("neck", [])):
        by_joint.setdefault(j, f"spine{k}")
    trunk = np.array([bool(_TRUNK.match(by_joint.get(int(j), ""))) for j in clip_index])
    use = trunk if trunk.sum() >= 3 and np.linalg.matrix_rank(rest[clip_index[trunk]] - rest[clip_index[trunk]].mean(0),
                                                             tol=1e-6 * clip.height()) >= 2 else np.ones(len(bind), bool)
    scale, rotation, shift = _similarity(bind[use], rest[clip_index[use]])
    if not (np.isfinite(scale) and scale > 0):
        raise ConfigError("the skin's paired joints all sit in one place; the skin cannot be placed over the clip")
    placed = bind @ (scale * rotation).T + shift

    # One affine map per clip joint: linear part and where it takes the paired skin joint.
    num = clip.num_joints
    linear = np.zeros((num, 3, 3))
    turns = np.zeros((num, 3, 3))
    has = np.zeros(num, bool)
    source = np.zeros((num, 3))
    source[clip_index] = placed
    has_pair = np.zeros(num, bool)
    has_pair[clip_index] = True
    paired_parent = np.full(num, -1)
    for j in range(1, num):
        p = int(clip.parents[j])
        paired_parent[j] = p if has_pair[p] else paired_parent[p]
    central = [roles["hips"]] if "hips" in roles else []
    central += chains.get("spine", []) + chains.get("neck", []) + ([roles["head"]] if "head" in roles else [])
    central = [j for j in central if has_pair[j]]
    floor = 1e-2 * clip.height()
    for j in range(num):
        if not has_pair[j]:
            continue
        kids = [c for c in range(num) if has_pair[c] and paired_parent[c] == j]
        if j in central and central.index(j) + 1 < len(central):
            kids = central[central.index(j) + 1:]  # up the trunk, past joints that sit on this one
        elif len(kids) > 1:
            incoming = rest[j] - rest[paired_parent[j]] if paired_parent[j] >= 0 else None
            if incoming is not None and np.linalg.norm(incoming) > 0:
                kids.sort(key=lambda c: -np.dot(rest[c] - rest[j], incoming) / max(np.linalg.norm(rest[c] - rest[j]), 1e-300))
            else:
                kids.sort(key=lambda c: -len(clip.descendants(c)))
        for c in kids:
            there, here = rest[c] - rest[j], source[c] - source[j]
            if np.linalg.norm(there) > floor and np.linalg.norm(here) > floor:
                axis = here / np.linalg.norm(here)
                stretch = np.clip(np.linalg.norm(there) / np.linalg.norm(here), 1 / AXIAL_LIMIT, AXIAL_LIMIT)
                turns[j] = quat_to_matrix(quat_between(here, there))
                linear[j] = turns[j] @ (np.eye(3) + (stretch - 1.0) * np.outer(axis, axis))
                has[j] = True
                break
    for j in range(num):  # a bone with no paired joint below it (a head, a hand) turns as the one above, unstretched
        if has_pair[j] and not has[j]:
            p = paired_parent[j]
            turns[j] = turns[p] if p >= 0 else np.eye(3)
            linear[j] = turns[j]
            has[j] = True
    # y -> rest[j] + linear[j] @ (y - source[j]) as a 3x4 matrix
    affine = np.concatenate([linear, (rest - np.einsum("jab,jb->ja", linear, source))[:, :, None]], axis=2)

    # Every skin joint's weight goes to its partner, else its nearest paired ancestor, else the nearest paired joint.
    partner = {s: clip.index(c) for c, s in binding.pairs.items()}
    target = np.empty(len(skin.joint_names), dtype=np.int64)
    for k, name in enumerate(skin.joint_names):
        up = name
        while up is not None and up not in partner:
            up = skin.parents.get(up)
        if up is not None:
            target[k] = partner[up]
        elif name in skin.bind:
            near = np.argmin(np.linalg.norm(bind - np.asarray(skin.bind[name], dtype=np.float64), axis=1))
            target[k] = clip_index[near]
        else:
            target[k] = clip_index[0]
    joints = target[skin.joints]
    vertices = skin.vertices @ (scale * rotation).T + shift
    blended = np.einsum("vk,vkab->vab", skin.weights, affine[joints])
    vertices = np.einsum("vab,vb->va", blended[:, :, :3], vertices) + blended[:, :, 3]
    rows = np.repeat(np.arange(skin.num_vertices), skin.joints.shape[1])
    used = np.unique(joints[skin.weights > 0])
    column = np.full(num, -1)
    column[used] = np.arange(len(used))
    top_j, top_w = top_influences(rows, column[joints].ravel(), skin.weights.ravel(), skin.num_vertices,
                                  skin.joints.shape[1])
    bound = Skin(vertices, skin.faces, tuple(clip.names[j] for j in used), top_j, top_w)
    return bound, Binding(binding.pairs, binding.how, scale, binding.unpaired_roles)
