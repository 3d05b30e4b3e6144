"""The default character: a rubber figure grown from the skeleton itself.

Like Kwon and Lee's Figure 12 cat, the body is tubes: each run of links that go
on from one another in the rest pose (shoulder, elbow, wrist and hand; hip,
knee, ankle and foot; the spine; the neck) is ONE closed tube, round at both
ends. A ring at a joint lies in the plane halving the bend and is shared half
and half by the two links' joints, handing over smoothly to each link's own
joint within two radii of it, so the tube bends at the joint instead of parting
there; on the rubber skeleton `mocap_exaggerate.rig.skinning.reweight` spreads each
link's weight over its sub-joints, and the tube follows the link's curve. Rings
sit half a radius apart, so a bent link is round all along. Where a run branches
(hips, chest) each child run starts with a round end buried in its parent's,
moved by the branch joint; runs meeting at more than `MAX_BEND` in the rest pose
(a foot at right angles to its shin, an arm hanging from a level collar) are
separate tubes, each round at the joint they share. A link shorter than its
tube is thick (a Daz buttock, an iClone waist) is folded into its neighbour.
Thinner where stretched: the GLB scales each joint by
`mocap_exaggerate.jobs.outputs.output_thickness` (volume kept), and so does the preview.

Why not separate capsules, one per link (the body before): a capsule's round
ends overlapped its neighbours', and on the rubber skeleton the overlapping caps
were bent by both links (0.3 % of the edges past 2x with no exaggeration at all),
and the body read as beads on a string. Why not one welded mesh (the body before
that): the boolean union of every capsule, weighted to the four nearest links,
welded limbs packed together in the rest pose (iClone's ``CC_Base_*`` rest has
the legs and arms pointing up beside the spine; 3ds Max and MocapBank rest with
the arms against the hips) and tore the welds apart as they moved (43 % of the
iClone faces stretched threefold in the captured motion). Tubes per run never
join two limbs: a tube holds one run, and runs meet only at a branch.

Measured on the 33 shared rigs (``bench/skin.py``): in the captured motion no
face of the tubes passes 2.4x its rest size and at most 0.13 % pass 2x (linear
blend skinning at joints bent far from the rest pose); every joint and link of
the rubber skeleton stays within 0.86-1.13x its rest distance of the body at
every frame at looney, with ``--auto-stretch`` too.

So that the body reads as a body, the torso (links from the root up to the neck
base) is thicker than a limb, the head is a ball around the head's link, and a
joint whose own children all ride rigidly on it (a hand with fingers, a foot
with toes, a head with a face rig) gets one piece reaching to the middle of
what rides on it instead of one per finger, toe or eye. Twist and share bones
ride rigidly, so they add nothing. Tubes are tessellated directly (no boolean
operation): a humanoid body is 3.5k-4.6k vertices and costs about 10 ms.
"""

from __future__ import annotations

import numpy as np

from ..core.skeleton import Skeleton
from .skinning import Skin

__all__ = ["default_skin", "LIMB_RADIUS", "TORSO_RADIUS", "HEAD_RADIUS"]

#: Radius of a limb's capsule: ``LIMB_RADIUS[0]`` of its length, clipped to the other two shares of the height.
LIMB_RADIUS = (0.22, 0.025, 0.05)
#: Radius of the capsules from the root up to the neck base, as a share of the height.
TORSO_RADIUS = 0.06
#: Radius of the head's ball, as a share of the height (more where the head's link is longer).
HEAD_RADIUS = 0.05


