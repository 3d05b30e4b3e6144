"""Pictures without a GPU or a display: the skinned body at a few frames, captured above, exaggerated
below (`render_preview`), and one joint's path captured, averaged and exaggerated (`render_trajectory`).

The mesh is posed by linear blend skinning and drawn with matplotlib (Agg) as
shaded triangles sorted back to front, seen from the side the body faces most.
"""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from .motion import Motion
from .outputs import base_skin, output_skin
from .pipeline import PipelineResult
from .rotations import quat_rotate
from .skinning import Skin

__all__ = ["pose_skin", "render_preview", "telling_frames", "lined_up", "write_preview", "fastest_end", "render_trajectory", "telling_window"]


def pose_skin(skin: Skin, bind: np.ndarray, world_rot: np.ndarray, world_pos: np.ndarray,
              joint_index: np.ndarray) -> np.ndarray:
    """Linear blend skinning: vertices ``(V, 3)`` of ``skin`` posed by one frame's world transforms.

    bind : (J, 3) rest (bind) position of each skeleton joint; world_rot (J, 4), world_pos (J, 3);
    joint_index : (len(skin.joint_names),) skeleton index of each skin joint.
    The bind pose has identity orientations (BVH rest), so a vertex moves as
    ``R_j (v - bind_j) + p_j`` under joint j.
    """
    joints = joint_index[skin.joints]
    moved = quat_rotate(world_rot[joints], skin.vertices[:, None, :] - bind[joints]) + world_pos[joints]
    return np.sum(skin.weights[..., None] * moved, axis=1)


def _draw(ax, vertices: np.ndarray, faces: np.ndarray, axes: tuple[int, int, int], color: tuple) -> None:
    from matplotlib.collections import PolyCollection

    right, up, depth = axes
    triangles = vertices[faces]
    normal = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    light = np.zeros(3)
    light[depth], light[up] = 0.8, 0.6
    shade = 0.35 + 0.65 * np.clip(normal @ light, 0.0, 1.0)
    order = np.argsort(triangles[:, :, depth].mean(axis=1))  # far first
    polygons = triangles[order][:, :, [right, up]]
    colors = np.clip(np.outer(shade[order], color), 0.0, 1.0)
    ax.add_collection(PolyCollection(polygons, facecolors=colors, edgecolors="none"))


