"""The default character: a body grown from the skeleton itself.

Each link becomes a capsule (thick enough to read as a limb, thin enough to
show the skeleton's proportions), kept as its own closed piece and bound
rigidly to the joint that moves it (a link moves with its head joint). Both
round ends of a capsule are centred on joints, so wherever a joint turns, the
capsules meeting there turn about their common centre and the body stays
joined without any weight blending.

Why not one welded mesh. The body used to be the boolean union of all the
capsules, each vertex weighted to its four nearest links. On rigs whose rest
pose packs the limbs together (iClone's ``CC_Base_*`` rest pose has both legs
and both arms pointing up beside the spine; the 3ds Max and MocapBank clips
rest with the arms down against the hips) the union welded arms, torso and
legs into one block, and linear blend skinning tore the welds into shards as
soon as the limbs moved apart: 43 % of the faces of the iClone clips
stretched more than threefold in the captured motion itself (6 % on 3ds Max,
3 % on MocapBank), and legs side by side pulled webs out of each other
through shared weights. Measured alternatives on ``../shared/data/bvh``:
a union per limb (arms, legs, torso) with weights kept inside the limb still
welds iClone's clavicles into its neck (7 % of faces over 3x); a union per
unbranched chain has no weld left, but blending weights across a joint folds
the skin into itself where a clip turns a joint far from its rest pose (2-6 %
of the faces on the packed rigs get an edge squashed below a third; iClone's
hips turn half a turn in every frame). Separate rigid capsules cannot weld,
tear or fold whatever the rest pose and the motion: in the captured motion no
edge changes length, and on the rubber skeleton, where
`mocap_exaggerate.skinning.reweight` bends each capsule along its link's
curve, at most 0.6 % of the faces of any shared clip stretch more than
threefold (31-33 % on iClone before).

So that the body reads as a body, the torso (links from the root up to the
neck base) is thicker than a limb and ends at the neck base, the head is a
ball around the head's link, and a joint whose own children all ride rigidly
on it (a hand with fingers, a foot with toes, a head with a face rig) gets
one capsule reaching to the middle of what rides on it instead of one per
finger, toe or eye. Twist and share bones ride rigidly, so they add nothing.
Capsules are tessellated directly (no boolean operation): a humanoid body is
2.7k-3.4k vertices and costs a few milliseconds.
"""

from __future__ import annotations

import numpy as np

from .skeleton import Skeleton
from .skinning import Skin

__all__ = ["default_skin", "LIMB_RADIUS", "TORSO_RADIUS", "HEAD_RADIUS"]

#: Radius of a limb's capsule: ``LIMB_RADIUS[0]`` of its length, clipped to the other two shares of the height.
LIMB_RADIUS = (0.22, 0.025, 0.05)
#: Radius of the capsules from the root up to the neck base, as a share of the height.
TORSO_RADIUS = 0.06
#: Radius of the head's ball, as a share of the height (more where the head's link is longer).
HEAD_RADIUS = 0.05


