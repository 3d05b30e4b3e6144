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

import numpy as np

from ..motion import Motion
from ..rotations import quat_inv, quat_mul, quat_normalize, quat_rotate
from .subjoints import SubjointHierarchy

__all__ = ["positions_to_motion", "recover_orientations", "quat_between", "quat_slerp", "motion_from_world"]


def positions_to_motion(world_pos: np.ndarray, source: Motion, world_rot: np.ndarray | None = None) -> Motion:
    """A 6-channel Motion on the source skeleton whose joints sit at ``world_pos``, orientations as captured.

    world_pos : (F, J, 3) float64 target world positions, same F and J as ``source``
    source : the captured Motion; its local rotations are kept
    world_rot : (F, J, 4) float64, the source's world rotations if already computed
    """
    world_pos = np.asarray(world_pos, dtype=np.float64)
    expected = source.local_positions.shape
    if world_pos.shape != expected:
        raise ValueError(f"positions must be {expected}, got {world_pos.shape}")
    if world_rot is None:
        world_rot = source.world_rotations()
    return motion_from_world(world_pos, world_rot, source.skeleton.with_full_channels(), source.frame_time,
                             source.euler_hint)


def motion_from_world(world_pos, world_rot, skeleton, frame_time, euler_hint=None) -> Motion:
    """Local 6-DOF channels from world transforms ``(F, J, 3)`` and ``(F, J, 4)``."""
    parents = skeleton.parents
    local_pos = np.empty_like(world_pos)
    local_rot = np.empty_like(world_rot)
    local_pos[:, 0] = world_pos[:, 0]
    local_rot[:, 0] = world_rot[:, 0]
    inverse = quat_inv(world_rot[:, parents[1:]])
    local_pos[:, 1:] = quat_rotate(inverse, world_pos[:, 1:] - world_pos[:, parents[1:]])
    local_rot[:, 1:] = quat_normalize(quat_mul(inverse, world_rot[:, 1:]))
    return Motion(skeleton, frame_time, local_rot, local_pos, euler_hint)


def quat_between(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Smallest rotation carrying directions ``u`` onto ``v``, ``(..., 3) -> (..., 4)``.

    Identity where either vector is (nearly) zero; a half turn about some
    perpendicular axis where they are opposite.
    """
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    nu = np.linalg.norm(u, axis=-1, keepdims=True)
    nv = np.linalg.norm(v, axis=-1, keepdims=True)
    q = np.concatenate([np.cross(u, v), nu * nv + np.sum(u * v, axis=-1, keepdims=True)], axis=-1)
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    tiny = 1e-12 * np.maximum(nu * nv, 1e-300)
    opposite = (norm <= tiny) & (nu * nv > 0)
    if np.any(opposite):
        # Any axis perpendicular to u: cross with the coordinate axis least aligned with it.
        axis_index = np.argmin(np.abs(u), axis=-1)
        helper = np.eye(3)[axis_index]
        perpendicular = np.cross(u, helper)
        perpendicular /= np.maximum(np.linalg.norm(perpendicular, axis=-1, keepdims=True), 1e-300)
        flipped = np.concatenate([perpendicular, np.zeros(u.shape[:-1] + (1,))], axis=-1)
        q = np.where(opposite, flipped, q)
        norm = np.where(opposite, 1.0, norm)
    degenerate = (nu * nv <= 1e-300) | (norm <= 0)
    identity = np.zeros_like(q)
    identity[..., 3] = 1.0
    return np.where(degenerate, identity, q / np.where(norm > 0, norm, 1.0))


def quat_slerp(a: np.ndarray, b: np.ndarray, t: np.ndarray | float) -> np.ndarray:
    """Spherical interpolation from ``a`` (t = 0) to ``b`` (t = 1) along the shorter arc."""
    t = np.asarray(t, dtype=np.float64)[..., None] if np.ndim(t) else float(t)
    dot = np.sum(a * b, axis=-1, keepdims=True)
    b = np.where(dot < 0, -b, b)
    dot = np.abs(dot)
    angle = np.arccos(np.clip(dot, -1.0, 1.0))
    sin = np.sin(angle)
    close = sin < 1e-9
    safe = np.where(close, 1.0, sin)
    wa = np.where(close, 1.0 - t, np.sin((1.0 - t) * angle) / safe)
    wb = np.where(close, t, np.sin(t * angle) / safe)
    return quat_normalize(wa * a + wb * b)


def _kabsch(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotations ``(F, 4)`` best carrying vector sets ``u (F, n, 3)`` onto ``v (F, n, 3)``."""
    from scipy.spatial.transform import Rotation

    h = np.einsum("fni,fnj->fij", u, v)
    left, _, right_t = np.linalg.svd(h)
    d = np.sign(np.linalg.det(np.einsum("fij,fjk->fik", left, right_t)))
    d = np.where(d == 0, 1.0, d)
    fix = np.ones(h.shape[:1] + (3,))
    fix[:, 2] = d
    matrix = np.einsum("fji,fj,fkj->fik", right_t, fix, left)
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

    for j in range(skeleton.num_joints):
        if rigid[j]:
            continue
        targets = _first_at_distance(skeleton, j, rigid)
        if len(targets) >= 2:
            u = source_pos[:, targets] - source_pos[:, j : j + 1]
            v = new_pos[:, targets] - new_pos[:, j : j + 1]
            sizes = np.linalg.svd(u[len(u) // 2], compute_uv=False)
            spread = sizes[1] > 1e-2 * sizes[0]
            turn = _kabsch(u, v) if spread else quat_between(u[:, 0], v[:, 0])
        elif len(targets) == 1:
            t = targets[0]
            turn = quat_between(source_pos[:, t] - source_pos[:, j], new_pos[:, t] - new_pos[:, j])
        else:
            above = _first_above_at_distance(skeleton, j)
            if above < 0:
                turn = np.tile([0.0, 0.0, 0.0, 1.0], (frames, 1))
            else:
                turn = quat_between(source_pos[:, j] - source_pos[:, above], new_pos[:, j] - new_pos[:, above])
        world[:, j] = quat_normalize(quat_mul(turn, source_rot[:, j]))

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
        out[:, between] = quat_slerp(
            world[:, hierarchy.link_parent[between]],
            world[:, hierarchy.link_child[between]],
            hierarchy.fraction[between][None, :],
        )
    return out, sub_pos
