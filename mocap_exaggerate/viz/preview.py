"""Pictures without a GPU or a display: the skinned body captured and exaggerated, as still frames
(`render_preview`, a PNG), as a looping animation side by side (`render_gif`, `render_mp4`), and
one joint's path captured, averaged and exaggerated (`render_trajectory`).

The mesh is posed by linear blend skinning and drawn with matplotlib (Agg) as
shaded triangles sorted back to front, seen from the side the body faces most.
The view covers everything drawn (`view_limits`), at one scale for both bodies.
"""

from __future__ import annotations

import difflib
import io
import logging
import math
import os
import shutil
import subprocess
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.errors import ConfigError, check_number
from ..core.motion import Motion
from ..core.rotations import quat_rotate
from ..core.skeleton import Skeleton
from ..jobs.outputs import base_skin, output_skin, output_thickness
from ..pipeline import PipelineResult
from ..rig.skinning import Skin

__all__ = ["pose_skin", "pose_bodies", "PosedBodies", "view_limits", "render_preview", "telling_frames", "lined_up",
           "write_preview", "fastest_end", "render_trajectory", "telling_window", "preview_window",
           "animation_frames", "render_frames", "render_gif", "render_mp4", "gif_durations", "joint_named",
           "PREVIEW_SUFFIXES"]

log = logging.getLogger(__name__)

PREVIEW_SUFFIXES = (".png", ".gif", ".mp4")
MAX_FPS = 20.0  # an animation shows every step-th frame, the smallest step at or under this rate
MAX_SECONDS = 10.0  # an animation's default length: a long clip is cut here (``seconds`` shows more)
CAPTURED_COLOR = (0.75, 0.75, 0.78)
EXAGGERATED_COLOR = (1.0, 0.62, 0.25)
NO_FFMPEG = "writing .mp4 needs ffmpeg on PATH, which was not found; .gif previews work without it"
_TRIANGLE_CODES = np.array([1, 2, 2, 79], dtype=np.uint8)  # a matplotlib Path's MOVETO, LINETO, LINETO, CLOSEPOLY


def pose_skin(skin: Skin, bind: np.ndarray, world_rot: np.ndarray, world_pos: np.ndarray,
              joint_index: np.ndarray, scale: np.ndarray | None = None) -> np.ndarray:
    """Linear blend skinning: vertices ``(..., V, 3)`` of ``skin`` posed by world transforms.

    bind : (J, 3) rest (bind) position of each skeleton joint;
    world_rot : (..., J, 4), world_pos : (..., J, 3), any leading axes (frames) broadcast;
    joint_index : (len(skin.joint_names),) skeleton index of each skin joint;
    scale : (..., J) world scale of each joint (the GLB's `mocap_exaggerate.jobs.outputs.output_thickness`) or None.
    The bind pose has identity orientations (BVH rest), so a vertex moves as
    ``s_j R_j (v - bind_j) + p_j`` under joint j.
    """
    joints = joint_index[skin.joints]  # (V, K)
    turned = quat_rotate(world_rot[..., joints, :], skin.vertices[:, None, :] - bind[joints])
    if scale is not None:
        turned = turned * scale[..., joints, None]
    moved = turned + world_pos[..., joints, :]
    return np.sum(skin.weights[..., None] * moved, axis=-2)


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


def _view_axes(skeleton: Skeleton, root_path: np.ndarray) -> tuple[int, int, int]:
    """(right, up, depth): look along the horizontal axis the root moves least along (from its side).

    root_path : (F, 3) root positions over the clip
    """
    up = skeleton.up_axis()
    horizontal = [a for a in range(3) if a != up]
    spread = np.ptp(root_path[:, horizontal], axis=0) if len(root_path) else np.zeros(2)
    depth = horizontal[int(np.argmin(spread))]
    right = horizontal[int(np.argmax(spread))] if spread.max() > 0 else horizontal[0]
    return right, up, depth


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
                       _view_axes(skeleton, captured_pos[:, 0]))


