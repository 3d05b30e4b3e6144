"""Orientation recovery (Kwon & Lee 2008, section 6): from positions back to joint channels.

Sub-joints that sit on original joints take the original joint's captured
world orientation turned by the smallest rotation that carries its original
link direction onto the new one; sub-joints between two original joints
slerp between their orientations. Because link lengths change, every output
joint carries position and rotation channels (6 DOF), and forward kinematics
of the result reproduces the positions exactly.

Which "link" turns a joint: its one outgoing link; at a branch joint (hips,
chest) the rotation that best carries all of its outgoing links (a Kabsch
fit; the smallest rotation when the links are collinear); at an end
effector its incoming link. Zero-length links are looked through to the
first joint at a distance. Branches pruned as minor (fingers, toes, face)
ride rigidly: their captured local transforms are applied under the
recovered parent.
"""

from __future__ import annotations

import numba
import numpy as np

from ..motion import Motion
from ..rotations import _cross, quat_mul, quat_normalize, quat_rotate, quat_slerp, slerp_into
from .subjoints import SubjointHierarchy

__all__ = ["recover_orientations", "quat_between", "quat_slerp", "motion_from_world"]


def motion_from_world(world_pos, world_rot, skeleton, frame_time, euler_hint=None) -> Motion:
    """Local 6-DOF channels from world transforms ``(F, J, 3)`` and ``(F, J, 4)``."""
    world_pos = np.ascontiguousarray(world_pos, dtype=np.float64)
    world_rot = np.ascontiguousarray(world_rot, dtype=np.float64)
    local_pos = np.empty_like(world_pos)
    local_rot = np.empty_like(world_rot)
    _local_from_world(world_pos, world_rot, np.asarray(skeleton.parents, dtype=np.int64), local_pos, local_rot)
    return Motion(skeleton, frame_time, local_rot, local_pos, euler_hint)


@numba.njit(cache=True)
def _local_from_world(world_pos, world_rot, parents, local_pos, local_rot):  # pragma: no cover - compiled
    """Each joint's transform in its parent's frame; one pass, no temporaries."""
    frames, joints = world_pos.shape[0], world_pos.shape[1]
    for f in range(frames):
        for a in range(3):
            local_pos[f, 0, a] = world_pos[f, 0, a]
        for a in range(4):
            local_rot[f, 0, a] = world_rot[f, 0, a]
        for j in range(1, joints):
            p = parents[j]
            # Inverse (conjugate) of the parent's rotation.
            ux, uy, uz, w = -world_rot[f, p, 0], -world_rot[f, p, 1], -world_rot[f, p, 2], world_rot[f, p, 3]
            vx = world_pos[f, j, 0] - world_pos[f, p, 0]
            vy = world_pos[f, j, 1] - world_pos[f, p, 1]
            vz = world_pos[f, j, 2] - world_pos[f, p, 2]
            tx = 2.0 * (uy * vz - uz * vy)
            ty = 2.0 * (uz * vx - ux * vz)
            tz = 2.0 * (ux * vy - uy * vx)
            local_pos[f, j, 0] = vx + w * tx + (uy * tz - uz * ty)
            local_pos[f, j, 1] = vy + w * ty + (uz * tx - ux * tz)
            local_pos[f, j, 2] = vz + w * tz + (ux * ty - uy * tx)
            bx, by, bz, bw = world_rot[f, j, 0], world_rot[f, j, 1], world_rot[f, j, 2], world_rot[f, j, 3]
            local_rot[f, j, 0] = w * bx + ux * bw + uy * bz - uz * by
            local_rot[f, j, 1] = w * by - ux * bz + uy * bw + uz * bx
            local_rot[f, j, 2] = w * bz + ux * by - uy * bx + uz * bw
            local_rot[f, j, 3] = w * bw - ux * bx - uy * by - uz * bz


@numba.njit(cache=True)
def _slerp_links(world, first, second, fraction, out, target):  # pragma: no cover - compiled
    """out[:, target[s]] = slerp(world[:, first[s]], world[:, second[s]], fraction[s])."""
    for f in range(world.shape[0]):
        for s in range(first.shape[0]):
            slerp_into(world[f, first[s]], world[f, second[s]], fraction[s], out[f, target[s]])


