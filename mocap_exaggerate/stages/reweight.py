"""Skin weight redistribution onto sub-joints (Kwon & Lee 2008, section 6).

A vertex bound to original joint k with weight w is re-bound to k's
sub-joints with weights proportional to the inverse distance from the vertex
to each sub-link segment in the rest pose, summing to w; then the strongest
influences are kept and renormalised. k's sub-joints are k itself and the
sub-joints on the links from k to its children, each owning the sub-link
that starts at it (a bone moves with its head joint).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError
from ..io.skin import Skin, top_influences
from ..skeleton import Skeleton
from .subjoints import SubjointHierarchy

__all__ = ["reweight", "segment_distance", "subjoint_bind_positions", "ReweightConfig"]


@dataclass(frozen=True, kw_only=True)
class ReweightConfig:
    """max_influences : joints kept per vertex, 4 (one glTF set) or 8 (two sets)."""

    max_influences: int = 4

    def __post_init__(self) -> None:
        if self.max_influences not in (4, 8):
            raise ConfigError(f"reweight.max_influences must be 4 or 8, got {self.max_influences!r}")


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
    entry = np.repeat(np.arange(len(vertex)), per_entry)
    segment = seg_start[original][entry] + (np.arange(len(entry)) - np.repeat(np.cumsum(per_entry) - per_entry, per_entry))
    distance = segment_distance(skin.vertices[vertex[entry]], rest[seg_head[segment]], rest[seg_tail[segment]])
    floor = 1e-6 * max(sub.height(), 1e-9)
    inverse = 1.0 / np.maximum(distance, floor)
    share = inverse / np.bincount(entry, weights=inverse, minlength=len(vertex))[entry]
    values = share * weight[entry]
    joints, weights = top_influences(vertex[entry], seg_head[segment], values, skin.num_vertices, max_influences)
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
