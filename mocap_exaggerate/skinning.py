"""Skins: the `Skin` type, influence pruning, and weight redistribution onto sub-joints.

A skin is stored sparsely, as glTF does: for each vertex the indices of its
strongest joints and their weights, ``(V, K)`` each, rows summing to 1.

Redistribution (Kwon & Lee 2008, section 6):

A vertex bound to original joint k with weight w is re-bound to k's
sub-joints with weights proportional to the inverse distance from the vertex
to each sub-link segment in the rest pose, summing to w; then the strongest
influences are kept and renormalised. k's sub-joints are k itself and the
sub-joints on the links from k to its children, each owning the sub-link
that starts at it (a bone moves with its head joint).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import ConfigError
from .skeleton import Skeleton
from .stages.subjoints import SubjointHierarchy

__all__ = ["Skin", "top_influences", "reweight", "segment_distance", "subjoint_bind_positions"]


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
        `mocap_exaggerate.binding` uses it to fit a character to another rig.
    """

    vertices: np.ndarray
    faces: np.ndarray
    joint_names: tuple[str, ...]
    joints: np.ndarray
    weights: np.ndarray
    bind: dict = field(default_factory=dict)
    parents: dict = field(default_factory=dict)

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
    return np.linalg.norm(points - closest, axis=-1)


def reweight(skin: Skin, skeleton: Skeleton, hierarchy: SubjointHierarchy, *, max_influences: int = 4) -> Skin:
    """The skin re-bound to the sub-joint skeleton of ``hierarchy``.

    skin : bound to (a subset of) ``skeleton``'s joints by name, in its rest pose
    Returns a Skin whose joint names are the sub-joint skeleton's.
    """
    sub = hierarchy.skeleton
    rest = subjoint_bind_positions(skeleton, hierarchy, skin.bind)
    index = {name: j for j, name in enumerate(skeleton.names)}
    unknown = [n for n in skin.joint_names if n not in index]
    if unknown:
        raise ConfigError(f"skin joints not in the skeleton: {', '.join(unknown[:5])}")
    to_original = np.array([index[n] for n in skin.joint_names], dtype=np.int64)

    # Segments owned by each original joint, as a CSR list: seg_start[k]:seg_start[k + 1].
    owner = np.array([_owner(hierarchy, int(p)) for p in sub.parents[1:]], dtype=np.int64)
    order = np.argsort(owner, kind="stable")
    seg_head = (sub.parents[1:])[order].astype(np.int64)
    seg_tail = np.arange(1, sub.num_joints)[order]
    counts = np.bincount(owner, minlength=skeleton.num_joints)
    # Leaf joints own no segment: their weight stays on the joint itself (a zero-length segment).
    lonely = np.flatnonzero(counts == 0)
    seg_head = np.concatenate([seg_head, hierarchy.original[lonely]])
    seg_tail = np.concatenate([seg_tail, hierarchy.original[lonely]])
    owner_sorted = np.concatenate([owner[order], lonely])
    order = np.argsort(owner_sorted, kind="stable")
    seg_head, seg_tail, owner_sorted = seg_head[order], seg_tail[order], owner_sorted[order]
    counts = np.bincount(owner_sorted, minlength=skeleton.num_joints)
    seg_start = np.concatenate([[0], np.cumsum(counts)])

    # Every (vertex, original joint, weight) entry, expanded to one row per owned segment.
    vertex = np.repeat(np.arange(skin.num_vertices), skin.joints.shape[1])
    original = to_original[skin.joints.ravel()]
    weight = skin.weights.ravel()
    keep = weight > 0
    vertex, original, weight = vertex[keep], original[keep], weight[keep]
    per_entry = counts[original]
    floor = 1e-6 * max(sub.height(), 1e-9)
    # In blocks of whole entries of about a million segment rows: a joint that owns hundreds of
    # sub-links (a root with many children) would otherwise expand to gigabytes. Each entry
    # keeps only its strongest few rows: a vertex's strongest influences are among them.
    ends = np.cumsum(per_entry)
    rows, cols, vals = [], [], []
    first = 0
    while first < len(vertex):
        last = max(first + 1, int(np.searchsorted(ends, (ends[first - 1] if first else 0) + 1_000_000, "right")))
        block = np.arange(first, last)
        count = per_entry[block]
        entry = np.repeat(np.arange(len(block)), count)
        within = np.arange(len(entry)) - np.repeat(np.cumsum(count) - count, count)
        segment = seg_start[original[block]][entry] + within
        distance = segment_distance(skin.vertices[vertex[block][entry]], rest[seg_head[segment]], rest[seg_tail[segment]])
        inverse = 1.0 / np.maximum(distance, floor)
        values = inverse / np.bincount(entry, weights=inverse, minlength=len(block))[entry] * weight[block][entry]
        # Segments that start at the same sub-joint (a hip's links to each leg) are one influence:
        # sum them per (entry, sub-joint) first, then keep each entry's strongest sub-joints.
        heads = seg_head[segment]
        order = np.lexsort((heads, entry))
        new = np.concatenate([[True], (entry[order][1:] != entry[order][:-1]) | (heads[order][1:] != heads[order][:-1])])
        starts = np.flatnonzero(new)
        pair_entry, pair_head = entry[order][starts], heads[order][starts]
        pair_value = np.add.reduceat(values[order], starts)
        ranked = np.lexsort((-pair_value, pair_entry))  # by entry, strongest first
        sizes = np.bincount(pair_entry, minlength=len(block))
        rank = np.arange(len(ranked)) - np.repeat(np.cumsum(sizes) - sizes, sizes)
        strongest = ranked[rank < max_influences]
        rows.append(vertex[block][pair_entry[strongest]])
        cols.append(pair_head[strongest])
        vals.append(pair_value[strongest])
        first = last
    joints, weights = top_influences(np.concatenate(rows or [np.zeros(0, np.int64)]),
                                     np.concatenate(cols or [np.zeros(0, np.int64)]),
                                     np.concatenate(vals or [np.zeros(0)]), skin.num_vertices, max_influences)
    return Skin(skin.vertices, skin.faces, sub.names, joints, weights)


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


def _owner(hierarchy: SubjointHierarchy, joint: int) -> int:
    """The original joint whose bone a sub-joint belongs to: itself, or the link's parent."""
    if hierarchy.fraction[joint] == 1.0:
        return int(hierarchy.link_child[joint])
    return int(hierarchy.link_parent[joint])
