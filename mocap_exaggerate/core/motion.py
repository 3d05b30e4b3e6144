"""Motion: a skeleton plus per-frame local transforms, and forward kinematics."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .kinematics import forward_kinematics, parent_rotations
from .rotations import quat_inv, quat_mul, quat_rotate
from .skeleton import Skeleton

__all__ = ["Motion"]


@dataclass(frozen=True, eq=False)
class Motion:
    """A clip: skeleton, frame time and local transforms of every joint.

    Attributes
    ----------
    skeleton : Skeleton with J joints
    frame_time : float, seconds per frame
    local_rotations : (F, J, 4) float64 unit quaternions (x, y, z, w)
    local_positions : (F, J, 3) float64, each joint's translation from its
        parent: the rest offset where a joint has no position channels, the
        channel values where it has them. For the root this is the root
        translation.
    euler_hint : (F, J, 3) float64 or None, Euler angles in degrees (each
        joint's own order) that the BVH writer stays nearest to when it picks
        among equivalent angle triples; the reader fills it with the angles
        it read, so an unchanged clip writes back the same channels.
    """

    skeleton: Skeleton
    frame_time: float
    local_rotations: np.ndarray
    local_positions: np.ndarray
    euler_hint: np.ndarray | None = None

    def __post_init__(self) -> None:
        j = self.skeleton.num_joints
        rot = np.asarray(self.local_rotations, dtype=np.float64)
        pos = np.asarray(self.local_positions, dtype=np.float64)
        if rot.ndim != 3 or rot.shape[1:] != (j, 4):
            raise ValueError(f"local_rotations must be (F, {j}, 4), got {rot.shape}")
        if pos.shape != rot.shape[:2] + (3,):
            raise ValueError(f"local_positions must be {rot.shape[:2] + (3,)}, got {pos.shape}")
        if self.euler_hint is not None and np.shape(self.euler_hint) != pos.shape:
            raise ValueError(f"euler_hint must be {pos.shape}, got {np.shape(self.euler_hint)}")
        if not (np.isfinite(self.frame_time) and self.frame_time > 0):
            raise ValueError(f"frame_time must be a positive number of seconds, got {self.frame_time}")
        object.__setattr__(self, "local_rotations", rot)
        object.__setattr__(self, "local_positions", pos)
        object.__setattr__(self, "frame_time", float(self.frame_time))

    @property
    def num_frames(self) -> int:
        return self.local_rotations.shape[0]

    @property
    def fps(self) -> float:
        return 1.0 / self.frame_time

    @property
    def duration(self) -> float:
        """Seconds from the first frame to the last."""
        return (self.num_frames - 1) * self.frame_time

    @property
    def root_translation(self) -> np.ndarray:
        """(F, 3) float64 translation of the root."""
        return self.local_positions[:, 0]

    def replace(self, **changes) -> Motion:
        """A copy with some fields changed (``dataclasses.replace``)."""
        return replace(self, **changes)

    def slice(self, frames: slice) -> Motion:
        """The frames selected by a slice, as a new Motion."""
        hint = None if self.euler_hint is None else self.euler_hint[frames]
        return Motion(
            self.skeleton, self.frame_time, self.local_rotations[frames], self.local_positions[frames], hint
        )

    def forward_kinematics(self) -> tuple[np.ndarray, np.ndarray]:
        """World rotations ``(F, J, 4)`` and world positions ``(F, J, 3)``.

        Loops over joints; every frame is handled at once.
        """
        return forward_kinematics(self.skeleton.parents, self.local_rotations, self.local_positions)

    def world_positions(self) -> np.ndarray:
        """(F, J, 3) float64 world position of every joint."""
        return self.forward_kinematics()[1]

    def world_rotations(self) -> np.ndarray:
        """(F, J, 4) float64 world orientation of every joint."""
        return self.forward_kinematics()[0]

    def with_rest(self, pose: np.ndarray) -> Motion:
        """The same motion on a skeleton whose rest pose is this one's posed by ``pose``.

        pose : (J, 4) local rotations; the new skeleton's rest pose is this skeleton
            with them applied (its offsets and end sites turned into it)

        Every frame's world positions are kept exactly (up to rounding); each joint's
        world orientation becomes ``W W_pose^-1``, its turn away from the new rest.
        So a character bound in that pose skins as it was bound, and the
        skeleton's rest is the pose a DCC shows. Where a rig's rest pose is a
        stick with every bone along one axis (iClone, Reallusion CC), a mesh
        bound to it collapses where the limbs turn back down; posed like the
        mesh, it does not (`mocap_exaggerate.rig.binding.bind_skin`,
        `mocap_exaggerate.jobs.outputs.at_bind_pose`).
        """
        skeleton = self.skeleton
        rested, world = skeleton.posed(pose)
        above = parent_rotations(skeleton.parents, world)
        rotations = quat_mul(quat_mul(above, self.local_rotations), quat_inv(world))
        rotations *= np.where(rotations[..., 3:] < 0.0, -1.0, 1.0)
        return Motion(rested, self.frame_time, rotations, quat_rotate(above, self.local_positions))
