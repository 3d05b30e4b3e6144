"""The bodies drawn: the captured and the exaggerated body posed by linear blend skinning
(`pose_skin`, `pose_bodies`), and their triangles shaded and sorted for drawing (`shaded_triangles`).

The exaggerated body is posed as the GLB poses it: the same skin re-weighted
onto the output skeleton, thinner where stretched (`mocap_exaggerate.jobs.outputs`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.motion import Motion
from ..jobs.outputs import base_skin, output_skin, output_thickness
from ..pipeline import PipelineResult
from ..rig.skinning import Skin, pose_skin
from .framing import view_axes

__all__ = ["pose_skin", "pose_bodies", "PosedBodies", "shaded_triangles", "CAPTURED_COLOR", "EXAGGERATED_COLOR"]

CAPTURED_COLOR = (0.75, 0.75, 0.78)
EXAGGERATED_COLOR = (1.0, 0.62, 0.25)


def _pose_frames(skin: Skin, bind: np.ndarray, world_rot: np.ndarray, world_pos: np.ndarray,
                 joint_index: np.ndarray, chunk: int = 32, scale: np.ndarray | None = None) -> np.ndarray:
    """`pose_skin` over frames ``(F, J, ...)`` -> ``(F, V, 3)``, a chunk of frames at a time: the
    ``(F, V, K, 3)`` intermediates of a long animation would otherwise take hundreds of MB."""
    posed = [pose_skin(skin, bind, world_rot[i:i + chunk], world_pos[i:i + chunk], joint_index,
                       None if scale is None else scale[i:i + chunk])
             for i in range(0, len(world_rot), chunk)]
    return np.concatenate(posed) if posed else np.zeros((0, len(skin.vertices), 3))


@dataclass(frozen=True)
class PosedBodies:
    """The captured and the exaggerated body at some output frames, and the side they are seen from.

    captured : (F, V, 3) float64 vertices of the body on the clip's skeleton; captured_faces (T, 3)
    exaggerated : (F, V', 3) float64 vertices of the body on the output skeleton; exaggerated_faces (T', 3)
    root : (F, 3) float64 captured root position (the camera follows it)
    axes : (right, up, depth) world axes drawn across, drawn up, and looked along
    """

    frames: np.ndarray
    captured: np.ndarray
    captured_faces: np.ndarray
    exaggerated: np.ndarray
    exaggerated_faces: np.ndarray
    root: np.ndarray
    axes: tuple[int, int, int]

    def screen_points(self) -> np.ndarray:
        """``(F, V + V' + 1, 2)``: every drawn vertex of both bodies and the root, as (across, up)."""
        right, up, _ = self.axes
        return np.concatenate([self.captured, self.exaggerated, self.root[:, None]], axis=1)[..., [right, up]]


def pose_bodies(motion: Motion, result: PipelineResult, frames: np.ndarray, skin: Skin | None = None) -> PosedBodies:
    """Pose both bodies at the output ``frames`` (ints into ``result``), all frames at once.

    The captured body stands on the clip's skeleton lined up frame for frame with the output
    (`lined_up`); the exaggerated one is the same body (``skin`` bound to the clip, else the
    default body) re-weighted onto the output skeleton, as the GLB poses it (thinner where
    stretched unless the run's ``output.preserve_volume`` is off).
    """
    skeleton = motion.skeleton
    body = base_skin(motion, result, skin)
    rubber = output_skin(motion, result, body)
    out_skeleton = result.motion.skeleton
    captured_rot, captured_pos = motion.forward_kinematics()
    if result.rest_frames_dropped:  # the output starts where the motion does: line the frames up
        captured_rot, captured_pos = captured_rot[result.rest_frames:], captured_pos[result.rest_frames:]
    frames = np.asarray(frames, dtype=np.int64)
    index_in = np.array([skeleton.index(n) for n in body.joint_names], dtype=np.int64)
    index_out = np.array([out_skeleton.index(n) for n in rubber.joint_names], dtype=np.int64)
    captured = _pose_frames(body, skeleton.rest_positions(), captured_rot[frames], captured_pos[frames], index_in)
    thickness = output_thickness(result)
    exaggerated = _pose_frames(rubber, out_skeleton.rest_positions(), result.world_rotations[frames],
                               result.world_positions[frames], index_out,
                               scale=None if thickness is None else thickness[frames])
    return PosedBodies(frames, captured, body.faces, exaggerated, rubber.faces, captured_pos[frames, 0],
                       view_axes(skeleton, captured_pos[:, 0]))


def shaded_triangles(vertices: np.ndarray, faces: np.ndarray, axes: tuple[int, int, int],
                     color: tuple) -> tuple[np.ndarray, np.ndarray]:
    """Screen triangles ``(F, T, 3, 2)`` sorted far to near and their colours ``(F, T, 3)``,
    lit from the front and above; ``vertices (F, V, 3)``, ``faces (T, 3)``."""
    right, up, depth = axes
    triangles = vertices[:, faces]  # (F, T, 3, 3)
    normal = np.cross(triangles[:, :, 1] - triangles[:, :, 0], triangles[:, :, 2] - triangles[:, :, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-12)
    light = np.zeros(3)
    light[depth], light[up] = 0.8, 0.6
    shade = 0.35 + 0.65 * np.clip(normal @ light, 0.0, 1.0)
    order = np.argsort(triangles[..., depth].mean(axis=-1), axis=-1, kind="stable")  # far first
    polygons = np.take_along_axis(triangles[..., [right, up]], order[..., None, None], axis=1)
    colors = np.clip(np.take_along_axis(shade, order, axis=1)[..., None] * np.asarray(color), 0.0, 1.0)
    return polygons, colors