def default_skin(skeleton: Skeleton, rigid: np.ndarray | None = None) -> Skin:
    """A capsule body around ``skeleton``'s rest pose, each capsule bound to the joint that moves it.

    skeleton : any skeleton; humanoids (`mocap_exaggerate.limbs.find_limbs`) get a thicker
        torso and a round head
    rigid : (J,) bool, joints (fingers, toes, face, twist bones) that get no capsule of
        their own but ride on their nearest non-rigid ancestor's; default
        `mocap_exaggerate.stages.subjoints.minor_branches`, as the pipeline prunes them

    Returns a `Skin` made of closed, outward-facing capsules, one per piece, in the rest
    pose; every vertex has a single influence (weight 1, padded to four columns).
    """
    from .limbs import find_limbs
    from .stages.subjoints import minor_branches

    rigid = minor_branches(skeleton) if rigid is None else np.asarray(rigid, dtype=bool)
    count = skeleton.num_joints
    parents = skeleton.parents
    rest = skeleton.rest_positions()
    height = max(skeleton.height(), 1e-9)
    short = 1e-4 * height  # links shorter than this are no capsule (the joint is covered anyway)
    has_end = np.isfinite(skeleton.end_sites[:, 0])
    end_sites = rest + np.nan_to_num(skeleton.end_sites)

    # Pieces as (mover, start, end, child): the link to each non-rigid joint, moving with its
    # parent; each non-rigid joint's End Site; child is the joint a link ends at, or -1.
    linked = np.flatnonzero(~rigid[1:]) + 1
    ended = np.flatnonzero(has_end & ~rigid)
    mover = np.concatenate([parents[linked], ended])
    start = np.concatenate([rest[parents[linked]], rest[ended]])
    end = np.concatenate([rest[linked], end_sites[ended]])
    child = np.concatenate([linked, np.full(len(ended), -1)])
    keep = np.linalg.norm(end - start, axis=1) > short
    mover, start, end, child = mover[keep], start[keep], end[keep], child[keep]

    # A joint from which no piece starts but on which others ride (a hand with fingers, a foot
    # with toes, a head with a face rig): one piece to the mean of the riders' joints and End Sites.
    carrier = np.arange(count)
    for j in np.flatnonzero(rigid):
        carrier[j] = carrier[parents[j]] if j > 0 and rigid[parents[j]] else max(parents[j], 0)
    riders = np.flatnonzero(rigid)
    riders_ended = riders[has_end[riders]]
    points = np.concatenate([rest[riders], end_sites[riders_ended]])
    at = np.concatenate([carrier[riders], carrier[riders_ended]])
    total = np.zeros((count, 3))
    np.add.at(total, at, points)
    number = np.bincount(at, minlength=count)
    capped = np.flatnonzero((number > 0) & ~rigid & ~np.isin(np.arange(count), mover))
    mover = np.concatenate([mover, capped])
    start = np.concatenate([start, rest[capped]])
    end = np.concatenate([end, total[capped] / number[capped, None]])
    child = np.concatenate([child, np.full(len(capped), -1)])

    length = np.linalg.norm(end - start, axis=1)
    end[length <= short] = start[length <= short]  # a hand whose riders sit on it: a ball
    radius = np.clip(LIMB_RADIUS[0] * length, LIMB_RADIUS[1] * height, LIMB_RADIUS[2] * height)
    limbs = find_limbs(skeleton)
    if "spine" in limbs:  # the links from the root up to the neck base
        torso = np.zeros(count, bool)
        torso[_ancestors(parents, limbs["spine"].end)] = True
        trunk = (child > 0) & torso[np.maximum(child, 0)]
        radius[trunk] = np.maximum(radius[trunk], TORSO_RADIUS * height)
        # The torso's round top ends at the neck base instead of swallowing the neck.
        top = trunk & (np.linalg.norm(end - rest[limbs["spine"].end], axis=1) <= short)
        back = np.minimum(radius[top], length[top])[:, None] / np.maximum(length[top], short)[:, None]
        end[top] -= back * (end[top] - start[top])
    if "neck" in limbs:  # a piece from the head joint (to its End Site, its face) becomes a ball
        head = mover == limbs["neck"].end
        radius[head] = np.maximum(HEAD_RADIUS * height, 0.5 * length[head])  # still holding the joint
        start[head] = end[head] = 0.5 * (start[head] + end[head])
    if not len(mover):  # a skeleton with no link at all: a ball on the root
        mover, start, end, radius = np.zeros(1, np.int64), rest[:1], rest[:1], np.array([LIMB_RADIUS[2] * height])

    # Pieces that coincide and move together (MocapBank's collars start and end where its neck
    # does) are drawn once, the thickest.
    by_size = np.argsort(-radius, kind="stable")
    key = np.column_stack([mover[by_size], np.round(np.hstack([start, end])[by_size] / short)])
    _, first = np.unique(key, axis=0, return_index=True)
    pick = np.sort(by_size[first])
    mover, start, end, radius = mover[pick], start[pick], end[pick], radius[pick]

    # Beyond DETAILED pieces (a root with hundreds of children: not a character) they are
    # tessellated coarser, so the body stays bounded in size.
    detail = min(1.0, np.sqrt(DETAILED / len(mover)))
    vertices, faces, owner = _capsules(start, end, radius, max(6, int(_AROUND * detail)), max(2, int(_RINGS * detail)))
    joints = np.zeros((len(vertices), 4), dtype=np.int64)
    weights = np.zeros((len(vertices), 4))
    joints[:, 0], weights[:, 0] = mover[owner], 1.0
    return Skin(vertices, faces, skeleton.names, joints, weights)


