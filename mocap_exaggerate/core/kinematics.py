"""Forward kinematics, world-to-local and rest positions over whole clips.

A skeleton here is its ``parents`` vector (-1 for the root, every parent
before its children); transforms are arrays ``(F, J, ...)``. Forward
kinematics loops over joints only, every frame at once; world-to-local (the
"ik" of orangeduck's and LAFAN1's code) needs no loop at all:
``local_rot = quat_inv(parent_rot) * world_rot``.
"""

from __future__ import annotations

import numpy as np

from .native import frame_halves, on_both_cores
from .native import kernels as _kernels  # the compiled loops, where built (core/native.py)
from .rotations import CACHE_ELEMENTS, quat_inv, quat_mul, quat_rotate

__all__ = ["forward_kinematics", "local_from_world", "parent_rotations", "rest_positions", "frame_blocks", "cache_blocks",
           "consecutive", "link_vectors", "CACHE_ELEMENTS"]


def forward_kinematics(
    parents: np.ndarray, local_rot: np.ndarray, local_pos: np.ndarray, *, compiled: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """World rotations ``(F, J, 4)`` and positions ``(F, J, 3)`` from local transforms.

    parents : (J,) int, -1 for the root, ``parents[j] < j``
    local_rot : (F, J, 4) float64 unit quaternions, each joint's rotation in its parent's frame
    local_pos : (F, J, 3) float64, each joint's translation from its parent (the root's: world)

    The work is done joint by joint on ``(J, F, ...)`` copies, so each
    joint's frames are contiguous in memory, by ``core/_kernels.c`` where it was
    built (``compiled``: the same bits, about half the time; the copies are the rest).
    """
    parents = np.asarray(parents)
    # Always copies: for a single frame the swapped view is contiguous already, and writing into
    # it changed the caller's motion (and the clip a one-frame slice was cut from).
    rot = np.array(np.swapaxes(local_rot, 0, 1), dtype=np.float64, order="C")
    pos = np.array(np.swapaxes(local_pos, 0, 1), dtype=np.float64, order="C")
    if (compiled and _kernels is not None and rot.ndim == 3 and rot.shape[2:] == (4,)
            and pos.shape == rot.shape[:2] + (3,) and len(parents) == len(rot)):
        _kernels.forward_kinematics(np.ascontiguousarray(parents, dtype=np.int64), rot, pos, rot.shape[1], len(rot))
        return np.swapaxes(rot, 0, 1), np.swapaxes(pos, 0, 1)
    for j in range(1, len(parents)):
        p = parents[j]
        pos[j] = pos[p] + quat_rotate(rot[p], pos[j])
        rot[j] = quat_mul(rot[p], rot[j])
    return np.swapaxes(rot, 0, 1), np.swapaxes(pos, 0, 1)


def local_from_world(
    parents: np.ndarray, world_rot: np.ndarray, world_pos: np.ndarray, *, overwrite_rotations: bool = False,
    compiled: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Local rotations ``(F, J, 4)`` and translations ``(F, J, 3)`` from world transforms.

    The inverse of `forward_kinematics`, loop-free: each joint's transform
    in its parent's frame. With ``overwrite_rotations`` the local rotations are
    written over ``world_rot`` (a float64 array), a block of frames at a time
    (each block read whole before it is written): a long clip's copy saved.
    ``compiled``: by ``core/_kernels.c`` where it was built (the same bits, a tenth of the time).
    """
    parents = np.asarray(parents)
    if overwrite_rotations and not (isinstance(world_rot, np.ndarray) and world_rot.dtype == np.float64):
        raise TypeError("overwrite_rotations needs world_rot as a float64 array")
    world_rot = np.asarray(world_rot, dtype=np.float64)
    world_pos = np.asarray(world_pos, dtype=np.float64)
    local_rot = world_rot if overwrite_rotations else np.empty(world_rot.shape)
    local_pos = np.empty(world_pos.shape)
    if (compiled and _kernels is not None and world_rot.ndim == 3 and world_rot.shape[2:] == (4,)
            and world_pos.shape == world_rot.shape[:2] + (3,) and len(parents) == world_rot.shape[1]
            and world_rot.flags.c_contiguous and world_pos.flags.c_contiguous):
        parents = np.ascontiguousarray(parents, dtype=np.int64)
        joints = world_rot.shape[1]
        on_both_cores(lambda part: _kernels.local_from_world(
            parents, world_rot[part], world_pos[part], local_rot[part], local_pos[part], part.stop - part.start,
            joints), frame_halves(len(world_rot)))
        return local_rot, local_pos
    local_rot[:, 0] = world_rot[:, 0]
    local_pos[:, 0] = world_pos[:, 0]
    if len(parents) > 1:
        for part in cache_blocks(len(world_rot), len(parents) - 1):  # (the same arithmetic, in the cache)
            inverse = quat_inv(world_rot[part, parents[1:]])
            local_rot[part, 1:] = quat_mul(inverse, world_rot[part, 1:])
            local_pos[part, 1:] = quat_rotate(inverse, world_pos[part, 1:] - world_pos[part, parents[1:]])
    return local_rot, local_pos


def parent_rotations(parents: np.ndarray, world: np.ndarray) -> np.ndarray:
    """``(J, 4)``: each joint's parent's world rotation of one pose ``world (J, 4)``, the identity for the root."""
    from .rotations import quat_identity

    return np.concatenate([quat_identity((1,)), np.asarray(world)[np.asarray(parents)[1:]]])


def frame_blocks(frames: int, size: int = 1024):
    """Slices covering ``range(frames)`` in blocks: per-frame work done block by block keeps memory flat."""
    return [slice(start, min(start + size, frames)) for start in range(0, frames, size)]


def cache_blocks(frames: int, per_frame: int):
    """`frame_blocks` of about `CACHE_ELEMENTS` elements, ``per_frame`` to a frame (at least 16 frames):
    per-frame work then stays in the cache instead of streaming whole clips through memory (world-to-local
    on 100,000 frames of 95 joints took five times as long in blocks of 1,024 frames)."""
    return frame_blocks(frames, max(CACHE_ELEMENTS // max(per_frame, 1), 16))


def link_vectors(positions: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """``positions[:, 1:] - positions[:, parents[1:]]``: every joint's link from its parent ``(F, J - 1, 3)``,
    the parents gathered by ``np.take`` (a third of the time of indexing along the joints)."""
    positions = np.asarray(positions)
    return positions[:, 1:] - np.take(positions, np.asarray(parents)[1:], axis=1)


def consecutive(indices: np.ndarray, size: int) -> np.ndarray | slice:
    """Integer ``indices`` into an axis of ``size`` as a slice where they are consecutive and within it (a limb's
    rubber chain is), else as they are (negative, past the end, a mask: indexing says what they mean, or raises):
    an array indexed by the slice is a view, changed in place, not gathered and put back."""
    indices = np.asarray(indices)
    if (indices.ndim == 1 and len(indices) and np.issubdtype(indices.dtype, np.integer) and 0 <= indices[0]
            and indices[0] + len(indices) <= size
            and np.array_equal(indices, np.arange(indices[0], indices[0] + len(indices)))):
        return slice(int(indices[0]), int(indices[0]) + len(indices))
    return indices


def rest_positions(parents: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """World positions ``(J, 3)`` of the joints when every rotation is zero (offsets only)."""
    offsets = np.asarray(offsets, dtype=np.float64)
    pos = np.zeros(offsets.shape)
    pos[0] = offsets[0]
    for j in range(1, len(parents)):
        pos[j] = pos[parents[j]] + offsets[j]
    return pos
