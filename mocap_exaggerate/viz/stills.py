"""Still pictures as PNG bytes: the captured and exaggerated body at a few frames (`render_preview`)
and one joint's path captured, averaged and exaggerated (`render_trajectory`).

Drawn with matplotlib (Agg): no GPU, no display, the same bytes every time.
"""

from __future__ import annotations

import io

import numpy as np

from ..core.motion import Motion
from ..pipeline import PipelineResult
from ..rig.skinning import Skin
from .framing import fastest_end, lined_up, view_limits
from .posing import CAPTURED_COLOR, EXAGGERATED_COLOR, pose_bodies, shaded_triangles

__all__ = ["render_preview", "render_trajectory"]


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
        polygons, colors = shaded_triangles(vertices, faces, bodies.axes, color)
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
