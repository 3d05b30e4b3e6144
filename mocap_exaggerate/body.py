"""The default character: a body grown from the skeleton itself.

Each link becomes a capsule (thick enough to read as a limb, thin enough to
show the skeleton's proportions); the capsules are merged into one watertight
mesh with Manifold's boolean union (manifold3d, called directly: going
through trimesh would cost its 0.33 s import on every command), and each vertex is weighted to the joints
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
    import manifold3d

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
    if not len(heads):  # a skeleton with no link at all: a ball on the root
        heads, tails, radii = np.array([0]), np.array([0]), np.array([0.05 * max(height, 1e-3)])
    # Humanoids have 20 to 100 capsules. Beyond MAX_UNION (a root with hundreds of children) the
    # union's cost grows much faster than the count (600 took minutes): the capsules are then
    # kept as separate closed pieces, coarser, so the body stays bounded in time and size.
    many = len(heads) > MAX_UNION
    segments = max(8, int(_SEGMENTS * np.sqrt(MAX_UNION / len(heads)))) if many else _SEGMENTS
    capsules = [_capsule(points[a], points[b], r, segments) for a, b, r in zip(heads, tails, radii)]
    if many:
        meshes = [capsule.to_mesh64() for capsule in capsules]
    else:
        body = manifold3d.Manifold.batch_boolean(capsules, manifold3d.OpType.Add) if len(capsules) > 1 else capsules[0]
        meshes = [body.to_mesh64()]
    pieces = [np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3] for mesh in meshes]
    starts = np.cumsum([0] + [len(piece) for piece in pieces[:-1]])
    vertices = np.concatenate(pieces)
    faces = np.concatenate([np.asarray(mesh.tri_verts, dtype=np.int64) + start for mesh, start in zip(meshes, starts)])
    if many:
        # Separate pieces: each moves with its own link's head joint (no search over thousands of links).
        owner = np.repeat(heads, [len(piece) for piece in pieces])
        joints = np.zeros((len(vertices), 4), dtype=np.int64)
        weights = np.zeros((len(vertices), 4))
        joints[:, 0], weights[:, 0] = owner, 1.0
        return Skin(vertices, faces, skeleton.names, joints, weights)
    # Weights: inverse fourth power of the distance to the nearest four links, each link
    # moving with its head joint (an End Site's link with the joint itself).
    count = min(4, len(heads))
    nearest = np.empty((len(vertices), count), dtype=np.int64)
    strength = np.empty((len(vertices), count))
    block = max(1, 2_000_000 // len(heads))  # vertices x links per block: memory stays flat on big rigs
    for start in range(0, len(vertices), block):
        part = slice(start, start + block)
        distance = segment_distance(vertices[part, None, :], points[heads][None], points[tails][None])
        distance = np.maximum(distance - radii[None] * 0.5, 1e-3 * height)
        nearest[part] = np.argsort(distance, axis=1, kind="stable")[:, :count]
        strength[part] = 1.0 / np.take_along_axis(distance, nearest[part], axis=1) ** 4
    rows = np.repeat(np.arange(len(vertices)), nearest.shape[1])
    joints, weights = top_influences(rows, heads[nearest].ravel(), strength.ravel(), len(vertices), 4)
    return Skin(vertices, faces, skeleton.names, joints, weights)


def _capsule(a: np.ndarray, b: np.ndarray, radius: float, segments: int = 20):
    """A capsule (a ``manifold3d.Manifold``) from point ``a`` to ``b``: the hull of two spheres."""
    import manifold3d

    ball = manifold3d.Manifold.sphere(float(radius), segments)
    if np.allclose(a, b):
        return ball.translate(tuple(float(v) for v in a))
    return manifold3d.Manifold.batch_hull([ball.translate(tuple(float(v) for v in a)),
                                           ball.translate(tuple(float(v) for v in b))])


#: Segments around each capsule: 20 reads as round in a preview; bodies come out at 1.1k-1.6k vertices.
_SEGMENTS = 20
#: Most capsules merged by a boolean union; more are kept as separate pieces.
MAX_UNION = 150