def default_skin(skeleton: Skeleton, rigid: np.ndarray | None = None, detail: float = 1.0) -> Skin:
    """A rubber body of tubes around ``skeleton``'s rest pose (see the module's notes).

    skeleton : any skeleton; humanoids (`mocap_exaggerate.analysis.limbs.find_limbs`) get a thicker
        torso and a round head
    rigid : (J,) bool, joints (fingers, toes, face, twist bones) that get no piece of
        their own but ride on their nearest non-rigid ancestor's; default
        `mocap_exaggerate.analysis.branches.minor_branches`, as the pipeline prunes them
    detail : below 1, a coarser body (fewer vertices around and along each tube): a compare grid's
        small cells draw ten bodies a picture

    Returns a `Skin` made of closed, outward-facing tubes, one per run of links, in the rest
    pose; a vertex has one influence, or two near a joint where a tube bends (padded to four
    columns).
    """
    from ..analysis.branches import minor_branches
    from ..analysis.limbs import find_limbs

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
        torso[skeleton.ancestors(limbs["spine"].end)] = True
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
        child = np.full(1, -1)

    # Pieces that coincide and move together (MocapBank's collars start and end where its neck
    # does) are drawn once, the thickest.
    by_size = np.argsort(-radius, kind="stable")
    key = np.column_stack([mover[by_size], np.round(np.hstack([start, end])[by_size] / short)])
    _, first = np.unique(key, axis=0, return_index=True)
    pick = np.sort(by_size[first])
    mover, start, end, radius, child = mover[pick], start[pick], end[pick], radius[pick], child[pick]

    # Pieces that run on from one another (a thigh into a shin, a forearm into its hand) are
    # drawn as one tube; beyond DETAILED tubes (a root with hundreds of children: not a
    # character) they are tessellated coarser, so the body stays bounded in size.
    chains = _chains(mover, start, end, child, short)
    detail = min(1.0, np.sqrt(DETAILED / max(len(chains), 1))) * min(max(float(detail), 0.1), 1.0)
    around = max(6, int(_AROUND * detail))
    rings = max(2, int(_RINGS * detail))
    steps = _STEPS if detail == 1.0 else 1  # a coarse body: no rings between a piece's ends
    parts = [_tube(start[c[0]], end[c], radius[c], mover[c], around, rings, short, steps) for c in chains]
    vertices = np.concatenate([part[0] for part in parts])
    first = np.cumsum([0] + [len(part[0]) for part in parts[:-1]])
    faces = np.concatenate([part[1] + at for part, at in zip(parts, first)])
    owners = np.concatenate([part[2] for part in parts])
    share = np.concatenate([part[3] for part in parts])
    joints = np.zeros((len(vertices), 4), dtype=np.int64)
    weights = np.zeros((len(vertices), 4))
    weights[:, 1] = np.where(owners[:, 1] != owners[:, 0], share, 0.0)
    weights[:, 0] = 1.0 - weights[:, 1]
    joints[:, 0] = owners[:, 0]
    joints[:, 1] = np.where(weights[:, 1] > 0, owners[:, 1], 0)
    return Skin(vertices, faces.astype(np.int64), skeleton.names, joints, weights, per_link=True)


def _chains(mover: np.ndarray, start: np.ndarray, end: np.ndarray, child: np.ndarray, short: float) -> list[list[int]]:
    """Pieces grouped into runs that go on from one another, each run in order from its base.

    Piece ``b`` goes on from piece ``a`` when ``a`` ends at the joint ``b`` starts from, no other
    piece starts there (not a branch: hips, chest), neither is a ball, and they meet at less
    than `MAX_BEND` (a foot at right angles to its shin is its own piece, rounded at both ends).
    """
    count = len(mover)
    length = np.linalg.norm(end - start, axis=1)
    starting = np.bincount(mover, minlength=int(max(mover.max(), child.max()) + 1) if count else 1)
    successor = np.full(count, -1)
    by_mover = {int(m): i for i, m in enumerate(mover)}
    for a in range(count):
        c = int(child[a])
        if c < 0 or starting[c] != 1 or length[a] <= short:
            continue
        b = by_mover[c]
        if length[b] <= short or np.linalg.norm(end[a] - start[b]) > short:  # a ball, or a torso top cut short
            continue
        cosine = np.dot(end[a] - start[a], end[b] - start[b]) / (length[a] * length[b])
        if cosine > np.cos(np.radians(MAX_BEND)):
            successor[a] = b
    has_predecessor = np.zeros(count, bool)
    has_predecessor[successor[successor >= 0]] = True
    chains = []
    for a in range(count):
        if has_predecessor[a]:
            continue
        chain = [a]
        while successor[chain[-1]] >= 0:
            chain.append(int(successor[chain[-1]]))
        chains.append(chain)
    return chains