def _shaded(vertices: np.ndarray, faces: np.ndarray, axes: tuple[int, int, int],
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


def view_limits(points: np.ndarray, centre: np.ndarray, *, margin: float = 0.04, min_aspect: float = 0.5,
                max_aspect: float = 3.0) -> tuple[float, float, float]:
    """One view that shows every point of every frame: ``(half_width, low, high)``.

    points : (F, N, 2) float, what is drawn at each of F frames (or picture columns) as (across, up)
    centre : (F,) float, where each frame's view is centred across

    Frame f shows ``centre[f] ± half_width`` across and ``[low, high]`` up: the same size for
    every frame, so that bodies drawn in different frames or panels are at one scale. A margin
    of ``margin`` times the larger extent is left on every side; the view is at least
    ``min_aspect`` and at most ``max_aspect`` times as wide as it is tall (it grows to be).

    >>> view_limits(np.array([[[0.0, 0.0], [1.0, 2.0]]]), np.array([0.0]), margin=0.0)
    (1.0, 0.0, 2.0)
    """
    points = np.asarray(points, dtype=np.float64)
    centre = np.asarray(centre, dtype=np.float64)
    if points.ndim != 3 or points.shape[-1] != 2 or points.shape[1] == 0:
        raise ValueError(f"points must be (F, N, 2) with N > 0, got {points.shape}")
    if centre.shape != points.shape[:1]:
        raise ValueError(f"centre must be ({points.shape[0]},), got {centre.shape}")
    low, high = float(points[..., 1].min()), float(points[..., 1].max())
    half = float(np.abs(points[..., 0] - centre[:, None]).max())
    extent = max(high - low, 2.0 * half)
    pad = margin * extent if extent > 0 else 1.0  # a single point still gets a view around it
    low, high, half = low - pad, high + pad, half + pad
    grow = max(2.0 * half / max_aspect - (high - low), 0.0) / 2.0
    low, high = low - grow, high + grow
    return max(half, 0.5 * min_aspect * (high - low)), low, high


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
                   at: list[int] | None = None, dpi: int = 80, skin: Skin | None = None) -> bytes:
    """A PNG: the captured (top, grey) and exaggerated (bottom, orange) body at a few frames.

    ``at``: the output frames to draw (e.g. `telling_frames`); default ``frames`` evenly spaced.
    ``width``: inches per column. Every column is centred on the captured root and all panels
    share one scale and one height range, taller where a stretch reaches higher (`view_limits`).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    first = result.first
    last = result.world_positions.shape[0] - 1
    picks = np.unique(np.linspace(first, last, frames).astype(int) if at is None else np.clip(at, 0, last))
    bodies = pose_bodies(motion, result, picks, skin)
    right = bodies.axes[0]
    half, low, high = view_limits(bodies.screen_points(), bodies.root[:, right])
    row_height = width * (high - low) / (2.0 * half)
    figure, axes = plt.subplots(2, len(picks), figsize=(width * len(picks), 2 * row_height + 0.5), squeeze=False)
    for row, (vertices, faces, color) in enumerate(((bodies.captured, bodies.captured_faces, CAPTURED_COLOR),
                                                    (bodies.exaggerated, bodies.exaggerated_faces, EXAGGERATED_COLOR))):
        polygons, colors = _shaded(vertices, faces, bodies.axes, color)
        for column, frame in enumerate(picks):
            ax = axes[row, column]
            ax.add_collection(PolyCollection(polygons[column], facecolors=colors[column], edgecolors="none"))
            centre = bodies.root[column, right]
            ax.set_xlim(centre - half, centre + half)
            ax.set_ylim(low, high)
            ax.set_aspect("equal")
            ax.axis("off")
            if row == 0:
                ax.set_title(f"frame {frame}", fontsize=9)
    figure.suptitle("captured (top) and exaggerated (bottom)", fontsize=10)
    return _png(figure, dpi)


def preview_window(motion: Motion, result: PipelineResult, *, start: float = 0.0,
                   seconds: float | None = None) -> tuple[int, int]:
    """Output frames ``[begin, end)``: from ``start`` seconds into the motion (past the rest-pose
    frames the output kept) for ``seconds`` (default: to the end)."""
    check_number("start", start, 0.0, math.inf)
    first = result.first
    total = result.world_positions.shape[0]
    begin = first + start / motion.frame_time  # a float until it is known to be a frame: start may be inf
    if begin >= total - 0.5:
        length = max(total - 1 - first, 0) * motion.frame_time
        raise ConfigError(f"start {start:g} s is past the end of the motion ({length:.3f} s long)")
    begin = int(round(begin))
    if seconds is None:
        return begin, total
    check_number("seconds", seconds, 0.0, math.inf, low_open=True)
    count = seconds / motion.frame_time  # inf shows the rest
    return begin, total if count >= total - begin else min(total, begin + max(int(round(count)), 1))


def animation_frames(motion: Motion, result: PipelineResult, *, start: float = 0.0, seconds: float | None = None,
                     max_fps: float = MAX_FPS) -> tuple[np.ndarray, float]:
    """The output frames an animated preview shows, and the seconds each one is shown.

    Every ``step``-th frame of `preview_window` (``seconds`` default: the motion, cut at
    `MAX_SECONDS`), the smallest step that plays at or under ``max_fps``, so that playback runs
    at the clip's speed: 120 fps plays every 6th frame at 20 fps, 30 fps every 2nd at 15 fps.
    A window of two frames or more always shows at least two.
    """
    check_number("max_fps", max_fps, 0.0, 1000.0, low_open=True)
    begin, end = preview_window(motion, result, start=start, seconds=MAX_SECONDS if seconds is None else seconds)
    if seconds is None and end < result.world_positions.shape[0]:
        log.warning("the animation shows %.3g s from %g s of a longer motion; --seconds shows more",
                    (end - begin) * motion.frame_time, start)
    step = max(1, math.ceil(motion.fps / max_fps - 1e-3))  # a Frame Time of 0.008333 is 120 fps
    step = min(step, max(end - begin - 1, 1))
    return np.arange(begin, end, step), step * motion.frame_time


def _camera(root_across: np.ndarray, points: np.ndarray, tall: float, sigma: float) -> np.ndarray:
    """``(F,)``: where each frame's view is centred across.

    Standing still over everything drawn unless the root travels more than half the body's
    height ``tall``; then following it, smoothed over ``sigma`` frames so that the body's own
    surges show: the extrapolation's own Gaussian average, whose point-reflected ends keep a
    steady run steady there.
    """
    from ..core.timing import gaussian_average

    if np.ptp(root_across) <= 0.5 * tall:
        across = points[..., 0]
        return np.full(len(root_across), 0.5 * (across.min() + across.max()))
    return gaussian_average(root_across, sigma)


def render_frames(motion: Motion, result: PipelineResult, frames: np.ndarray, *,
                  height: int = 320, skin: Skin | None = None) -> Iterator[np.ndarray]:
    """RGB pictures ``(H, W, 3) uint8``, one per output frame of ``frames``: the captured body
    (left, grey) and the exaggerated one (right, orange) side by side, one camera, one scale.

    height : pixels of the body panels; a title and a frame label add 40. ``H`` and ``W`` are even
    (as H.264 wants) and the same for every picture.
    The view covers every vertex of both bodies in every frame (`view_limits`). The camera
    follows the captured root across when it travels (`_camera`); ticks on the ground
    then scroll by with the travel. Both bodies are posed and shaded for many frames at once;
    the loop draws.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import LineCollection, PathCollection
    from matplotlib.figure import Figure
    from matplotlib.path import Path as Path2D

    frames = np.asarray(frames, dtype=np.int64)
    bodies = pose_bodies(motion, result, frames, skin)
    right, up, _ = bodies.axes
    points = bodies.screen_points()
    tall = motion.skeleton.height()
    shown_seconds = (frames[1] - frames[0]) * motion.frame_time if len(frames) > 1 else motion.frame_time
    centre = _camera(bodies.root[:, right], points, tall, max(0.4 / shown_seconds, 1.0))
    half, low, high = view_limits(points, centre)
    panel_h = max(int(height), 16)
    panel_w = math.ceil(panel_h * 2.0 * half / (high - low))
    half = 0.5 * panel_w / panel_h * (high - low)  # the panel's own scale: at least the fitted half width
    top, bottom, gap = 22, 18, 10
    gap += (2 * panel_w + gap) % 2
    bottom += (panel_h + top + bottom) % 2
    width_px, height_px = 2 * panel_w + gap, panel_h + top + bottom
    figure = Figure(figsize=(width_px / 100, height_px / 100), dpi=100, facecolor="white")
    canvas = FigureCanvasAgg(figure)
    # The ground: the lowest the captured body goes (the exaggerated one may go through it).
    floor = float(bodies.captured[..., up].min() if bodies.captured.shape[1] else bodies.root[:, up].min())
    spacing = (tall if tall > 0 else high - low) / 4.0
    ticks = np.arange(math.floor((centre.min() - half) / spacing), math.ceil((centre.max() + half) / spacing) + 1)
    tick = 0.025 * (high - low)
    panels = []
    for number, (vertices, faces, color, title, ink) in enumerate((
            (bodies.captured, bodies.captured_faces, CAPTURED_COLOR, "captured", (0.35, 0.35, 0.38)),
            (bodies.exaggerated, bodies.exaggerated_faces, EXAGGERATED_COLOR, "exaggerated", (0.8, 0.42, 0.08)))):
        left = number * (panel_w + gap)
        ax = figure.add_axes((left / width_px, bottom / height_px, panel_w / width_px, panel_h / height_px))
        ax.set_ylim(low, high)
        ax.axis("off")
        ax.axhline(floor, color=(0.8, 0.8, 0.82), linewidth=1.0, zorder=1)
        ax.add_collection(LineCollection([[(x * spacing, floor), (x * spacing, floor - tick)] for x in ticks],
                                         colors=[(0.8, 0.8, 0.82)], linewidths=1.0, zorder=1))
        # One Path per triangle, made once, each a view into ``corners``: a frame is drawn by
        # writing its sorted triangles into ``corners`` (set_verts would build thousands of Paths).
        corners = np.zeros((len(faces), 4, 2))
        polygons = PathCollection([Path2D(c, _TRIANGLE_CODES) for c in corners], edgecolors="none", zorder=2)
        ax.add_collection(polygons)
        figure.text((left + panel_w / 2) / width_px, 1 - 4 / height_px, title, ha="center", va="top", fontsize=9,
                    color=ink)
        panels.append((ax, polygons, corners, vertices, faces, color))
    label = figure.text(0.5, 3 / height_px, "", ha="center", va="bottom", fontsize=8, color=(0.3, 0.3, 0.3))
    first = result.first
    chunk = 32
    for begin in range(0, len(frames), chunk):
        shaded = [_shaded(vertices[begin:begin + chunk], faces, bodies.axes, color)
                  for *_, vertices, faces, color in panels]
        for offset in range(len(shaded[0][0])):
            k = begin + offset
            for (ax, polygons, corners, *_), (triangles, colors) in zip(panels, shaded):
                corners[:, :3] = triangles[offset]
                corners[:, 3] = triangles[offset, :, 0]
                polygons.set_facecolor(colors[offset])  # marks the collection for redrawing
                ax.set_xlim(centre[k] - half, centre[k] + half)
            label.set_text(f"frame {frames[k]}   {(frames[k] - first) * motion.frame_time:.2f} s")
            canvas.draw()
            yield np.asarray(canvas.buffer_rgba())[:height_px, :width_px, :3].copy()