def _ancestors(parents: np.ndarray, joint: int) -> list[int]:
    """``joint`` and every joint above it up to the root."""
    out = []
    while joint >= 0:
        out.append(int(joint))
        joint = parents[joint]
    return out


def _capsules(start: np.ndarray, end: np.ndarray, radius: np.ndarray, around: int, rings: int):
    """Closed, outward-facing capsules from ``start`` to ``end`` ``(N, 3)`` with ``radius`` ``(N,)``.

    Each round end is a pole and ``rings`` rings of ``around`` vertices; a zero-length
    capsule is a sphere (its two halves share the equator).
    Returns vertices (V, 3), faces (T, 3) int64 and the capsule of each vertex (V,).
    """
    axis = end - start
    length = np.linalg.norm(axis, axis=1)
    ball = length <= 0
    w = np.where(ball[:, None], [0.0, 0.0, 1.0], axis / np.where(ball, 1.0, length)[:, None])
    helper = np.where((np.abs(w[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    u = np.cross(w, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(w, u)  # u x v = w: rings run anticlockwise about the axis, faces face out
    polar = 0.5 * np.pi * np.arange(1, rings + 1) / rings
    phi = 2.0 * np.pi * np.arange(around) / around
    vertices, faces, owner = [], [], []
    for joined in (False, True):
        which = np.flatnonzero(ball == joined)
        if not len(which):
            continue
        # The profile, pole to pole: each ring's height along the axis (in radii, plus the length
        # on the far half) and its width (in radii).
        far = polar[::-1][1:] if joined else polar[::-1]
        rise = np.concatenate([[-1.0], -np.cos(polar), np.cos(far), [1.0]])
        width = np.concatenate([[0.0], np.sin(polar), np.sin(far), [0.0]])
        shift = np.concatenate([np.zeros(1 + rings), np.ones(len(far) + 1)])
        r, a, ww, n = radius[which], start[which], w[which], len(which)
        centre = a[:, None] + (rise[None] * r[:, None] + shift[None] * length[which][:, None])[..., None] * ww[:, None]
        spoke = np.cos(phi)[None, :, None] * u[which][:, None] + np.sin(phi)[None, :, None] * v[which][:, None]
        # (n, rows, around, 3); of each pole row one vertex is kept, rings 1..count lie between.
        points = centre[:, :, None] + (width[None] * r[:, None])[..., None, None] * spoke[:, None]
        count = len(rise) - 2
        per = count * around + 2
        around_rings = points[:, 1:-1].reshape(n, -1, 3)
        vertices.append(np.concatenate([points[:, :1, 0], around_rings, points[:, -1:, 0]], axis=1).reshape(-1, 3))
        j = np.arange(around)
        k = (j + 1) % around
        ring = 1 + np.arange(count)[:, None] * around  # first vertex of each ring
        fans = [np.column_stack([np.zeros(around, np.int64), ring[0] + k, ring[0] + j]),
                np.column_stack([ring[-1] + j, ring[-1] + k, np.full(around, per - 1)])]
        lower, upper = ring[:-1], ring[1:]
        quads = np.concatenate([np.stack([lower + j, lower + k, upper + k], axis=-1),
                                np.stack([lower + j, upper + k, upper + j], axis=-1)]).reshape(-1, 3)
        template = np.concatenate([fans[0], quads, fans[1]])
        first = sum(len(x) for x in vertices[:-1])
        faces.append((template[None] + first + per * np.arange(n)[:, None, None]).reshape(-1, 3))
        owner.append(np.repeat(which, per))
    return np.concatenate(vertices), np.concatenate(faces).astype(np.int64), np.concatenate(owner)


#: Vertices around each capsule and rings on each of its round ends: round in a preview, at
#: 130 vertices a capsule; humanoid bodies come out at 2k-4k vertices.
_AROUND = 16
_RINGS = 4
#: Most pieces tessellated in full; more are drawn coarser.
DETAILED = 150
