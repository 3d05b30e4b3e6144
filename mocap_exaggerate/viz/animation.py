"""Animated previews: the captured and exaggerated body side by side at the clip's speed, as
RGB pictures (`render_frames`), a looping GIF (`render_gif`) or an H.264 MP4 through ffmpeg
(`render_mp4`).

`animation_frames` chooses the frames shown (every step-th, at most `MAX_FPS`);
one camera and one scale for the whole animation (`camera_centres`, `view_limits`).
"""

from __future__ import annotations

import io
import logging
import math
import shutil
import subprocess
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from ..core.errors import ConfigError, check_number
from ..core.motion import Motion
from ..pipeline import PipelineResult
from ..rig.skinning import Skin
from .framing import camera_centres, preview_window, steady_view
from .posing import CAPTURED_COLOR, EXAGGERATED_COLOR, pose_bodies
from .raster import BATCH, Canvas, draw_body, in_order, write

__all__ = ["animation_frames", "render_frames", "render_gif", "render_mp4", "encode_gif", "encode_mp4", "gif_durations",
           "gif_quantizer", "MAX_FPS",
           "MAX_SECONDS", "NO_FFMPEG"]

log = logging.getLogger(__name__)

MAX_FPS = 20.0  # an animation shows every step-th frame, the smallest step at or under this rate
MAX_SECONDS = 10.0  # an animation's default length: a long clip is cut here (``seconds`` shows more)
NO_FFMPEG = "writing .mp4 needs ffmpeg on PATH, which was not found; .gif previews work without it"


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


def render_frames(motion: Motion, result: PipelineResult, frames: np.ndarray, *,
                  height: int = 320, skin: Skin | None = None, finish=None) -> Iterator[np.ndarray]:
    """RGB pictures ``(H, W, 3) uint8``, one per output frame of ``frames``: the captured body
    (left, grey) and the exaggerated one (right, orange) side by side, one camera, one scale.

    height : a body height is 0.75 ``height`` pixels; a title and a frame label add 40. ``H`` and ``W``
    are even (as H.264 wants) and the same for every picture.
    The view covers every vertex of both bodies in every frame, and at least the captured body with a
    quarter of its height around it (`steady_view`): animations of one clip at different settings are
    the same size with the body at one scale, but where one exaggerates further. The camera
    follows the captured root across when it travels (`camera_centres`); ticks on the ground
    then scroll by with the travel. Both bodies are posed, shaded and drawn (`mocap_exaggerate.viz.raster`)
    for a batch of frames at once. ``finish`` (a GIF's quantizer, `gif_quantizer`) is applied to each
    picture in the drawing threads.
    """
    frames = np.asarray(frames, dtype=np.int64)
    bodies = pose_bodies(motion, result, frames, skin, dtype=np.float32)
    right, up, _ = bodies.axes
    points = bodies.screen_points()
    tall = motion.skeleton.height()
    shown_seconds = (frames[1] - frames[0]) * motion.frame_time if len(frames) > 1 else motion.frame_time
    centre = camera_centres(bodies.root[:, right], points, tall, max(0.4 / shown_seconds, 1.0))
    half, low, high = steady_view(bodies.captured[..., [right, up]], points, centre, tall)
    # One scale for every animation of the clip, whatever its settings: 0.75 ``height`` pixels a body height.
    scale = 0.75 * max(int(height), 16) / tall if tall > 0 else max(int(height), 16) / (high - low)
    panel_h = max(int(math.ceil((high - low) * scale)), 16)
    panel_w = max(int(math.ceil(2.0 * half * scale)), 16)
    half = 0.5 * panel_w / scale
    top, bottom, gap = 22, 18, 10
    gap += (2 * panel_w + gap) % 2
    bottom += (panel_h + top + bottom) % 2
    width_px, height_px = 2 * panel_w + gap, panel_h + top + bottom
    # The ground: the lowest the captured body goes (the exaggerated one may go through it).
    floor = float(bodies.captured[..., up].min() if bodies.captured.shape[1] else bodies.root[:, up].min())
    floor_row = min(max(int(round(top + (high - floor) * scale)), 0), height_px - 1)
    tick_rows = max(int(round(0.025 * panel_h)), 1)
    spacing = (tall if tall > 0 else high - low) / 4.0
    panels = ((bodies.captured, bodies.captured_faces, CAPTURED_COLOR, bodies.captured_facing, "captured", (89, 89, 97)),
              (bodies.exaggerated, bodies.exaggerated_faces, EXAGGERATED_COLOR, bodies.exaggerated_facing, "exaggerated",
               (204, 107, 20)))
    first = result.first

    def draw(begin: int) -> list[np.ndarray]:
        count = min(BATCH, len(frames) - begin)
        chunk = slice(begin, begin + count)
        canvas = Canvas(count, height_px, width_px)
        ground = canvas.colour((0.8, 0.8, 0.82))
        for number, (vertices, faces, colour, facing, *_) in enumerate(panels):
            left = number * (panel_w + gap)
            canvas.fill(slice(None), slice(floor_row, floor_row + 1), slice(left, left + panel_w), ground)
            for k in range(count):
                view = centre[begin + k] - half
                for x in np.arange(math.floor(view / spacing), math.ceil((view + 2 * half) / spacing) + 1):
                    column = int(round(left + (x * spacing - view) * scale))
                    if left <= column < left + panel_w:
                        canvas.fill(k, slice(floor_row, floor_row + tick_rows + 1), slice(column, column + 1), ground)
            draw_body(canvas, np.arange(count), vertices[chunk], faces, bodies.axes, colour,
                      left, top, scale, centre[chunk] - half, high, facing)
        pictures = []
        for k, picture in enumerate(canvas.pictures()):
            frame = frames[begin + k]
            texts = [(number * (panel_w + gap) + panel_w / 2, 4, title, 12, ink, "mt")
                     for number, (*_, title, ink) in enumerate(panels)]
            texts.append((width_px / 2, height_px - 3, f"frame {frame}   {(frame - first) * motion.frame_time:.2f} s",
                          11, (77, 77, 77), "mb"))
            pictures.append(write(picture, texts) if finish is None else finish(write(picture, texts)))
        return pictures

    yield from in_order(draw, range(0, len(frames), BATCH))


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
    return encode_gif(render_frames(motion, result, frames, height=height, skin=skin, finish=gif_quantizer()),
                      frame_seconds)


