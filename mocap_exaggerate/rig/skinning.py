"""Skins: the `Skin` type, influence pruning, and weight redistribution onto sub-joints.

A skin is stored sparsely, as glTF does: for each vertex the indices of its
strongest joints and their weights, ``(V, K)`` each, rows summing to 1.

Redistribution (after Kwon & Lee 2008, section 6; see `reweight` for where
and why it departs from their inverse-distance rule):

A vertex bound to original joint k with weight w is re-bound to the joints
owning the sub-links of k's outgoing link (each owns the sub-link that starts
at it: a bone moves with its head joint), by where the vertex lies along the
link, blending across the joints into the links before and after; then the
strongest influences are kept and renormalised.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from ..core.errors import ConfigError, printable
from ..core.rotations import quat_rotate, vector_norm
from ..core.skeleton import Skeleton
from ..stages.subjoints import SubjointHierarchy

__all__ = ["Skin", "top_influences", "reweight", "segment_distance", "subjoint_bind_positions", "pose_skin"]


@dataclass(frozen=True, eq=False)
class Skin:
    """A skinned mesh in its bind pose.

    vertices : (V, 3) float64, in the skeleton's units and rest pose
    faces : (T, 3) int64 triangles
    joint_names : names of the joints ``joints`` indexes into
    joints : (V, K) int64 joint indices, 0 where the weight is 0
    weights : (V, K) float64, each row sums to 1
    bind : joint name -> (3,) bind-pose position, where the mesh's bind pose
        is not the skeleton's rest pose (MakeHuman's A-pose); empty otherwise
    parents : joint name -> its parent's name, the skin's own hierarchy where the
        file gives one (a glTF node tree, a MakeHuman .mhskel); roots are absent.
        `mocap_exaggerate.rig.binding` uses it to fit a character to another rig.
    per_link : the weights were made link by link for the rubber skeleton (the default
        body's tubes, each weighted to the joint its link starts at), not painted for
        rigid bones: on the rubber skeleton a branch joint's weight then follows the
        child link its vertex lies along (`reweight`)
    pose : joint name -> (4,) local rotation: the mesh is bound to the skeleton posed by
        these (the character's own pose, `mocap_exaggerate.rig.binding.bind_skin`), not to
        its rest pose; the outputs then take that pose as the skeleton's rest
        (`mocap_exaggerate.core.motion.Motion.with_rest`). Empty: bound in the rest pose.
    """

    vertices: np.ndarray
    faces: np.ndarray
    joint_names: tuple[str, ...]
    joints: np.ndarray
    weights: np.ndarray
    bind: dict = field(default_factory=dict)
    parents: dict = field(default_factory=dict)
    per_link: bool = False
    pose: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        v = np.asarray(self.vertices, dtype=np.float64)
        if v.ndim != 2 or v.shape[1] != 3:
            raise ValueError(f"vertices must be (V, 3), got {v.shape}")
        if np.shape(self.joints) != np.shape(self.weights) or np.shape(self.joints)[0] != len(v):
            raise ValueError(f"joints {np.shape(self.joints)} and weights {np.shape(self.weights)} must be (V, K)")
        for name in ("faces", "joints"):
            values = np.asarray(getattr(self, name))
            if values.dtype.kind not in "iub" and not np.array_equal(values, np.round(values)):
                raise ValueError(f"{name} must be whole numbers")
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", np.asarray(self.faces, dtype=np.int64).reshape(-1, 3))
        object.__setattr__(self, "joints", np.asarray(self.joints, dtype=np.int64))
        object.__setattr__(self, "weights", np.asarray(self.weights, dtype=np.float64))
        object.__setattr__(self, "joint_names", tuple(self.joint_names))

    @property
    def num_vertices(self) -> int:
        return len(self.vertices)

    def pose_rows(self, names) -> np.ndarray:
        """``(len(names), 4)``: `pose`'s local rotation of each joint named, the identity where it turns
        none; a ConfigError where `pose` turns a joint not among ``names`` (a skin bound to another clip)."""
        index = {name: k for k, name in enumerate(names)}
        rows = np.zeros((len(index), 4))
        rows[:, 3] = 1.0
        for name, turn in self.pose.items():
            if name not in index:
                raise ConfigError(f"the skin is bound in a pose that turns '{printable(name[:80])}', which is not "
                                  "a joint of the clip")
            rows[index[name]] = turn
        return rows


def top_influences(rows: np.ndarray, cols: np.ndarray, values: np.ndarray, num_rows: int, k: int):
    """The ``k`` strongest (column, value) pairs of each row of a sparse matrix, renormalised.

    rows, cols, values : (E,) entries (duplicates are summed)
    Returns joints (num_rows, k) int64 and weights (num_rows, k) float64; rows
    without entries get joint 0 with weight 0.
    """
    order = np.lexsort((cols, rows))
    rows, cols, values = rows[order], cols[order], values[order]
    if len(rows):
        new = np.concatenate([[True], (rows[1:] != rows[:-1]) | (cols[1:] != cols[:-1])])
        starts = np.flatnonzero(new)
        values = np.add.reduceat(values, starts)
        rows, cols = rows[starts], cols[starts]
    counts = np.bincount(rows, minlength=num_rows)
    width = max(int(counts.max(initial=0)), 1)
    slot = np.arange(len(rows)) - np.repeat(np.cumsum(counts) - counts, counts)
    dense_w = np.zeros((num_rows, width))
    dense_j = np.zeros((num_rows, width), dtype=np.int64)
    dense_w[rows, slot] = values
    dense_j[rows, slot] = cols
    if width > k:
        pick = np.argpartition(-dense_w, k - 1, axis=1)[:, :k]
        dense_w = np.take_along_axis(dense_w, pick, axis=1)
        dense_j = np.take_along_axis(dense_j, pick, axis=1)
    elif width < k:
        dense_w = np.pad(dense_w, ((0, 0), (0, k - width)))
        dense_j = np.pad(dense_j, ((0, 0), (0, k - width)))
    order = np.argsort(-dense_w, axis=1, kind="stable")
    dense_w = np.take_along_axis(dense_w, order, axis=1)
    dense_j = np.take_along_axis(dense_j, order, axis=1)
    total = dense_w.sum(axis=1, keepdims=True)
    dense_w = np.divide(dense_w, total, out=np.zeros_like(dense_w), where=total > 0)
    dense_j[dense_w == 0] = 0
    return dense_j, dense_w


def segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from points to segments a-b, broadcasting over leading axes."""
    ab = b - a
    length2 = np.sum(ab * ab, axis=-1)
    along = np.sum((points - a) * ab, axis=-1)
    length2 = np.broadcast_to(length2, along.shape)
    t = np.divide(along, length2, out=np.zeros_like(along), where=length2 > 0)
    closest = a + np.clip(t, 0.0, 1.0)[..., None] * ab
    return vector_norm(points - closest)


def reweight(skin: Skin, skeleton: Skeleton, hierarchy: SubjointHierarchy, *, max_influences: int = 4) -> Skin:
    """The skin re-bound to the rubber skeleton of ``hierarchy``.

    skin : bound to (a subset of) ``skeleton``'s joints by name, in its rest pose
    hierarchy : the rubber skeleton (`mocap_exaggerate.stages.subjoints.link_starts`, as
        `mocap_exaggerate.pipeline.run` returns it, or a plain `build_hierarchy`)
    Returns a Skin whose joint names are the rubber skeleton's.

    A vertex's weight on an original joint is shared among the joints that own
    the sub-links of that joint's outgoing link, by where the vertex lies along
    it: each sub-link's owner peaks at the sub-link's middle and hands over
    linearly to its neighbours, and past the link's ends to the last sub-link
    of the link before and the first of the link after (a knee blends the
    thigh into the shin; on a stretched chain the skin stretches evenly, as
    the joints do). The hand-over crosses a joint only where the chain goes on
    through it (one link in, one out), where the bones' frames meet smoothly.
    At a branch, an end joint or the root the joint's own frame takes over
    instead: from the joint itself at a link's start, and from half a
    sub-link past it at a link's end (so the last sub-link's skin stretches
    like the others). End joints (a hand, a head) and riders (fingers, toes)
    keep their own weight: their frames turn away from the link's (a nod, a
    bent wrist).

    A branch joint (hips, chest) keeps its weight on its own frame, as a
    character's author painted it: the skin there (a belly, a chest, the top
    of a shoulder) is shaped for one rigid frame, and handed to the sub-links
    of the child links it wraps (an abdomen, a neck, both collars) it rolled
    and stretched with them, which tore the MakeHuman body at the hips and
    shoulders more than straight links do (0.25 % of its edges past 2x, median
    over the 33 shared rigs, against 0.22 %; 0.16 % when kept). A skin made
    link by link for the rubber skeleton (``skin.per_link``: the default
    body's tubes, each weighted to the joint its link starts at) shares a
    branch joint's weight among its outgoing links by nearness instead, so a
    tube follows its own link's curve and a left hip's tube takes nothing
    from the right thigh or the spine.

    Kwon and Lee share the weight by the inverse distance to every sub-link of
    the joint; that spreads a branch joint over the sub-links of all its child
    links and puts a vertex's weight on sub-links far down the bone, which tore
    a real character at the hips and shoulders (see the README's design notes).
    """
    sub = hierarchy.skeleton
    rest = subjoint_bind_positions(skeleton, hierarchy, skin.bind)
    index = {name: j for j, name in enumerate(skeleton.names)}
    unknown = [n for n in skin.joint_names if n not in index]
    if unknown:
        raise ConfigError(f"skin joints not in the skeleton: {', '.join(unknown[:5])}")
    to_original = np.array([index[n] for n in skin.joint_names], dtype=np.int64)
    links = _link_knots(skeleton, hierarchy, rest, per_link=skin.per_link)

    vertex = np.repeat(np.arange(skin.num_vertices), skin.joints.shape[1])
    original = to_original[skin.joints.ravel()]
    weight = skin.weights.ravel()
    keep = weight > 0
    vertex, original, weight = vertex[keep], original[keep], weight[keep]
    pair_entry, pair_link = _pairs(skin.vertices[vertex], original, links)
    rows, cols, vals = [], [], []
    bounds = np.searchsorted(pair_entry, np.arange(len(vertex) + 1))  # each entry's pairs: bounds[e]:bounds[e + 1]
    first = 0
    # In blocks of about a million (entry, link) rows: a root with hundreds of children stays small.
    while first < len(vertex):
        last = min(max(first + 1, int(np.searchsorted(bounds, bounds[first] + _BLOCK_ROWS, "right")) - 1), len(vertex))
        block = np.arange(first, last)
        entry = pair_entry[bounds[first]:bounds[last]] - first
        link = pair_link[bounds[first]:bounds[last]]
        point = skin.vertices[vertex[block][entry]]
        head, tail = links.head[link], links.tail[link]
        span = tail - head
        length2 = np.einsum("ij,ij->i", span, span)
        along = np.einsum("ij,ij->i", point - head, span) / np.maximum(length2, 1e-300)
        along = np.where(length2 > 0, along, 1.0)
        # Nearness to each of an entry's links: (nearest / distance)^8, the faintest (under 1 %) dropped.
        distance = segment_distance(point, head, tail)
        nearest = np.full(len(block), np.inf)
        np.minimum.at(nearest, entry, distance)
        share = (np.maximum(nearest[entry], 1e-12) / np.maximum(distance, 1e-12)) ** 8
        share *= _sibling_share(links, link, entry, point, distance)
        total = np.bincount(entry, share, minlength=len(block))[entry]
        share = np.divide(share, total, out=np.zeros_like(share), where=total > 0)
        share = np.where(share < 0.01, 0.0, share)
        total = np.bincount(entry, share, minlength=len(block))[entry]
        share = np.divide(share, total, out=np.zeros_like(share), where=total > 0)
        # Along the link: linear hand-over between the owners' peaks.
        knots, owners = links.knots[link], links.owners[link]
        along = np.clip(along, knots[:, 0], np.nanmax(knots, axis=1))
        slot = np.clip(np.sum(knots <= along[:, None], axis=1) - 1, 0, knots.shape[1] - 2)
        left = knots[np.arange(len(link)), slot]
        right = knots[np.arange(len(link)), slot + 1]
        ahead = np.isfinite(right) & (right > left)
        u = np.where(ahead, (along - left) / np.where(ahead, right - left, 1.0), 0.0)
        u = np.clip(u, 0.0, 1.0)
        base = (weight[block][entry] * share)
        for owner, part in ((owners[np.arange(len(link)), slot], 1.0 - u), (owners[np.arange(len(link)), slot + 1], u)):
            value = base * part
            keep = value > 1e-9  # not the rounding of a hand-over that has not begun
            rows.append(vertex[block][entry][keep])
            cols.append(owner[keep])
            vals.append(value[keep])
        first = last
    joints, weights = top_influences(np.concatenate(rows or [np.zeros(0, np.int64)]),
                                     np.concatenate(cols or [np.zeros(0, np.int64)]),
                                     np.concatenate(vals or [np.zeros(0)]), skin.num_vertices, max_influences)
    return Skin(skin.vertices, skin.faces, sub.names, joints, weights)


#: (entry, link) rows re-weighted at once.
_BLOCK_ROWS = 1_000_000
#: A joint with more outgoing links than this shares a vertex's weight among the `_NEAREST` links nearest it
#: only (found through a k-d tree): sharing it among all of a 10,000-link star's was quadratic in the joints
#: (13 s at 500 joints, 170 s at 2,000). A humanoid's joints have at most a handful and are as they were.
_MANY_LINKS = 16
_NEAREST = 8


def _pairs(points: np.ndarray, original: np.ndarray, links: _Links) -> tuple[np.ndarray, np.ndarray]:
    """The (entry, link) pairs re-weighted, sorted by entry: every outgoing link of an entry's joint, or for
    a joint of more than `_MANY_LINKS` the `_NEAREST` nearest the entry's point (by points along each link)."""
    count = links.count[original]
    many = count > _MANY_LINKS
    few = np.flatnonzero(~many)
    entry = np.repeat(few, count[few])
    within = np.arange(len(entry)) - np.repeat(np.cumsum(count[few]) - count[few], count[few])
    pair_entry, pair_link = [entry], [links.start[original[few]][np.searchsorted(few, entry)] + within]
    if np.any(many):
        from scipy.spatial import cKDTree

        samples = np.linspace(0.0, 1.0, 5)
        for joint in np.unique(original[many]):
            own = np.arange(links.start[joint], links.start[joint] + links.count[joint])
            along = links.head[own][:, None] + samples[None, :, None] * (links.tail[own] - links.head[own])[:, None]
            tree = cKDTree(along.reshape(-1, 3))
            entries = np.flatnonzero(many & (original == joint))
            k = min(_NEAREST * len(samples), len(own) * len(samples))
            _, nearest = tree.query(points[entries], k=k)
            nearest = np.asarray(nearest).reshape(len(entries), -1)
            found = own[nearest // len(samples)]  # (entries, k) links, nearest first, with repeats
            # Each link at its first (nearest) place only, and the first `_NEAREST` of those.
            earlier = np.triu(np.ones((found.shape[1], found.shape[1]), bool), 1)  # [i, j]: i before j
            seen = ((found[:, :, None] == found[:, None, :]) & earlier).any(axis=1)
            fresh = ~seen & (np.cumsum(~seen, axis=1) <= _NEAREST)
            chosen = np.where(fresh, found, np.iinfo(found.dtype).max)
            chosen.sort(axis=1)
            kept = fresh.sum(axis=1)
            pair_entry.append(np.repeat(entries, kept))
            pair_link.append(chosen[np.arange(chosen.shape[1]) < kept[:, None]])
    pair_entry, pair_link = np.concatenate(pair_entry), np.concatenate(pair_link)
    order = np.argsort(pair_entry, kind="stable")
    return pair_entry[order], pair_link[order]


def _sibling_share(links: _Links, link: np.ndarray, entry: np.ndarray, point: np.ndarray,
                   own: np.ndarray) -> np.ndarray:
    """How a share tied between coincident sibling links is split among them, by the links after them.

    Some rigs start the neck and both collars at one point (an Assimp chest, a
    mocapbank chest): their first links lie on top of each other, every vertex
    is as near to one as to the others, and an even three-way split of the neck
    tore 48x at a looney crouch, where the three curves part. Within such a
    group the link that goes on straightest (the neck, on to the head) keeps
    the skin along the group's shared link, and a vertex goes to another
    member only where it lies nearer that member's next link (the top of a
    shoulder, by the upper arm), by the same (nearest / distance)^8 rule; the
    group's total share is unchanged.

    own : each row's distance to its own link, as the caller measured it
    """
    factor = np.ones(len(link))
    group = links.group[link]
    tied = np.flatnonzero(group >= 0)
    if not len(tied):
        return factor
    distance = segment_distance(point[tied], links.probe_head[link[tied]], links.probe_tail[link[tied]])
    main = links.straightest[link[tied]]
    distance[main] = np.minimum(distance[main], own[tied][main])
    _, key = np.unique(entry[tied] * (int(links.group.max()) + 1) + group[tied], return_inverse=True)
    nearest = np.full(key.max() + 1, np.inf)
    np.minimum.at(nearest, key, distance)
    split = (np.maximum(nearest[key], 1e-12) / np.maximum(distance, 1e-12)) ** 8
    factor[tied] = split / np.bincount(key, split)[key] * np.bincount(key)[key]
    return factor


class _Links(NamedTuple):
    """Each original joint's outgoing links, as the rows ``start[k]:start[k] + count[k]``.

    head, tail : (L, 3) the link's ends in the bind pose (for an end joint, the link into it)
    knots : (L, M) where each owner peaks, in link lengths from the head (NaN-padded, increasing)
    owners : (L, M) the rubber joint that peaks there (0 where padded)
    group : (L,) a number shared by sibling links that lie on top of each other in the bind
        pose (within 2 % of their length), -1 for every other link
    probe_head, probe_tail : (L, 3) the link after a grouped one (its own where the chain
        does not go on through one link), which tells the group's members apart
    straightest : (L,) bool, the member of its group whose next link goes on straightest
    """

    start: np.ndarray
    count: np.ndarray
    head: np.ndarray
    tail: np.ndarray
    knots: np.ndarray
    owners: np.ndarray
    group: np.ndarray
    probe_head: np.ndarray
    probe_tail: np.ndarray
    straightest: np.ndarray


def _coincident(points: np.ndarray, radius: np.ndarray) -> list[list[int]]:
    """For each point, the points within its ``radius`` (itself included), as lists of indices.

    Pairwise for a joint's few children; a k-d tree where a root has thousands (SciPy's
    spatial module is imported only then: the command line does without it).
    """
    if len(points) <= 64:
        near = vector_norm(points[:, None] - points[None]) <= radius[:, None]
        return [list(np.flatnonzero(row)) for row in near]
    from scipy.spatial import cKDTree

    return cKDTree(points).query_ball_point(points, radius)


def _link_knots(skeleton: Skeleton, hierarchy: SubjointHierarchy, rest: np.ndarray, *, per_link: bool) -> _Links:
    sub = hierarchy.skeleton
    count = skeleton.num_joints
    original = hierarchy.original
    height = max(skeleton.height(), 1e-12)
    placed = rest[original]
    length = np.linalg.norm(placed - placed[np.maximum(skeleton.parents, 0)], axis=1)
    length[0] = 0.0
    moving = ~hierarchy.rigid
    real = moving & (length > 1e-4 * height)
    real[0] = False
    # The owners of each link's sub-links, from its head: a joint owns the sub-link that starts at it.
    owners_of: dict[int, list[int]] = {}
    for j in range(1, sub.num_joints):
        c = int(hierarchy.link_child[j])
        if j == original[c]:
            continue
        owners_of.setdefault(c, []).append(j)
    chains: dict[int, list[int]] = {}
    kids: list[list[int]] = [[] for _ in range(count)]
    for c in np.flatnonzero(real):
        c = int(c)
        below = owners_of.get(c, [])
        head = [int(original[skeleton.parents[c]])] if not below or sub.offsets[below[0]].any() else []
        chains[c] = head + below  # with a start joint, the head's own zero link is not a sub-link
        kids[int(skeleton.parents[c])].append(c)  # one pass: children() per joint is quadratic on a star

    def peaks(c: int) -> tuple[np.ndarray, list[int]]:
        owners = chains[c]
        return (np.arange(len(owners)) + 0.5) / len(owners), owners

    # Across a joint the chain goes on through (one link in, one out), its bones' frames meet
    # smoothly (the curve and its twist run on): the skin hands over from the last sub-link of one
    # link to the first of the next. At a branch (hips, chest), an end (a hand, a head, a foot)
    # or the root it does not: there the joint's own frame holds the skin at the joint, so the
    # skin on both sides of it moves as one and a stretched sub-link never pulls it apart.
    def before(k: int, scale: float) -> tuple[list[float], list[int]]:
        """The first knot of a link from ``k`` (lengths in units of ``scale``)."""
        if k > 0 and real[k] and len(kids[k]) == 1:  # the peak of the last sub-link into ``k``
            at, owners = peaks(k)
            return [(at[-1] - 1.0) * length[k] / scale], [owners[-1]]
        return [0.0], [int(original[k])]

    def after(c: int, scale: float) -> tuple[list[float], list[int]]:
        """The last knot of the link into ``c``."""
        if len(kids[c]) == 1:  # the peak of the first sub-link the chain goes on through
            at, owners = peaks(kids[c][0])
            return [1.0 + at[0] * length[kids[c][0]] / scale], [owners[0]]
        # Half a sub-link past the joint, as a next link's first peak would be: the last sub-link
        # hands over to the joint's frame stretched as evenly as the others (at 1.0 the half
        # sub-link before the joint took all of its stretch, twice over).
        at, _ = peaks(c)
        return [1.0 + (1.0 - at[-1])], [int(original[c])]

    heads, tails, knot_rows, owner_rows, starts, counts = [], [], [], [], [], []
    groups, probes, turns, next_group = [], [], [], 0
    for k in range(count):
        starts.append(len(heads))
        if moving[k] and kids[k] and (per_link or len(kids[k]) == 1):
            tied = _coincident(placed[kids[k]], 0.02 * length[kids[k]])
            for i, c in enumerate(kids[k]):
                groups.append(next_group + min(tied[i]) if len(tied[i]) > 1 else -1)
                probes.append((placed[c], placed[kids[c][0]]) if len(kids[c]) == 1 else (placed[k], placed[c]))
                # How straight the chain goes on: the cosine between the link and its next one.
                on, step = probes[-1][1] - probes[-1][0], placed[c] - placed[k]
                turns.append(float(on @ step) / max(float(np.linalg.norm(on) * np.linalg.norm(step)), 1e-300))
                at, owners = peaks(c)
                k0, o0 = before(k, length[c])
                k1, o1 = after(c, length[c])
                heads.append(placed[k])
                tails.append(placed[c])
                knot_rows.append(k0 + list(at) + k1)
                owner_rows.append(o0 + owners + o1)
            next_group += len(kids[k])
        else:  # an end joint (a hand, a head), a rider, a painted branch: its weight stays on it
            heads.append(placed[k])
            tails.append(placed[k])
            knot_rows.append([1.0])
            owner_rows.append([int(original[k])])
            groups.append(-1)
            probes.append((placed[k], placed[k]))
            turns.append(0.0)
        counts.append(len(heads) - starts[-1])
    width = max(len(r) for r in knot_rows) + 1
    knots = np.full((len(knot_rows), width), np.nan)
    owners = np.zeros((len(knot_rows), width), dtype=np.int64)
    for i, (r, o) in enumerate(zip(knot_rows, owner_rows)):
        knots[i, : len(r)] = r
        owners[i, : len(o)] = o
    probe = np.array(probes).reshape(-1, 2, 3)
    group, turn = np.array(groups, dtype=np.int64), np.array(turns)
    straightest = np.zeros(len(group), dtype=bool)
    for g in np.unique(group[group >= 0]):
        members = np.flatnonzero(group == g)
        straightest[members[np.argmax(turn[members])]] = True
    return _Links(np.array(starts), np.array(counts), np.array(heads), np.array(tails), knots, owners,
                  group, probe[:, 0], probe[:, 1], straightest)


def subjoint_bind_positions(skeleton: Skeleton, hierarchy: SubjointHierarchy, bind: dict | None = None) -> np.ndarray:
    """Bind-pose positions ``(J', 3)`` of the sub-joints.

    Original joints sit at the skin's ``bind`` positions where it gives them
    (otherwise at the parent's plus the rest offset); sub-joints are spaced
    evenly on their straight link.
    """
    positions = skeleton.rest_positions()
    if bind:
        for j in range(skeleton.num_joints):
            name = skeleton.names[j]
            if name in bind:
                positions[j] = bind[name]
            elif j > 0:
                positions[j] = positions[skeleton.parents[j]] + skeleton.offsets[j]
    f = hierarchy.fraction[:, None]
    parent = np.where(hierarchy.link_parent < 0, hierarchy.link_child, hierarchy.link_parent)
    return (1 - f) * positions[parent] + f * positions[hierarchy.link_child]


def pose_skin(skin: Skin, bind: np.ndarray, world_rot: np.ndarray, world_pos: np.ndarray,
              joint_index: np.ndarray, scale: np.ndarray | None = None) -> np.ndarray:
    """Linear blend skinning: vertices ``(..., V, 3)`` of ``skin`` posed by world transforms.

    bind : (J, 3) rest (bind) position of each skeleton joint;
    world_rot : (..., J, 4), world_pos : (..., J, 3), any leading axes (frames) broadcast;
    joint_index : (len(skin.joint_names),) skeleton index of each skin joint;
    scale : (..., J) world scale of each joint (the GLB's `mocap_exaggerate.jobs.outputs.output_thickness`) or None.
    The bind pose has identity orientations (BVH rest), so a vertex moves as
    ``s_j R_j (v - bind_j) + p_j`` under joint j.
    """
    joints = joint_index[skin.joints]  # (V, K)
    turned = quat_rotate(world_rot[..., joints, :], skin.vertices[:, None, :] - bind[joints])
    if scale is not None:
        turned = turned * scale[..., joints, None]
    moved = turned + world_pos[..., joints, :]
    return np.sum(skin.weights[..., None] * moved, axis=-2)