def _gif_palette() -> np.ndarray:
    """``(256, 3) uint8``: one fixed palette for every GIF frame, so that the frames do not flicker
    and the bytes do not depend on what was drawn first. Each body colour at 24 shades, each
    also blended 3 ways into the white ground (the anti-aliased edges), and 64 greys (text,
    ground, white)."""
    colors = [alpha * shade * np.asarray(color) + (1.0 - alpha)
              for color in (CAPTURED_COLOR, EXAGGERATED_COLOR)
              for shade in np.linspace(0.35, 1.0, 24)
              for alpha in (1.0, 0.7, 0.4, 0.15)]
    colors += [np.full(3, grey) for grey in np.linspace(0.0, 1.0, 256 - len(colors))]
    return np.round(255 * np.asarray(colors)).astype(np.uint8)


def _indexed(rgb: np.ndarray, palette: np.ndarray, lookup: np.ndarray):
    """A P-mode picture of ``rgb (H, W, 3) uint8``, each pixel the nearest ``palette (256, 3)`` colour.

    lookup : (2**24,) int16, the palette index of each packed RGB colour, -1 where not yet
    known; filled in here, so that later frames only search for colours not seen before.
    Exactly the nearest (Pillow's own mapping rounds colours to a coarse cache first and
    would turn the white ground light grey).
    """
    from PIL import Image

    packed = (rgb[..., 0].astype(np.int32) << 16) | (rgb[..., 1].astype(np.int32) << 8) | rgb[..., 2]
    index = lookup[packed]
    unknown = np.unique(packed[index < 0])
    if len(unknown):
        distinct = np.stack([unknown >> 16, (unknown >> 8) & 255, unknown & 255], axis=-1)
        distance = ((distinct[:, None, :] - palette[None].astype(np.int32)) ** 2).sum(axis=-1)
        lookup[unknown] = np.argmin(distance, axis=1)
        index = lookup[packed]
    picture = Image.fromarray(index.astype(np.uint8), mode="P")
    picture.putpalette(palette.ravel().tolist())
    return picture