def quat_between(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Smallest rotation carrying directions ``u`` onto ``v``, ``(..., 3) -> (..., 4)``.

    Identity where either vector is (nearly) zero; a half turn about some
    perpendicular axis where they are opposite.
    """
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    nu = np.linalg.norm(u, axis=-1, keepdims=True)
    nv = np.linalg.norm(v, axis=-1, keepdims=True)
    q = np.concatenate([_cross(u, v), nu * nv + np.sum(u * v, axis=-1, keepdims=True)], axis=-1)
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    tiny = 1e-12 * np.maximum(nu * nv, 1e-300)
    opposite = (norm <= tiny) & (nu * nv > 0)
    if np.any(opposite):
        # Any axis perpendicular to u: cross with the coordinate axis least aligned with it.
        axis_index = np.argmin(np.abs(u), axis=-1)
        helper = np.eye(3)[axis_index]
        perpendicular = _cross(u, helper)
        perpendicular /= np.maximum(np.linalg.norm(perpendicular, axis=-1, keepdims=True), 1e-300)
        flipped = np.concatenate([perpendicular, np.zeros(u.shape[:-1] + (1,))], axis=-1)
        q = np.where(opposite, flipped, q)
        norm = np.where(opposite, 1.0, norm)
    degenerate = (nu * nv <= 1e-300) | (norm <= 0)
    identity = np.zeros_like(q)
    identity[..., 3] = 1.0
    return np.where(degenerate, identity, q / np.where(norm > 0, norm, 1.0))


def _triad(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotations ``(F, 4)`` carrying vector sets ``u (F, n, 3)`` onto ``v (F, n, 3)`` (TRIAD).

    The first axis is the mean direction of the set, the second the member
    farthest from it; exact when ``v`` is a rotated ``u``, and a few vector
    operations instead of a per-frame SVD.
    """
    from scipy.spatial.transform import Rotation

    def frame(vectors: np.ndarray, pick: int) -> np.ndarray:
        first = vectors.mean(axis=1)
        first /= np.maximum(np.linalg.norm(first, axis=-1, keepdims=True), 1e-300)
        second = _cross(first, vectors[:, pick])
        second /= np.maximum(np.linalg.norm(second, axis=-1, keepdims=True), 1e-300)
        return np.stack([first, second, _cross(first, second)], axis=-1)

    middle = len(u) // 2
    mean = u[middle].mean(axis=0)
    pick = int(np.argmax(np.linalg.norm(np.cross(mean, u[middle]), axis=-1)))
    matrix = np.einsum("fij,fkj->fik", frame(v, pick), frame(u, pick))
    return Rotation.from_matrix(matrix).as_quat()


def _effective_lengths(skeleton) -> np.ndarray:
    """Rest link lengths, with links under 1e-4 of the skeleton height counted as zero.

    Some rigs park a joint a hair from its parent (Reallusion's pelvis sits
    1e-5 cm from the hip); its direction means nothing.
    """
    lengths = skeleton.link_lengths()
    return np.where(lengths < 1e-4 * skeleton.height(), 0.0, lengths)


def _first_at_distance(skeleton, joint: int, rigid: np.ndarray) -> list[int]:
    """For each kept child branch of ``joint``, the first joint down it at non-zero rest distance."""
    lengths = _effective_lengths(skeleton)
    out = []
    for child in skeleton.children(joint):
        if rigid[child]:
            continue
        current = int(child)
        while lengths[current] <= 0:
            below = [int(c) for c in skeleton.children(current) if not rigid[c]]
            if len(below) != 1:
                break
            current = below[0]
        if lengths[current] > 0 or current != child:
            out.append(current)
    return out


def _first_above_at_distance(skeleton, joint: int) -> int:
    lengths = _effective_lengths(skeleton)
    current = joint
    while current > 0 and lengths[current] <= 0:
        current = int(skeleton.parents[current])
    return int(skeleton.parents[current]) if current > 0 else -1


def recover_orientations(
    sub_pos: np.ndarray,
    hierarchy: SubjointHierarchy,
    source: Motion,
    source_rot: np.ndarray,
    source_pos: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """World orientations ``(F, J', 4)`` of every sub-joint, and positions with rigid branches placed.

    sub_pos : (F, J', 3) float64 sub-joint positions (rigid branches' entries are replaced)
    hierarchy : the sub-joint hierarchy of ``source.skeleton``
    source : the captured Motion (its local transforms place rigid branches)
    source_rot, source_pos : (F, J, 4) and (F, J, 3) captured world transforms
    """
    skeleton = source.skeleton
    original = hierarchy.original
    rigid = hierarchy.rigid
    sub_pos = np.array(sub_pos, dtype=np.float64)
    new_pos = sub_pos[:, original]
    frames = sub_pos.shape[0]
    world = np.zeros((frames, skeleton.num_joints, 4))
    world[..., 3] = 1.0

    single_joint, single_from, single_to = [], [], []
    for j in range(skeleton.num_joints):
        if rigid[j]:
            continue
        targets = _first_at_distance(skeleton, j, rigid)
        if len(targets) >= 2:
            u = source_pos[:, targets] - source_pos[:, j : j + 1]
            v = new_pos[:, targets] - new_pos[:, j : j + 1]
            sizes = np.linalg.svd(u[len(u) // 2], compute_uv=False)
            if sizes[1] > 1e-2 * sizes[0]:
                world[:, j] = quat_mul(_triad(u, v), source_rot[:, j])
                continue
            targets = targets[:1]
        if len(targets) == 1:
            single_joint.append(j)
            single_from.append(j)
            single_to.append(targets[0])
        else:
            above = _first_above_at_distance(skeleton, j)
            if above >= 0:
                single_joint.append(j)
                single_from.append(above)
                single_to.append(j)
            else:
                world[:, j] = source_rot[:, j]
    if single_joint:
        # One vectorised call for every joint turned by a single link.
        turn = quat_between(
            source_pos[:, single_to] - source_pos[:, single_from], new_pos[:, single_to] - new_pos[:, single_from]
        )
        world[:, single_joint] = quat_normalize(quat_mul(turn, source_rot[:, single_joint]))

    # Rigid branches: captured local transforms under the recovered parent.
    for j in range(1, skeleton.num_joints):
        if not rigid[j]:
            continue
        p = skeleton.parents[j]
        world[:, j] = quat_mul(world[:, p], source.local_rotations[:, j])
        new_pos[:, j] = new_pos[:, p] + quat_rotate(world[:, p], source.local_positions[:, j])
    sub_pos[:, original] = new_pos

    out = np.empty(sub_pos.shape[:2] + (4,))
    out[:, original] = world
    between = np.flatnonzero(~hierarchy.is_original)
    if len(between):
        _slerp_links(
            np.ascontiguousarray(world),
            hierarchy.link_parent[between].astype(np.int64),
            hierarchy.link_child[between].astype(np.int64),
            hierarchy.fraction[between].astype(np.float64),
            out,
            between.astype(np.int64),
        )
    return out, sub_pos