def lined_up(motion: Motion, result: PipelineResult, world: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """The captured world positions ``(F_out, J, 3)`` frame for frame with the output, and the
    output's first motion frame (past the rest-pose frames it kept).

    world : ``motion.world_positions()`` when the caller has it (it is not computed again)
    """
    world = motion.world_positions() if world is None else world
    if result.rest_frames_dropped:  # the output starts where the motion does
        return world[result.rest_frames:], 0
    return world, result.rest_frames


def telling_frames(motion: Motion, result: PipelineResult, count: int = 4, *,
                   world: np.ndarray | None = None) -> list[int]:
    """The ``count`` output frames where the body is most exaggerated, in time order.

    Exaggerated by the largest distance of any joint from where it was captured, relative
    to the root (so that a body drifting as a whole does not decide), the picks at least
    an eighth of the clip apart, so that one accent does not fill the row.
    """
    captured, first = lined_up(motion, result, world)
    exaggerated = result.world_positions[:, result.original_index]
    moved = (exaggerated - exaggerated[:, :1]) - (captured - captured[:, :1])
    away = np.linalg.norm(moved, axis=-1).max(axis=1)[first:]
    apart = max(len(away) // 8, 1)
    picks: list[int] = []
    for frame in np.argsort(-away, kind="stable"):
        if len(picks) == count:
            break
        if all(abs(int(frame) - p) >= apart for p in picks):
            picks.append(int(frame))
    return sorted(first + p for p in picks)


def render_preview(motion: Motion, result: PipelineResult, *, frames: int = 5, width: float = 2.4,
                   at: list[int] | None = None, dpi: int = 80) -> bytes:
    """A PNG: the captured (top, grey) and exaggerated (bottom, orange) body at a few frames.

    ``at``: the output frames to draw (e.g. `telling_frames`); default ``frames`` evenly spaced.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    skeleton = motion.skeleton
    body = base_skin(motion, result)
    rubber = output_skin(motion, result, body)
    out_skeleton = result.motion.skeleton
    captured_rot, captured_pos = motion.forward_kinematics()
    if result.rest_frames_dropped:  # the output starts where the motion does: line the frames up
        captured_rot, captured_pos = captured_rot[result.rest_frames:], captured_pos[result.rest_frames:]
    first = result.rest_frames if not result.rest_frames_dropped else 0
    last = result.world_positions.shape[0] - 1
    picks = np.unique(np.linspace(first, last, frames).astype(int) if at is None else np.clip(at, 0, last))
    up = skeleton.up_axis()
    # Look along the horizontal axis the body moves least along (its side).
    horizontal = [a for a in range(3) if a != up]
    spread = np.ptp(captured_pos[:, 0, horizontal], axis=0)
    depth = horizontal[int(np.argmin(spread))]
    right = horizontal[int(np.argmax(spread))] if spread.max() > 0 else horizontal[0]
    height = skeleton.height()
    bind_in = skeleton.rest_positions()
    bind_out = out_skeleton.rest_positions()
    index_in = np.array([skeleton.index(n) for n in body.joint_names])
    index_out = np.array([out_skeleton.index(n) for n in rubber.joint_names])
    figure, axes = plt.subplots(2, len(picks), figsize=(width * len(picks), 2 * width * 1.1), squeeze=False)
    low = min(captured_pos[:, :, up].min(), result.world_positions[:, :, up].min())
    for column, frame in enumerate(picks):
        for row, (skin, bind, index, rot, pos, color) in enumerate((
            (body, bind_in, index_in, captured_rot[frame], captured_pos[frame], (0.75, 0.75, 0.78)),
            (rubber, bind_out, index_out, result.world_rotations[frame], result.world_positions[frame], (1.0, 0.62, 0.25)),
        )):
            ax = axes[row, column]
            vertices = pose_skin(skin, bind, rot, pos, index)
            _draw(ax, vertices, skin.faces, (right, up, depth), color)
            centre = captured_pos[frame, 0, right]
            ax.set_xlim(centre - 0.75 * height, centre + 0.75 * height)
            ax.set_ylim(low - 0.05 * height, low + 1.45 * height)
            ax.set_aspect("equal")
            ax.axis("off")
            if row == 0:
                ax.set_title(f"frame {frame}", fontsize=9)
    figure.suptitle("captured (top) and exaggerated (bottom)", fontsize=10)
    return _png(figure, dpi)


def _png(figure, dpi: int = 80) -> bytes:
    """The figure as PNG bytes, the same bytes every time (no software or date written)."""
    import matplotlib.pyplot as plt

    figure.tight_layout()
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=dpi, metadata={"Software": None})
    plt.close(figure)
    return buffer.getvalue()


def fastest_end(motion: Motion, first: int | None = None, *, world: np.ndarray | None = None) -> int:
    """The end effector (hand, foot, head of the limbs found) that moves fastest in ``motion``.

    Fastest by the 99th percentile of its world speed from frame ``first`` on (default: past
    the leading rest-pose frames, whose jump into the motion is no move), so that one
    glitch in the capture does not decide. Falls back to the fastest joint of all on a rig
    whose limbs are not found.
    """
    from .limbs import find_limbs
    from .tpose import detect_rest_frames

    world = motion.world_positions() if world is None else world
    world = world[(detect_rest_frames(motion, world) if first is None else first):]
    ends = sorted({limb.end for limb in find_limbs(motion.skeleton).values()}) or list(range(motion.skeleton.num_joints))
    if len(world) < 2:
        return ends[0]
    speed = np.linalg.norm(np.diff(world[:, ends], axis=0), axis=-1)
    return ends[int(np.argmax(np.percentile(speed, 99, axis=0)))]


def telling_window(motion: Motion, result: PipelineResult, joint: int, seconds: float = 3.0, *,
                   world: np.ndarray | None = None) -> tuple[int, int]:
    """Output frames ``[start, end)`` of about ``seconds`` around the moment ``joint`` is moved
    furthest from its captured path: the part of a long clip a path picture can show."""
    captured, first = lined_up(motion, result, world)
    away = np.linalg.norm(result.world_positions[:, result.original_index[joint]] - captured[:, joint], axis=-1)
    total = len(away)
    width = max(int(round(seconds / motion.frame_time)), 2)
    if total - first <= width:
        return first, total
    peak = first + int(np.argmax(away[first:]))
    start = int(np.clip(peak - width // 2, first, total - width))
    return start, start + width


def render_trajectory(motion: Motion, result: PipelineResult, joint: int | str | None = None,
                      config=None, frames: tuple[int, int] | None = None, dpi: int = 80, *,
                      world: np.ndarray | None = None) -> bytes:
    """A PNG of one joint's world path (default: `fastest_end`), as Kwon and Lee's Figure 3 draws it.

    The captured path (grey), its Gaussian average over ``extrapolate.sigma`` (green; what
    extrapolation exaggerates away from) and the exaggerated path (orange, as the exaggerated
    body of `render_preview`; the paper draws them red, green and blue), seen from the
    side (left) and from above (right). ``config`` gives sigma (default: the default preset).
    ``frames``: the output frames ``[start, end)`` to draw (e.g. `telling_window`); default
    the whole motion past the rest frames. The average is taken over the whole clip.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .config import load_preset
    from .stages.extrapolate import gaussian_average

    skeleton = motion.skeleton
    world = motion.world_positions() if world is None else world
    if joint is None:
        joint = fastest_end(motion, result.rest_frames, world=world)
    index = skeleton.index(joint) if isinstance(joint, str) else int(joint)
    captured, first = lined_up(motion, result, world)  # the rest frames the output kept are not the motion
    captured = captured[:, index]
    exaggerated = result.world_positions[:, result.original_index[index]]
    config = config or load_preset("cartoon")
    sigma = config.extrapolate.sigma_frames(motion.frame_time, max(len(captured) - first, 1))
    average = np.empty_like(captured)
    average[first:] = gaussian_average(captured[first:], sigma)
    start, end = frames if frames is not None else (first, len(captured))
    start, end = max(int(start), first), min(int(end), len(captured))
    captured, average, exaggerated = captured[start:end], average[start:end], exaggerated[start:end]
    up = skeleton.up_axis()
    horizontal = [a for a in range(3) if a != up]
    spread = np.ptp(captured[:, horizontal], axis=0) if len(captured) else np.zeros(2)
    right, depth = (horizontal if spread[0] >= spread[1] else horizontal[::-1])
    figure, axes = plt.subplots(1, 2, figsize=(8.0, 3.4), squeeze=False)
    for ax, (across, along, title) in zip(axes[0], ((right, up, "the side"), (right, depth, "above"))):
        for path, color, label, width in ((captured, "#6b6b70", "captured", 1.6), (average, "#27ae60", "average", 1.2),
                                          (exaggerated, "#f08c2e", "exaggerated", 1.8)):
            ax.plot(path[:, across], path[:, along], color=color, linewidth=width, label=label)
            if len(path):
                ax.plot(path[:1, across], path[:1, along], "o", color=color, markersize=3)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(f"seen from {title}", fontsize=9)
        ax.set_xlabel("XYZ"[across], fontsize=8)
        ax.set_ylabel("XYZ"[along], fontsize=8)
        ax.tick_params(labelsize=7)
    axes[0, 0].legend(fontsize=7, loc="best")
    figure.suptitle(f"{skeleton.names[index]}, frames {start}-{max(end - 1, start)} (dot: start)", fontsize=10)
    return _png(figure, dpi)


def write_preview(source, output: str | os.PathLike, config=None, *, frames: int = 5, overwrite: bool = False,
                  label: str | None = None) -> Path:
    """Run the pipeline on a clip (path, bytes or stream) and write its preview PNG to ``output``.

    The target is checked first (never an input; taken only with ``overwrite``).
    """
    from .config import load_preset
    from .io.bvh import read_bvh
    from .io.files import atomic_write
    from .job import check_targets
    from .pipeline import run

    output = Path(output)
    if output.suffix.lower() != ".png":
        from .errors import ConfigError

        raise ConfigError(f"{output}: previews are written as PNG; name the file .png")
    inputs = [Path(source)] if isinstance(source, (str, os.PathLike)) and str(source) != "-" else []
    check_targets({"preview": output}, inputs, overwrite)
    config = config or load_preset("cartoon")
    motion, _ = read_bvh(source, name=label, fps=config.input.fps)
    atomic_write(output, render_preview(motion, run(motion, config), frames=frames), overwrite=True)
    return output
