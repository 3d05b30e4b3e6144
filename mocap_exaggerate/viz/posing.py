"""The bodies drawn: the captured and the exaggerated body posed by linear blend skinning
(`pose_skin`, `pose_bodies`), and their triangles shaded and sorted for drawing (`shaded_triangles`).

The exaggerated body is posed as the GLB poses it: the same skin re-weighted
onto the output skeleton, thinner where stretched (`mocap_exaggerate.jobs.outputs`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.motion import Motion
from ..core.rotations import vector_norm
from ..jobs.outputs import at_bind_pose, base_skin, output_skin, output_thickness
from ..pipeline import PipelineResult
from ..rig.skinning import Skin, pose_skin
from .framing import view_axes

__all__ = ["pose_skin", "pose_bodies", "pose_captured", "pose_exaggerated", "PosedBodies", "shaded_triangles",
           "facing", "CAPTURED_COLOR", "EXAGGERATED_COLOR"]

CAPTURED_COLOR = (0.75, 0.75, 0.78)
EXAGGERATED_COLOR = (1.0, 0.62, 0.25)


def _pose_frames(skin: Skin, bind: np.ndarray, world_rot: np.ndarray, world_pos: np.ndarray,
                 joint_index: np.ndarray, chunk: int = 32, scale: np.ndarray | None = None,
                 dtype=np.float64) -> np.ndarray:
    """`pose_skin` over frames ``(F, J, ...)`` -> ``(F, V, 3)``, a chunk of frames at a time (the
    intermediates of a long animation would otherwise take hundreds of MB), in threads.

    The same sum as `pose_skin`, blended as matrices: each joint's ``s R`` and ``p - s R bind`` once
    a frame, then each vertex's weighted sum of its joints' (12 numbers an influence instead of a
    quaternion turn of each influence's offset: a third of the time). ``dtype`` float32 for pictures.)"""
    from concurrent.futures import ThreadPoolExecutor

    from ..core.rotations import quat_to_matrix
    from .raster import THREADS

    joints = np.asarray(joint_index)[skin.joints]  # (V, K)
    weights = skin.weights.astype(dtype)
    vertices = skin.vertices.astype(dtype)

    def pose(i: int) -> np.ndarray:
        turn = quat_to_matrix(world_rot[i:i + chunk])  # (f, J, 3, 3)
        if scale is not None:
            turn = turn * scale[i:i + chunk, :, None, None]
        shift = world_pos[i:i + chunk] - np.einsum("fjab,jb->fja", turn, bind)
        turn, shift = turn.astype(dtype), shift.astype(dtype)
        blend = np.zeros(turn.shape[:1] + (len(vertices), 3, 3), dtype=dtype)
        moved = np.zeros(turn.shape[:1] + (len(vertices), 3), dtype=dtype)
        for k in range(joints.shape[1]):
            w = weights[:, k, None]
            blend += w[..., None] * turn[:, joints[:, k]]
            moved += w * shift[:, joints[:, k]]
        return np.einsum("fvab,vb->fva", blend, vertices) + moved

    with ThreadPoolExecutor(THREADS) as pool:  # NumPy lets go of the interpreter while it works
        posed = list(pool.map(pose, range(0, len(world_rot), chunk)))
    return np.concatenate(posed) if posed else np.zeros((0, len(vertices), 3), dtype=dtype)


@dataclass(frozen=True)
class PosedBodies:
    """The captured and the exaggerated body at some output frames, and the side they are seen from.

    captured : (F, V, 3) float64 vertices of the body on the clip's skeleton; captured_faces (T, 3)
    exaggerated : (F, V', 3) float64 vertices of the body on the output skeleton; exaggerated_faces (T', 3)
    root : (F, 3) float64 captured root position (the camera follows it)
    axes : (right, up, depth) world axes drawn across, drawn up, and looked along
    captured_facing, exaggerated_facing : `facing` of each body's mesh (+1 outward, -1 inward, 0 unknown)
    """

    frames: np.ndarray
    captured: np.ndarray
    captured_faces: np.ndarray
    exaggerated: np.ndarray
    exaggerated_faces: np.ndarray
    root: np.ndarray
    axes: tuple[int, int, int]
    captured_facing: int = 0
    exaggerated_facing: int = 0

    def screen_points(self) -> np.ndarray:
        """``(F, V + V' + 1, 2)``: every drawn vertex of both bodies and the root, as (across, up)."""
        right, up, _ = self.axes
        return np.concatenate([self.captured, self.exaggerated, self.root[:, None]], axis=1)[..., [right, up]]


def pose_bodies(motion: Motion, result: PipelineResult, frames: np.ndarray, skin: Skin | None = None,
                dtype=np.float64) -> PosedBodies:
    """Pose both bodies at the output ``frames`` (ints into ``result``), all frames at once.

    The captured body stands on the clip's skeleton lined up frame for frame with the output
    (`lined_up`); the exaggerated one is the same body (``skin`` bound to the clip, else the
    default body) re-weighted onto the output skeleton, as the GLB poses it (thinner where
    stretched unless the run's ``output.preserve_volume`` is off). ``dtype``: float32 is plenty for pictures.
    """
    body = base_skin(motion, result, skin)
    frames = np.asarray(frames, dtype=np.int64)
    captured, root, axes = pose_captured(motion, result, frames, body, dtype)
    exaggerated, rubber = pose_exaggerated(motion, result, frames, body, dtype)
    return PosedBodies(frames, captured, body.faces, exaggerated, rubber.faces, root, axes,
                       facing(body.vertices, body.faces), facing(rubber.vertices, rubber.faces))


def pose_captured(motion: Motion, result: PipelineResult, frames: np.ndarray, body: Skin,
                  dtype=np.float64) -> tuple[np.ndarray, np.ndarray, tuple[int, int, int]]:
    """The captured body ``body`` (bound to the clip, `base_skin`) at the output ``frames``: its vertices
    ``(F, V, 3)``, the captured root ``(F, 3)`` and the view's axes (`view_axes`)."""
    motion, _, body = at_bind_pose(motion, None, body)
    skeleton = motion.skeleton
    captured_rot, captured_pos = motion.forward_kinematics()
    if result.rest_frames_dropped:  # the output starts where the motion does: line the frames up
        captured_rot, captured_pos = captured_rot[result.rest_frames:], captured_pos[result.rest_frames:]
    index_in = np.array([skeleton.index(n) for n in body.joint_names], dtype=np.int64)
    vertices = _pose_frames(body, skeleton.rest_positions(), captured_rot[frames], captured_pos[frames], index_in,
                            dtype=dtype)
    return vertices, captured_pos[frames, 0], view_axes(skeleton, captured_pos[:, 0])


def pose_exaggerated(motion: Motion, result: PipelineResult, frames: np.ndarray, body: Skin,
                     dtype=np.float64) -> tuple[np.ndarray, Skin]:
    """The run's body at the output ``frames``: ``body`` re-weighted onto the output skeleton and posed
    as the GLB poses it; its vertices ``(F, V', 3)`` and the re-weighted skin."""
    motion, result, body = at_bind_pose(motion, result, body)
    rubber = output_skin(motion, result, body)
    out_skeleton = result.motion.skeleton
    index_out = np.array([out_skeleton.index(n) for n in rubber.joint_names], dtype=np.int64)
    thickness = output_thickness(result)
    vertices = _pose_frames(rubber, out_skeleton.rest_positions(), result.world_rotations[frames],
                            result.world_positions[frames], index_out,
                            scale=None if thickness is None else thickness[frames], dtype=dtype)
    return vertices, rubber


def facing(vertices: np.ndarray, faces: np.ndarray) -> int:
    """Which way a mesh's triangles face: +1 outward (its corners turn counter-clockwise seen from
    outside), -1 inward, 0 when its winding is not consistent (an edge runs the same way in two
    triangles) and the back of a triangle cannot be told from its front. Seen by the sign of the
    volume it encloses (the sum of its triangles' signed tetrahedra), at rest."""
    if not len(faces):
        return 0
    edges = np.stack([faces, np.roll(faces, -1, axis=1)], axis=-1).reshape(-1, 2).astype(np.int64)
    if len(np.unique(edges[:, 0] * (int(edges.max()) + 1) + edges[:, 1])) != len(edges):
        return 0
    corners = vertices[faces]
    volume = float(np.einsum("ti,ti->", corners[:, 0], np.cross(corners[:, 1], corners[:, 2])))
    return 0 if volume == 0 else (1 if volume > 0 else -1)


def shaded_triangles(vertices: np.ndarray, faces: np.ndarray, axes: tuple[int, int, int],
                     facing: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The triangles of a body at ``F`` frames, ready to draw: ``(frame (N,) int, screen corners
    (N, 3, 2) float32 as (across, up), shade (N,) in [0.35, 1])``, far to near within each frame, lit
    from the front and above; ``vertices (F, V, 3)``, ``faces (T, 3)``. The viewer looks along -``depth``.

    Where ``facing`` (the mesh's `facing`) tells, the triangles facing away are left out (on a closed
    body those in front cover them): half the triangles to sort and draw.
    """
    right, up, depth = axes
    triangles = np.asarray(vertices, dtype=np.float32)[:, faces]  # (F, T, 3, 3)
    normal = np.cross(triangles[:, :, 1] - triangles[:, :, 0], triangles[:, :, 2] - triangles[:, :, 0])
    if facing:
        frame, index = np.nonzero(facing * normal[..., depth] > 0)
    else:
        frame, index = np.divmod(np.arange(normal.shape[0] * normal.shape[1]), normal.shape[1])
    normal = normal[frame, index]
    kept = triangles[frame, index]  # (N, 3, 3)
    light = np.zeros(3, dtype=np.float32)
    light[depth], light[up] = 0.8, 0.6
    length = vector_norm(normal)
    shade = 0.35 + 0.65 * np.clip(np.divide(normal @ light, length, out=np.zeros_like(length), where=length > 0),
                                  0.0, 1.0)
    # Far first: one sort of all frames' triangles by depth keeps each frame's in order (frames never share
    # a picture, so their order among each other does not matter).
    order = np.argsort(kept[..., depth].sum(axis=-1), kind="stable")
    return frame[order], kept[order][..., [right, up]], shade[order]