def gif_durations(count: int, frame_seconds: float) -> list[int]:
    """Milliseconds each of ``count`` frames is shown: multiples of 10 (a GIF counts
    centiseconds), alternating where needed so that the loop keeps the clip's time
    (at 15 fps: 70, 60, 70, ... ms; rounding errors do not add up)."""
    ends = np.round(np.arange(count + 1) * frame_seconds * 100.0).astype(np.int64)
    return [int(d) * 10 for d in np.diff(ends)]


def render_gif(motion: Motion, result: PipelineResult, *, start: float = 0.0, seconds: float | None = None,
               max_fps: float = MAX_FPS, height: int = 320, skin: Skin | None = None) -> bytes:
    """A looping animated GIF: captured (left) and exaggerated (right) side by side at the clip's
    speed, at most ``max_fps`` (up to 50: GIF viewers slow faster frames down); frames from
    `animation_frames`, pictures from `render_frames`. The same bytes every time."""
    check_number("max_fps", max_fps, 0.0, 50.0, low_open=True)
    frames, frame_seconds = animation_frames(motion, result, start=start, seconds=seconds, max_fps=max_fps)
    palette = _gif_palette()
    lookup = np.full(1 << 24, -1, dtype=np.int16)
    pictures = [_indexed(rgb, palette, lookup) for rgb in render_frames(motion, result, frames, height=height, skin=skin)]
    buffer = io.BytesIO()
    pictures[0].save(buffer, format="GIF", save_all=True, append_images=pictures[1:], loop=0,
                     duration=gif_durations(len(pictures), frame_seconds))
    return buffer.getvalue()


