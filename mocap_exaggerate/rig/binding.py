"""Binding a character made for another rig to a clip: pair the joints, pose the clip like it, fit the mesh.

A user's character (the MakeHuman body in its A-pose, Y up, in decimetres; a
GLB exported from Blender) rarely shares the clip's skeleton. `bind_skin`
turns it into a skin on the clip's own joints, with the clip's limbs posed like
the character's, which is what the rest of the tool takes:

1. **Pair joints** (`pair_joints`). First what the user named (a joint map,
   ``clip joint = skin joint``); then the joints whose *role* both skeletons
   show: hips, spine and neck chains, head, and for each side clavicle, upper
   arm, forearm, hand, hip, thigh, shin, foot and toe, found by the limb
   finder (`mocap_exaggerate.analysis.limbs`), so CMU, Daz, iClone, MakeHuman,
   Mixamo, 3ds Max and assimp names pair without a table; spine and neck
   joints pair by where they sit along their chain; last, joints with the
   same name (fingers). Each joint pairs once.
2. **Place** the character over the clip: one scale, rotation and shift
   fitted to the paired trunk joints (Umeyama 1991), which differ little
   between an A-pose and a T-pose. This carries Y-up decimetres onto Z-up
   inches, and the character's front onto the clip's.
3. **Pose the clip like the character** (`_limb_pose`), where a limb of its rest
   points more than `POSE_TURN` from the character's. Each paired limb joint
   of the clip turns so its bone points along the character's; the trunk, which
   the placement is fitted to, does not. The fitted skin carries that pose
   (`Skin.pose`), and the outputs take it as the skeleton's rest
   (`mocap_exaggerate.jobs.outputs.at_bind_pose`). A rig resting with every
   bone along one axis (iClone: legs and arms straight up) otherwise had each
   leg's map turn the mesh 170 degrees, and blend skinning pinched the hips and
   shoulders shut as the legs came down.
4. **Fit each bone** to that pose. Every paired clip joint gets an affine map that takes
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

from ..analysis.limbs import find_limbs, main_child
from ..core.errors import ConfigError, InputError
from ..core.kinematics import parent_rotations
from ..core.rotations import quat_between, quat_identity, quat_inv, quat_mul, quat_rotate, quat_to_matrix
from ..core.skeleton import Skeleton
from .skinning import Skin, top_influences

__all__ = ["Binding", "joint_roles", "pair_joints", "bind_skin", "bind_skin_to_clip", "skin_skeleton", "read_joint_map",
           "needs_binding"]

# Roles whose joints sit in the trunk: where an A-pose and a T-pose agree, so the overall placement is fitted to them.
_TRUNK = re.compile(r"^(hips|pelvis|spine\d+|neck\d+|head|(left|right)_(clavicle|upper_arm|thigh))$")
# Roles found but not paired: exporters put the hip joint anywhere from the pelvis's centre (CMU's
# LHipJoint) to beside the thigh (Daz's lButtock), so a bone fitted to it would crush or tear the buttock.
_UNPAIRED = ("left_hip", "right_hip")
_SEGMENT = re.compile(r"\d+")
_SUBJOINT = re.compile(r"^(.*)_s\d+$")
AXIAL_LIMIT = 2.0  # a bone stretches or shrinks at most this much beyond the overall scale
POSE_TURN = 90.0  # degrees: a clip's limb bone pointing farther than this from the character's is posed to it


@dataclass(frozen=True)
class Binding:
    """How a skin was bound to a clip: the pairs (clip joint -> skin joint) and how each was found."""

    pairs: dict[str, str] = field(default_factory=dict)
    how: dict[str, str] = field(default_factory=dict)  # clip joint -> "map", "role" or "name"
    scale: float = 1.0
    unpaired_roles: tuple[str, ...] = ()
    posed: int = 0  # clip joints turned to pose its limbs like the character's (`Skin.pose`)

    def summary(self) -> dict:
        counts = {kind: sum(1 for h in self.how.values() if h == kind) for kind in ("map", "role", "name")}
        return {"pairs": len(self.pairs), "by": counts, "scale": round(self.scale, 6),
                "unpaired_roles": list(self.unpaired_roles), "posed_joints": self.posed}


def _segment_stem(name: str) -> str:
    """A name without its numbers: ``upperarm01.L`` and ``upperarm02.L`` are one bone cut in two."""
    return _SEGMENT.sub("", name).lower()


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
        child = main_child(skeleton, joint, helpers=False)
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
    from ..analysis.limbs import _common_ancestor

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
                toe = main_child(skeleton, end, helpers=False)
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
    every = set(skin.bind)
    # The sub-joints of a GLB this tool wrote (``lShin_s1`` on the link that ends at lShin) are pieces of
    # their link, not joints of the rig: left out, they ride (and give their weight to) the joint above.
    names = [n for n in skin.bind if not (_SUBJOINT.match(n) and _SUBJOINT.match(n).group(1) in every)]
    if len(names) < 3 or not skin.parents:
        return None
    known = set(names)

    def kept_parent(name: str) -> str | None:
        up = skin.parents.get(name)
        while up is not None and up not in known:
            up = skin.parents.get(up) if up in every else None
        return up

    parent_of = {n: kept_parent(n) for n in names}
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

    from ..io.files import LIMITS, read_limited

    label = str(path)
    try:
        text = read_limited(Path(path), limit=LIMITS["text"], what="joint map file", label=label).decode("utf-8-sig")
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
            raise InputError(f"clip joint {_shown(clip)} is named twice", source=label, line=number)
        if skin in taken:
            raise InputError(f"skin joint {_shown(skin)} is named twice (first on line {taken[skin]})", source=label,
                             line=number)
        pairs[clip] = skin
        taken[skin] = number
    if not pairs:
        raise InputError("no 'clip joint = skin joint' lines", source=label)
    return pairs


def _shown(name: str) -> str:
    """A name as a message quotes it: its repr, cut short when it is very long."""
    return repr(name) if len(name) <= 60 else repr(name[:57]) + "..."


def _close(name: str, names) -> str:
    import difflib

    close = difflib.get_close_matches(name, list(names), n=3, cutoff=0.5) if len(name) <= 200 else []
    return f" (close: {', '.join(close)})" if close else ""


def _chain_fractions(skeleton: Skeleton, roles: dict, chains: dict, chain: str) -> np.ndarray:
    """Where each joint of the spine (neck) chain sits along it, measured from the joint below the
    chain (hips; the neck base itself) to the one above (neck base; head)."""
    joints = chains[chain]
    below = roles.get("hips") if chain == "spine" else None
    above = (chains["neck"][0] if chains.get("neck") else None) if chain == "spine" else roles.get("head")
    full = ([below] if below is not None else []) + joints + ([above] if above is not None else [])
    return _arc_fractions(skeleton.rest_positions(), full)[1 if below is not None else 0:][:len(joints)]


#: Roles every humanoid shows; one left unpaired is reported (toes, clavicles and the pelvis may be missing).
_MAIN_ROLES = re.compile(r"^(hips|head|(left|right)_(upper_arm|forearm|hand|thigh|shin|foot))$")


def pair_joints(clip: Skeleton, skin: Skin, joint_map: dict[str, str] | None = None,
                roles: tuple[dict, dict] | None = None) -> Binding:
    """Pairs of clip and skin joints by the user's map, then by role, then by name (see module notes).

    roles : `joint_roles` of the clip, when the caller has it already
    """
    if joint_map and not skin.bind:
        raise ConfigError("a joint map pairs joints by where they sit, and this skin (an .npz) has no bind pose "
                          "of its own: bind it to the clip's joints in its rest pose, or bring a GLB or MakeHuman "
                          "character")
    pairs: dict[str, str] = {}
    how: dict[str, str] = {}
    known = set(skin.bind)
    clip_names = set(clip.names)
    for clip_name, skin_name in (joint_map or {}).items():
        if clip_name not in clip_names:
            raise ConfigError(f"the joint map names {_shown(clip_name)}, which is not a joint of the clip"
                              f"{_close(clip_name, clip.names)}")
        if skin_name not in known:
            raise ConfigError(f"the joint map names {_shown(skin_name)}, which is not a joint of the skin"
                              f"{_close(skin_name, known)}")
        pairs[clip_name], how[clip_name] = skin_name, "map"
    taken = set(pairs.values())

    def add(clip_name: str, skin_name: str, kind: str) -> None:
        if clip_name not in pairs and skin_name not in taken and skin_name in known:
            pairs[clip_name], how[clip_name] = skin_name, kind
            taken.add(skin_name)

    # A skin made for the clip's own rig family (most names shared) pairs by name first: the roles
    # would only pick the same joints, or worse (a toe below a metatarsal). Otherwise roles come first:
    # the same name can mean another joint in another convention (3ds Max's LeftShoulder is CMU's LeftArm).
    same = [n for n in clip.names if n in known]
    if len(same) >= 0.5 * min(clip.num_joints, len(known)):
        for name in same:
            add(name, name, "name")
    clip_roles, clip_chains = roles if roles is not None else joint_roles(clip)
    rig = skin_skeleton(skin)
    if rig is not None:
        skin_roles, skin_chains = joint_roles(rig)
        for role, j in clip_roles.items():
            if role not in _UNPAIRED and role in skin_roles:
                add(clip.names[j], rig.names[skin_roles[role]], "role")
        for chain in ("spine", "neck"):
            ours, theirs = clip_chains.get(chain), skin_chains.get(chain)
            if not ours or not theirs:
                continue
            # Each clip joint of the chain takes the free skin joint nearest its place along it.
            at = _chain_fractions(clip, clip_roles, clip_chains, chain)
            their_at = _chain_fractions(rig, skin_roles, skin_chains, chain)
            for j, f in sorted(zip(ours, at), key=lambda pair: pair[1]):
                free = [k for k in range(len(theirs)) if rig.names[theirs[k]] not in taken]
                if free:
                    k = min(free, key=lambda k: abs(their_at[k] - f))
                    if abs(their_at[k] - f) <= 0.35:
                        add(clip.names[j], rig.names[theirs[k]], "role")
    for name in same:  # what is left of the same names (fingers, when the roles came first)
        add(name, name, "name")
    unpaired = tuple(role for role, j in clip_roles.items() if _MAIN_ROLES.match(role) and clip.names[j] not in pairs)
    return Binding(pairs, how, 1.0, unpaired)


def needs_binding(skin: Skin, clip: Skeleton, joint_map: dict | None = None) -> bool:
    """Whether ``skin`` must be fitted to the clip: it has a bind pose that is not the clip's rest pose
    (or its joints are not all the clip's), or the user gave a joint map."""
    if joint_map:
        return True
    if not skin.bind:
        return False
    names = set(clip.names)
    if any(n not in names for n in skin.joint_names):
        return True
    rest = clip.rest_positions()
    off = [np.linalg.norm(np.asarray(p, dtype=np.float64) - rest[clip.index(n)]) for n, p in skin.bind.items()
           if n in names]
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
    """``skin`` on ``clip``'s joints, posed like it (``Skin.pose``), and how it was bound (None when it already was).

    A skin without a bind pose of its own (an ``.npz``) must already be bound
    to the clip's joints in its rest pose; one whose bind pose is the clip's
    rest pose is taken as it is. Any other is fitted (module notes).
    """
    if not needs_binding(skin, clip, joint_map):
        missing = [n for n in (*skin.joint_names, *skin.pose) if n not in clip.names]
        if missing:  # (said here, where the caller names the file, not deep in the re-weighting)
            shown = ", ".join(_shown(n) for n in dict.fromkeys(missing[:5]))
            raise ConfigError(f"names joints the clip does not have ({shown}{', ...' if len(missing) > 5 else ''}): a "
                              "skin with no bind pose of its own (an .npz) must be made for this clip's skeleton, as "
                              "a run's weights file is for the BVH it wrote; bring a GLB or MakeHuman character to "
                              "bind to another")
        return skin, None
    roles, chains = joint_roles(clip)
    binding = pair_joints(clip, skin, joint_map, (roles, chains))
    if len(binding.pairs) < 3:
        shown = ", ".join(list(skin.bind)[:6]) + (", ..." if len(skin.bind) > 6 else "")
        raise ConfigError(
            f"only {len(binding.pairs)} of the skin's joints could be paired with the clip's (the skin has "
            f"{len(skin.bind)}: {shown}; the clip's root is {clip.names[0]}); name the pairs in a --joint-map "
            "file, one 'clip joint = skin joint' a line")
    rest = clip.rest_positions()
    height = clip.height()
    clip_index = np.array([clip.index(c) for c in binding.pairs], dtype=np.int64)
    bind = np.array([np.asarray(skin.bind[s], dtype=np.float64) for s in binding.pairs.values()])
    scale, rotation, shift = _placement(skin, bind, rest[clip_index], clip_index, roles, chains, height)
    placed = bind @ (scale * rotation).T + shift
    pose = _limb_pose(clip, rest, clip_index, placed, roles, chains)
    posed = clip.posed(pose)[0]
    rest = posed.rest_positions()  # (the trunk is not turned, so the placement on it holds)
    affine = _bone_maps(posed, rest, clip_index, placed, roles, chains)

    # Every skin joint's weight goes to its partner, else its nearest paired ancestor, else the
    # nearest paired joint (or, with no place to go by, the paired joint nearest the clip's root).
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
            target[k] = clip_index.min()
    joints = target[skin.joints]
    vertices = skin.vertices @ (scale * rotation).T + shift
    blended = np.einsum("vk,vkab->vab", skin.weights, affine[joints])
    vertices = np.einsum("vab,vb->va", blended[:, :, :3], vertices) + blended[:, :, 3]
    weighted = skin.weights > 0
    rows = np.repeat(np.arange(skin.num_vertices), skin.joints.shape[1]).reshape(skin.joints.shape)[weighted]
    used = np.unique(joints[weighted])
    column = np.full(clip.num_joints, -1)
    column[used] = np.arange(len(used))
    top_j, top_w = top_influences(rows, column[joints[weighted]], skin.weights[weighted], skin.num_vertices,
                                  skin.joints.shape[1])
    turned = {clip.names[j]: tuple(map(float, pose[j])) for j in range(clip.num_joints) if pose[j, 3] < 1.0}
    fitted = Skin(vertices, skin.faces, tuple(clip.names[j] for j in used), top_j, top_w, pose=turned)
    return fitted, Binding(binding.pairs, binding.how, scale, binding.unpaired_roles, len(turned))


def _limb_pose(clip: Skeleton, rest: np.ndarray, clip_index: np.ndarray, placed: np.ndarray, roles: dict,
               chains: dict) -> np.ndarray:
    """Local rotations ``(J, 4)`` posing the clip's limbs like the placed character's, where they
    point another way.

    Where a limb bone of the clip's rest (`_bones`) points more than `POSE_TURN` away from the
    character's, each paired limb joint (not the trunk's: the placement is fitted to it)
    turns, by the smallest turn, to point its bone where the character's does; every other
    joint keeps its orientation in its parent. The character is then fitted to that pose,
    where its bones need no turn, only a stretch: bound to a rest pose with every bone along
    one axis (iClone, Reallusion CC: legs and arms straight up), each leg's map turned it by
    170 degrees, and linear blend skinning pinched the hips and shoulders shut as the legs
    and arms came back down. A rig whose limbs are all nearer (a T-pose rig and an A-pose
    character: 45-70 degrees at the arms) is fitted as it rests (the identity pose): posed,
    its mesh tore a little less on some rigs and a little more on others (`bench/binding.py`),
    and its GLB's rest would no longer be the clip's.
    """
    source = np.zeros((clip.num_joints, 3))
    source[clip_index] = placed
    aims = {j: c for j, c, _, trunk in _bones(clip, rest, clip_index, source, roles, chains)
            if c is not None and not trunk}
    world = np.tile(quat_identity(), (clip.num_joints, 1))
    apart = [np.dot(rest[c] - rest[j], source[c] - source[j])
             / (np.linalg.norm(rest[c] - rest[j]) * np.linalg.norm(source[c] - source[j])) for j, c in aims.items()]
    if not apart or min(apart) >= np.cos(np.radians(POSE_TURN)):
        return world  # every limb within POSE_TURN of the character's: fitted as it rests
    for j in range(clip.num_joints):
        above = world[clip.parents[j]] if j else quat_identity()
        world[j] = above
        if j in aims:
            c = aims[j]
            world[j] = quat_mul(quat_between(quat_rotate(above, rest[c] - rest[j]), source[c] - source[j]), above)
    local = quat_mul(quat_inv(parent_rotations(clip.parents, world)), world)
    local *= np.where(local[:, 3:] < 0.0, -1.0, 1.0)
    local[np.all(np.abs(local[:, :3]) <= 1e-12, axis=1)] = quat_identity()
    return local


def _placement(skin: Skin, bind: np.ndarray, rest: np.ndarray, clip_index: np.ndarray, roles: dict, chains: dict,
               height: float) -> tuple[float, np.ndarray, np.ndarray]:
    """The similarity placing the character over the clip, fitted to the paired trunk joints (all pairs
    when fewer than three trunk joints span a plane). ConfigError when the pairs cannot place it."""
    by_joint = {j: r for r, j in roles.items()}
    for k, j in enumerate(chains.get("spine", []) + chains.get("neck", [])):
        by_joint.setdefault(j, f"spine{k}")
    trunk = np.array([bool(_TRUNK.match(by_joint.get(int(j), ""))) for j in clip_index])

    def spans_a_plane(points: np.ndarray, size: float) -> bool:
        return len(points) >= 3 and np.linalg.matrix_rank(points - points.mean(axis=0), tol=1e-3 * size) >= 2

    use = trunk if spans_a_plane(rest[trunk], height) else np.ones(len(bind), bool)
    size = float(np.ptp(skin.vertices, axis=0).max()) or 1.0
    if np.ptp(bind[use], axis=0).max() <= 1e-6 * size:
        raise ConfigError("the skin's paired joints all sit in one place, so the skin cannot be placed over the "
                          "clip (are its inverse bind matrices or joint positions all the same?)")
    if not (spans_a_plane(rest[use], height) and spans_a_plane(bind[use], size)):
        raise ConfigError(f"the {int(use.sum())} paired joints lie on one line, so the skin's turn about it is "
                          "unknown: pair more joints (arms, legs) in a --joint-map file")
    return _similarity(bind[use], rest[use])


def _bones(clip: Skeleton, rest: np.ndarray, clip_index: np.ndarray, source: np.ndarray, roles: dict,
           chains: dict) -> list[tuple[int, int | None, list[int], bool]]:
    """Each paired joint (in order), the paired joint its bone runs to (None: no usable one), its
    other paired branches and whether it is in the trunk: up the trunk (past joints that sit on it) for the hips, spine and neck,
    else the paired child that goes on most straight from the bone coming in (the biggest subtree
    at the root). ``source (J, 3)`` holds the skin's joints placed at their clip partners."""
    num = clip.num_joints
    has_pair = np.zeros(num, bool)
    has_pair[clip_index] = True
    paired_parent = np.full(num, -1)
    below: dict[int, list[int]] = {}
    for j in range(1, num):
        p = int(clip.parents[j])
        paired_parent[j] = p if has_pair[p] else paired_parent[p]
        if has_pair[j] and paired_parent[j] >= 0:
            below.setdefault(int(paired_parent[j]), []).append(j)
    central = [roles["hips"]] if "hips" in roles else []
    central += chains.get("spine", []) + chains.get("neck", []) + ([roles["head"]] if "head" in roles else [])
    central = [j for j in central if has_pair[j]]
    floor = 1e-2 * clip.height()
    sizes = clip.subtree_sizes()

    def usable(j: int, c: int) -> bool:
        return np.linalg.norm(rest[c] - rest[j]) > floor and np.linalg.norm(source[c] - source[j]) > floor

    bones = []
    for j in map(int, np.sort(clip_index)):
        kids = list(below.get(j, []))
        if j in central and central.index(j) + 1 < len(central):
            ahead = central[central.index(j) + 1:]  # up the trunk, past joints that sit on this one
            primary = next((c for c in ahead if usable(j, c)), None)
            branches = [c for c in kids if c not in central]
        else:
            incoming = rest[j] - rest[paired_parent[j]] if paired_parent[j] >= 0 else None
            if incoming is not None and np.linalg.norm(incoming) > 0:
                kids.sort(key=lambda c: -np.dot(rest[c] - rest[j], incoming) / max(np.linalg.norm(rest[c] - rest[j]), 1e-300))
            else:
                kids.sort(key=lambda c: -sizes[c])
            primary = next((c for c in kids if usable(j, c)), None)
            branches = kids
        others = [c for c in branches if c != primary and usable(j, c)] if primary is not None else []
        bones.append((j, primary, others, j in central))
    return bones


def _bone_maps(clip: Skeleton, rest: np.ndarray, clip_index: np.ndarray, placed: np.ndarray, roles: dict,
               chains: dict) -> np.ndarray:
    """One affine map ``(J, 3, 4)`` per clip joint taking the placed skin onto the clip's rest pose.

    A paired joint's map takes its skin joint onto the clip's and turns (the smallest turn) and
    stretches (along the bone, 0.5-2x) the bone to the next paired joint up the trunk or down the
    limb onto the clip's (`_bones`). Where a joint branches (hips to spine and thighs, chest to neck and
    collars), the map is then fitted to every branch by least squares, held near that turn and
    stretch in the directions the branches do not span, so each branch's start lands where the
    clip has it and the mesh between them does not tear. A joint with no paired joint below it
    (a head, a hand) turns as its parent, unstretched.
    """
    num = clip.num_joints
    source = np.zeros((num, 3))
    source[clip_index] = placed
    linear = np.tile(np.eye(3), (num, 1, 1))
    turns = np.tile(np.eye(3), (num, 1, 1))
    fitted = np.zeros(num, bool)
    bones = _bones(clip, rest, clip_index, source, roles, chains)
    for j, primary, others, _ in bones:
        if primary is None:
            continue
        there, here = rest[primary] - rest[j], source[primary] - source[j]
        axis = here / np.linalg.norm(here)
        stretch = np.clip(np.linalg.norm(there) / np.linalg.norm(here), 1 / AXIAL_LIMIT, AXIAL_LIMIT)
        turns[j] = quat_to_matrix(quat_between(here, there))
        linear[j] = turns[j] @ (np.eye(3) + (stretch - 1.0) * np.outer(axis, axis))
        fitted[j] = True
        if others:
            ends = [primary] + others
            h = source[ends] - source[j]
            t = rest[ends] - rest[j]
            hold = 0.5 * np.mean(np.sum(h * h, axis=1))
            solved = (t.T @ h + hold * linear[j]) @ np.linalg.inv(h.T @ h + hold * np.eye(3))
            spread = np.linalg.svd(solved, compute_uv=False)
            if spread.max() <= AXIAL_LIMIT * 1.25 and spread.min() >= 1 / (AXIAL_LIMIT * 1.25) and np.linalg.det(solved) > 0:
                linear[j] = solved
    has_pair = np.zeros(num, bool)
    has_pair[clip_index] = True
    for j, *_ in bones:
        if not fitted[j]:
            p = int(clip.parents[j])
            while p >= 0 and not has_pair[p]:
                p = int(clip.parents[p])
            turns[j] = turns[p] if p >= 0 else np.eye(3)
            linear[j] = turns[j]
    # y -> rest[j] + linear[j] @ (y - source[j]) as a 3x4 matrix
    return np.concatenate([linear, (rest - np.einsum("jab,jb->ja", linear, source))[:, :, None]], axis=2)


def bind_skin_to_clip(skin: Skin, clip: Skeleton, joint_map: dict[str, str] | None = None, *,
                      skin_label: str = "skin", clip_label: str = "the clip") -> tuple[Skin, Binding | None]:
    """`bind_skin`, its refusal naming the skin and the clip for the user:
    ``ConfigError("<skin_label>: <why> (clip <clip_label>)")``."""
    try:
        return bind_skin(skin, clip, joint_map)
    except ConfigError as error:
        raise ConfigError(f"{skin_label}: {error} (clip {clip_label})") from None
