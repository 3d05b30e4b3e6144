"""Still pictures as PNG bytes: the captured and exaggerated body at a few frames (`render_preview`)
and one joint's path captured, averaged and exaggerated (`render_trajectory`).

The bodies are drawn by `mocap_exaggerate.viz.raster` (NumPy), the paths with matplotlib (Agg): no
GPU, no display, the same bytes every time.
"""

from __future__ import annotations

import io

import numpy as np

from ..core.motion import Motion
from ..pipeline import PipelineResult
from ..rig.skinning import Skin
from .framing import fastest_end, lined_up, steady_view
from .posing import CAPTURED_COLOR, EXAGGERATED_COLOR, pose_bodies
from .raster import Canvas, draw_body, write

__all__ = ["render_preview", "render_trajectory", "png_bytes"]


def render_preview(motion: Motion, result: PipelineResult, *, frames: int = 5, width: float = 2.4,
                   at: list[int] | None = None, dpi: int = 80, skin: Skin | None = None) -> bytes:
    """A PNG: the captured (top, grey) and exaggerated (bottom, orange) body at a few frames.

    ``at``: the output frames to draw (e.g. `telling_frames`); default ``frames`` evenly spaced.
    ``width * dpi``: pixels a body height. Every column is centred on the captured root and all panels
    share one scale and one height range, room for the captured body and a sixth of its height around it,
    more only where the exaggeration goes further (`steady_view`): previews of one clip at different
    settings come out the same size, the body at one scale.
    Drawn by `mocap_exaggerate.viz.raster`.
    """
    first = result.first
    last = result.world_positions.shape[0] - 1
    picks = np.unique(np.linspace(first, last, frames).astype(int) if at is None else np.clip(at, 0, last))
    bodies = pose_bodies(motion, result, picks, skin, dtype=np.float32)
    right, up, _ = bodies.axes
    tall = motion.skeleton.height()
    half, low, high = steady_view(bodies.captured[..., [right, up]], bodies.screen_points(), bodies.root[:, right],
                                  tall)
    # One scale for every preview of the clip, whatever its settings: ``width * dpi`` pixels a body height.
    scale = width * dpi / tall if tall > 0 else width * dpi / (2.0 * half)
    column = max(int(np.ceil(2.0 * half * scale)), 16)
    half = column / (2.0 * scale)
    row = max(int(np.ceil((high - low) * scale)), 16)
    top, title_row, margin = 26, 16, 6
    width_px = len(picks) * column + 2 * margin
    height_px = top + title_row + 2 * row + margin
    canvas = Canvas(1, height_px, width_px)
    everything = np.zeros(len(picks), dtype=np.int64)
    lefts = margin + column * np.arange(len(picks), dtype=np.float64)
    for number, (vertices, faces, colour, facing) in enumerate((
            (bodies.captured, bodies.captured_faces, CAPTURED_COLOR, bodies.captured_facing),
            (bodies.exaggerated, bodies.exaggerated_faces, EXAGGERATED_COLOR, bodies.exaggerated_facing))):
        draw_body(canvas, everything, vertices, faces, bodies.axes, colour, lefts, top + title_row + number * row,
                  scale, bodies.root[:, right] - half, high, facing)
    texts = [(width_px / 2, 4, "captured (top) and exaggerated (bottom)", 13, (30, 30, 30), "mt")]
    texts += [(left + column / 2, top, f"frame {frame}", 11, (30, 30, 30), "mt") for left, frame in zip(lefts, picks)]
    return png_bytes(write(canvas.pictures()[0], texts))


def png_bytes(picture: np.ndarray) -> bytes:
    """``picture (H, W, 3) uint8`` as PNG bytes (nothing but the pixels: the same bytes every time)."""
    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(picture).save(buffer, format="PNG", optimize=False)
    return buffer.getvalue()


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


def _png(figure, dpi: int = 80) -> bytes:
    """The figure as PNG bytes, the same bytes every time (no software or date written)."""
    import matplotlib.pyplot as plt

    figure.tight_layout()
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=dpi, metadata={"Software": None})
    plt.close(figure)
    return buffer.getvalue()