def gif_quantizer():
    """A function turning an RGB picture into a GIF frame on the fixed palette (`_indexed`): drawing threads
    call it (they share its table of colours found; two writing one colour write the same index)."""
    palette = _gif_palette()
    lookup = np.full(1 << 24, -1, dtype=np.int16)
    return lambda rgb: _indexed(rgb, palette, lookup)


def encode_gif(pictures: Iterable, frame_seconds: float) -> bytes:
    """``pictures`` (RGB arrays, or frames `gif_quantizer` made) as a looping GIF, each shown ``frame_seconds``,
    on one fixed palette (`_gif_palette`)."""
    quantize = gif_quantizer()
    indexed = [picture if not isinstance(picture, np.ndarray) else quantize(picture) for picture in pictures]
    buffer = io.BytesIO()
    indexed[0].save(buffer, format="GIF", save_all=True, append_images=indexed[1:], loop=0,
                    duration=gif_durations(len(indexed), frame_seconds))
    return buffer.getvalue()


def render_mp4(motion: Motion, result: PipelineResult, *, start: float = 0.0, seconds: float | None = None,
               max_fps: float = MAX_FPS, height: int = 320, skin: Skin | None = None) -> bytes:
    """The animation of `render_gif` as an H.264 MP4, encoded by ffmpeg (raw RGB piped in).

    ConfigError when ffmpeg is not on PATH; OSError with ffmpeg's message when it fails.
    """
    if shutil.which("ffmpeg") is None:
        raise ConfigError(NO_FFMPEG)
    frames, frame_seconds = animation_frames(motion, result, start=start, seconds=seconds, max_fps=max_fps)
    return encode_mp4(render_frames(motion, result, frames, height=height, skin=skin), frame_seconds)


def encode_mp4(pictures: Iterator[np.ndarray], frame_seconds: float) -> bytes:
    """RGB ``pictures`` (all of one size, even) as an H.264 MP4 by ffmpeg, each shown ``frame_seconds``.

    ConfigError when ffmpeg is not on PATH; OSError with ffmpeg's message when it fails.
    """
    ffmpeg = shutil.which("ffmpeg")
    if ffmpeg is None:
        raise ConfigError(NO_FFMPEG)
    pictures = iter(pictures)
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
