"""The default character: a body grown from the skeleton itself.

Each link becomes a capsule (thick enough to read as a limb, thin enough to
show the skeleton's proportions); the capsules are merged into one watertight
mesh with trimesh's boolean union, and each vertex is weighted to the joints
whose links it is nearest (inverse fourth power of the distance over the
four nearest links), so joints bend smoothly.
"""

from __future__ import annotations

import numpy as np

from .skeleton import Skeleton
from .skinning import Skin, segment_distance, top_influences

__all__ = ["default_skin"]


def default_skin(skeleton: Skeleton, rigid: np.ndarray | None = None) -> Skin:
    """A capsule body around ``skeleton``'s rest pose, weighted to its joints.

    rigid : (J,) bool, joints (fingers, toes, face) too small to get their own capsule
    """
    import trimesh  # imported here: trimesh and manifold3d take 0.15 s to load

    rest = skeleton.rest_positions()
    height = skeleton.height()
    heads, tails = [], []
    for j in range(1, skeleton.num_joints):
        if rigid is None or not rigid[j]:
            heads.append(skeleton.parents[j])
            tails.append(j)
    ends = np.flatnonzero(np.isfinite(skeleton.end_sites[:, 0]))
    points = np.concatenate([rest, rest[ends] + skeleton.end_sites[ends]])
    for k, j in enumerate(ends):
        if rigid is None or not rigid[j]:
            heads.append(j)
            tails.append(skeleton.num_joints + k)
    heads, tails = np.array(heads, dtype=np.int64), np.array(tails, dtype=np.int64)
    lengths = np.linalg.norm(points[tails] - points[heads], axis=1)
    keep = lengths > 1e-4 * height  # short links still get a (round) capsule: no gaps at the joints
    heads, tails, lengths = heads[keep], tails[keep], lengths[keep]
    radii = np.clip(0.22 * lengths, 0.025 * height, 0.05 * height)
    capsules = [_capsule(points[a], points[b], r) for a, b, r in zip(heads, tails, radii)]
    if not capsules:  # a skeleton with no link at all: a ball on the root
        capsules = [trimesh.creation.icosphere(subdivisions=2, radius=0.05 * max(height, 1e-3))]
        capsules[0].apply_translation(rest[0])
        heads, tails, radii = np.array([0]), np.array([0]), np.array([0.05 * max(height, 1e-3)])
    body = trimesh.boolean.union(capsules, engine="manifold") if len(capsules) > 1 else capsules[0]
    vertices = np.asarray(body.vertices, dtype=np.float64)
    faces = np.asarray(body.faces, dtype=np.int64)
    # Weights: inverse fourth power of the distance to the nearest four links, each link
    # moving with its head joint (an End Site's link with the joint itself).
    distance = segment_distance(vertices[:, None, :], points[heads][None], points[tails][None])
    distance = np.maximum(distance - radii[None] * 0.5, 1e-3 * height)
    nearest = np.argsort(distance, axis=1)[:, :4]
    strength = 1.0 / np.take_along_axis(distance, nearest, axis=1) ** 4
    rows = np.repeat(np.arange(len(vertices)), nearest.shape[1])
    joints, weights = top_influences(rows, heads[nearest].ravel(), strength.ravel(), len(vertices), 4)
    return Skin(vertices, faces, skeleton.names, joints, weights)


def _capsule(a: np.ndarray, b: np.ndarray, radius: float):
    """A capsule (trimesh.Trimesh) from point ``a`` to ``b``."""
    import trimesh

    length = float(np.linalg.norm(b - a))
    capsule = trimesh.creation.capsule(height=length, radius=radius, count=[12, 12])
    # trimesh builds it along Z, centred on the origin.
    direction = (b - a) / length
    transform = trimesh.geometry.align_vectors([0.0, 0.0, 1.0], direction)
    transform[:3, 3] = (a + b) / 2.0
    capsule.apply_transform(transform)
    return capsule