def render_mp4(motion: Motion, result: PipelineResult, *, start: float = 0.0, seconds: float | None = None,
               max_fps: float = MAX_FPS, height: int = 320, skin: Skin | None = None) -> bytes:
    """The animation of `render_gif` as an H.264 MP4, encoded by ffmpeg (raw RGB piped in).

    ConfigError when ffmpeg is not on PATH; OSError with ffmpeg's message when it fails.
    """
    ffmpeg = shutil.which("ffmpeg")
    if ffmpeg is None:
        raise ConfigError(NO_FFMPEG)
    frames, frame_seconds = animation_frames(motion, result, start=start, seconds=seconds, max_fps=max_fps)
    pictures = render_frames(motion, result, frames, height=height, skin=skin)
    picture = next(pictures)
    with tempfile.TemporaryDirectory(prefix="mocap-preview-") as folder:
        target, messages = Path(folder) / "preview.mp4", Path(folder) / "ffmpeg.log"
        command = [ffmpeg, "-nostdin", "-hide_banner", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", "rgb24",
                   "-s", f"{picture.shape[1]}x{picture.shape[0]}", "-framerate", f"{1.0 / frame_seconds:.6g}",
                   "-i", "-", "-an", "-c:v", "libx264", "-pix_fmt", "yuv420p", "-crf", "20",
                   "-movflags", "+faststart", "-f", "mp4", str(target)]
        with open(messages, "wb") as log_file:
            process = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=log_file)
            try:
                process.stdin.write(picture.tobytes())
                for picture in pictures:
                    process.stdin.write(picture.tobytes())
            except BrokenPipeError:
                pass  # ffmpeg stopped early; its own message is reported below
            finally:
                process.stdin.close()
                code = process.wait()
        if code != 0 or not target.exists():
            said = [line for line in messages.read_text(errors="replace").splitlines() if line.strip()]
            raise OSError(f"ffmpeg could not write the MP4 (exit {code}): {said[-1] if said else 'no message'}")
        return target.read_bytes()


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
    from ..analysis.limbs import find_limbs
    from ..analysis.tpose import detect_rest_frames

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

    from ..config import load_preset
    from ..core.timing import gaussian_average

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