def _tube(base: np.ndarray, ends: np.ndarray, radius: np.ndarray, movers: np.ndarray, around: int, rings: int,
          short: float, most_steps: int = 24):
    """One closed, outward-facing tube from ``base`` through the points ``ends`` (n, 3), round at both ends.

    Piece i runs from the point before to ``ends[i]`` with ``radius[i]`` and moves with ``movers[i]``;
    a ball where the tube has no length. Along a piece the radius eases to the thinner of two
    meeting pieces at their joint; the ring at a joint lies in the plane halving the bend
    (stretched across it so the tube's section stays round) and is shared half and half by the
    two pieces' joints, handing over smoothly to each piece's own joint within a radius, so the
    tube bends there instead of parting. Rings are carried along the
    tube by a rotation-minimising frame, so it does not twist.
    Returns vertices (V, 3), faces (T, 3), owners (V, 2): two joints, and share (V,): the second's weight.
    """
    points = np.vstack([base, ends])
    # A piece shorter than the tube is thick (a Daz buttock, an iClone waist) is folded into
    # its neighbour: rings a hair apart with different joints would stretch tenfold at a turn.
    length = np.linalg.norm(np.diff(points, axis=0), axis=1)
    # The last piece (a hand, a foot) keeps its own joint unless it is a mere stub.
    while len(length) > 1 and np.min(stub := length / radius / np.r_[np.ones(len(length) - 1), 0.25]) < 1.0:
        i = int(np.argmin(stub))
        # The point between it and the next piece (the last piece: the previous), which takes it over.
        points = np.delete(points, i + 1 if i + 1 < len(length) else i, axis=0)
        radius, movers = np.delete(radius, i), np.delete(movers, i)
        length = np.linalg.norm(np.diff(points, axis=0), axis=1)
    n = len(points) - 1
    if n == 1 and np.linalg.norm(points[1] - points[0]) <= short:
        vertices, faces, _ = _capsules(points[:1], points[1:], radius, around, rings)
        return vertices, faces, np.full((len(vertices), 2), movers[0]), np.zeros(len(vertices))
    direction = np.diff(points, axis=0)
    length = np.linalg.norm(direction, axis=1)
    direction = direction / length[:, None]
    node_radius = np.concatenate([radius[:1], np.minimum(radius[:-1], radius[1:]), radius[-1:]])

    # Rings along the tube, each (centre, tangent, radius, stretch across the bend or None,
    # its piece's joint, the other joint it hands over to, and that joint's weight).
    ring_rows: list[tuple] = []

    def ring(centre, tangent, size, mitre=None, joint=None, other=None, part=0.0):
        ring_rows.append((centre, tangent, size, mitre, joint, joint if other is None else other, part))

    # The round start: rings from the pole to the base's equator.
    polar = 0.5 * np.pi * np.arange(1, rings + 1) / rings
    for angle in polar[:-1]:
        ring(points[0] - np.cos(angle) * node_radius[0] * direction[0], direction[0], np.sin(angle) * node_radius[0],
             joint=movers[0])
    # Across a joint the two pieces' joints hand over smoothly, from half and half at the joint
    # to all of a piece's own within `_HAND_OVER` radii of it (half a piece at most).
    zone = np.minimum(_HAND_OVER * node_radius, 0.5 * np.minimum(np.concatenate([length[:1], length]),
                                                                 np.concatenate([length, length[-1:]])))
    # Rings this near a bent joint would cross its mitred ring on the inside of the bend.
    bend = np.concatenate([[0.0], np.arccos(np.clip(np.sum(direction[:-1] * direction[1:], axis=1), -1, 1)), [0.0]])
    clear = node_radius * (1.25 * np.tan(0.5 * bend) + np.where(bend > 0.05, 0.25, 0.0))
    for i in range(n):
        # The piece's own rings, half a radius apart: the sub-joints bend it smoothly.
        steps = int(np.clip(np.ceil(length[i] / max(0.5 * radius[i], 1e-12)), 1, most_steps))
        for t in np.arange(0 if i == 0 else 1, steps) / steps:
            after, before = t * length[i], (1.0 - t) * length[i]  # from the piece's start and to its end
            if (i > 0 and after < clear[i]) or before < clear[i + 1]:
                continue
            size = (radius[i] + (node_radius[i] - radius[i]) * _smooth(1.0 - t / _EASE)
                    + (node_radius[i + 1] - radius[i]) * _smooth(1.0 - (1.0 - t) / _EASE))
            other, part = None, 0.0
            if i > 0 and after < zone[i]:
                other, part = movers[i - 1], 0.5 * (1.0 - _smooth(after / zone[i]))
            elif i + 1 < n and before < zone[i + 1]:
                other, part = movers[i + 1], 0.5 * (1.0 - _smooth(before / zone[i + 1]))
            ring(points[i] + after * direction[i], direction[i], size, joint=movers[i], other=other, part=part)
        if i + 1 < n:  # the joint to the next piece: a mitred ring shared by both pieces' joints
            halfway = direction[i] + direction[i + 1]
            halfway /= np.linalg.norm(halfway)
            across = direction[i + 1] - direction[i]
            size = np.linalg.norm(across)
            mitre = None if size < 1e-9 else (across / size, 1.0 / np.dot(halfway, direction[i]) - 1.0)
            ring(points[i + 1], halfway, node_radius[i + 1], mitre, movers[i], movers[i + 1], 0.5)
    ring(points[-1], direction[-1], node_radius[-1], joint=movers[-1])  # the end's equator, then rings to its pole
    for angle in polar[::-1][1:]:
        ring(points[-1] + np.cos(angle) * node_radius[-1] * direction[-1], direction[-1],
             np.sin(angle) * node_radius[-1], joint=movers[-1])
    centres, tangents, radii, mitres, joint_a, joint_b, shares = zip(*ring_rows)

    # Rotation-minimising frames: the first ring's spoke carried from tangent to tangent.
    w = tangents[0]
    u = np.cross(w, [1.0, 0.0, 0.0] if abs(w[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    phi = 2.0 * np.pi * np.arange(around) / around
    ring_points = []
    for k, w in enumerate(tangents):
        u = u - np.dot(u, w) * w
        u /= np.linalg.norm(u)
        v = np.cross(w, u)
        spoke = np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * v  # u x v = w: anticlockwise about w
        if mitres[k] is not None:
            across, extra = mitres[k]
            spoke = spoke + extra * (spoke @ across)[:, None] * across
        ring_points.append(centres[k] + radii[k] * spoke)
    count = len(ring_points)
    vertices = np.concatenate([[points[0] - node_radius[0] * direction[0]], np.concatenate(ring_points),
                               [points[-1] + node_radius[-1] * direction[-1]]])
    owners = np.concatenate([[[movers[0]] * 2], np.repeat(np.column_stack([joint_a, joint_b]), around, axis=0),
                             [[movers[-1]] * 2]]).astype(np.int64)
    share = np.concatenate([[0.0], np.repeat(shares, around), [0.0]])
    j = np.arange(around)
    k = (j + 1) % around
    ring = 1 + np.arange(count)[:, None] * around
    lower, upper = ring[:-1], ring[1:]
    faces = np.concatenate([
        np.column_stack([np.zeros(around, np.int64), ring[0] + k, ring[0] + j]),
        np.stack([lower + j, lower + k, upper + k], axis=-1).reshape(-1, 3),
        np.stack([lower + j, upper + k, upper + j], axis=-1).reshape(-1, 3),
        np.column_stack([ring[-1] + j, ring[-1] + k, np.full(around, len(vertices) - 1)]),
    ])
    return vertices, faces, owners, share


def _smooth(x: float) -> float:
    """0 below 0, 1 above 1, smoothstep between."""
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


#: How far from a joint, in radii, its two pieces hand over (half and half at the joint).
_HAND_OVER = 2.0
#: Share of a piece, from each end, over which its radius eases to the joint's.
_EASE = 0.35
#: Pieces meeting at a sharper angle than this (degrees, in the rest pose) are separate tubes.
MAX_BEND = 60.0


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
#: Most rings between the ends of one piece (half a radius apart).
_STEPS = 24
#: Most tubes tessellated in full; more are drawn coarser.
DETAILED = 150
