"""Back from world positions to joint channels.

Until the sub-joint hierarchy exists this keeps every joint's captured
orientation and lets each link change length: every joint gets position and
rotation channels, its local translation expressed in its parent's captured
frame. Forward kinematics of the result reproduces the positions exactly.
"""

from __future__ import annotations

import numpy as np

from ..motion import Motion
from ..rotations import quat_inv, quat_rotate

__all__ = ["positions_to_motion"]


def positions_to_motion(world_pos: np.ndarray, source: Motion, world_rot: np.ndarray | None = None) -> Motion:
    """A 6-channel Motion on the source skeleton whose joints sit at ``world_pos``.

    world_pos : (F, J, 3) float64 target world positions, same F and J as ``source``
    source : the captured Motion; its local rotations are kept
    world_rot : (F, J, 4) float64, the source's world rotations if already computed
    """
    world_pos = np.asarray(world_pos, dtype=np.float64)
    expected = source.local_positions.shape
    if world_pos.shape != expected:
        raise ValueError(f"positions must be {expected}, got {world_pos.shape}")
    parents = source.skeleton.parents
    if world_rot is None:
        world_rot = source.world_rotations()
    local_pos = np.empty_like(world_pos)
    local_pos[:, 0] = world_pos[:, 0]
    link = world_pos[:, 1:] - world_pos[:, parents[1:]]
    local_pos[:, 1:] = quat_rotate(quat_inv(world_rot[:, parents[1:]]), link)
    return Motion(
        source.skeleton.with_full_channels(),
        source.frame_time,
        source.local_rotations,
        local_pos,
        source.euler_hint,
    )