def joint_named(skeleton: Skeleton, name: str, where: str = "the clip") -> int:
    """The index of the joint called ``name``; a ConfigError naming a few close names otherwise."""
    if name in skeleton.names:
        return skeleton.index(name)
    folded = name.casefold()
    close = [n for n in skeleton.names if folded and (folded in n.casefold() or n.casefold() in folded)]
    close += [n for n in difflib.get_close_matches(name, skeleton.names, n=5, cutoff=0.5) if n not in close]
    hint = f"close names: {', '.join(close[:5])}" if close else f"its joints include {', '.join(skeleton.names[:5])}"
    raise ConfigError(f"no joint named {name!r} in {where}; {hint}")


def _kind(output: Path, trajectory: str | None) -> str:
    """The suffix of the picture to write, refusing what cannot be written."""
    suffix = output.suffix.lower()
    if suffix not in PREVIEW_SUFFIXES:
        found = f"cannot write {suffix}" if suffix else "no suffix"
        raise ConfigError(f"{output}: {found}; previews are .png (still frames), .gif or .mp4 (animations)")
    if trajectory is not None and suffix != ".png":
        raise ConfigError(f"{output}: a joint's trajectory is a still picture; name the file .png")
    if suffix == ".mp4" and shutil.which("ffmpeg") is None:
        raise ConfigError(f"{output}: {NO_FFMPEG}")
    return suffix


def write_preview(source, output: str | os.PathLike, config=None, *, frames: int = 5, overwrite: bool = False,
                  label: str | None = None, trajectory: str | None = None, start: float = 0.0,
                  seconds: float | None = None, max_fps: float = MAX_FPS,
                  skin: Skin | str | os.PathLike | None = None, joint_map: dict | None = None) -> Path:
    """Run the pipeline on a clip (path, bytes or stream) and write its preview to ``output``.

    By the suffix: ``.png`` the body at ``frames`` evenly spaced frames (`render_preview`), or
    with ``trajectory`` (a joint's name) that joint's paths (`render_trajectory`); ``.gif``
    an animation (`render_gif`); ``.mp4`` the same through ffmpeg (`render_mp4`). ``start``
    and ``seconds`` choose the part of the motion shown (default: all of it; an animation
    stops at `MAX_SECONDS`). The name, the joint and ffmpeg are checked and the target is
    checked (never an input; taken only with ``overwrite``) before the clip is run. ``skin``
    (a `Skin` or a skin file, with ``joint_map`` for joints the pairing misses) is the body drawn,
    bound to the clip as the GLB's is (`mocap_exaggerate.rig.binding`); default: the capsule body.
    """
    from ..config import load_preset
    from ..io.bvh import read_bvh
    from ..io.files import atomic_write
    from ..jobs.job import check_targets
    from ..pipeline import run

    output = Path(output)
    kind = _kind(output, trajectory)
    inputs = [Path(p) for p in (source, skin) if isinstance(p, (str, os.PathLike)) and str(p) != "-"]
    check_targets({"preview": output}, inputs, overwrite)
    config = config or load_preset("cartoon")
    motion, _ = read_bvh(source, name=label, fps=config.input.fps, root_offset=config.input.root_offset,
                         up=config.input.up)
    where = label or (str(source) if inputs else "the clip")
    joint = joint_named(motion.skeleton, trajectory, where) if trajectory is not None else None
    if skin is not None:
        from ..io.skin import check_skin, load_skin
        from ..rig.binding import bind_skin

        skin_label = "skin" if isinstance(skin, Skin) else str(skin)
        skin = check_skin(skin, "skin") if isinstance(skin, Skin) else load_skin(skin)
        try:
            skin, _ = bind_skin(skin, motion.skeleton, joint_map)
        except ConfigError as error:
            raise ConfigError(f"{skin_label}: {error} (clip {where})") from None
    result = run(motion, config)
    if kind == ".gif":
        data = render_gif(motion, result, start=start, seconds=seconds, max_fps=max_fps, skin=skin)
    elif kind == ".mp4":
        data = render_mp4(motion, result, start=start, seconds=seconds, max_fps=max_fps, skin=skin)
    elif joint is not None:
        data = render_trajectory(motion, result, joint, config,
                                 frames=preview_window(motion, result, start=start, seconds=seconds))
    else:
        begin, end = preview_window(motion, result, start=start, seconds=seconds)
        data = render_preview(motion, result, at=list(np.linspace(begin, end - 1, frames).astype(int)), skin=skin)
    atomic_write(output, data, overwrite=True)
    return output
