"""Settings side by side: one clip run with several settings, drawn as one grid (``compare``).

Each `Cell` is a run's settings (a label, the options that make it, the config); `run_cells` runs them
all in memory (no files) and `cell_figures` labels each with what it did: the longest any limb got,
the jerk ratio, and how much the speed limit took (`mocap_exaggerate.analysis.quality.summary`).
The grid's first cell is the captured motion; every cell is drawn by one camera at one scale, so
that a body bigger in one cell is bigger in the motion:

- ``.png``: each cell a strip of the same few frames (`render_grid_png`);
- ``.gif`` / ``.mp4``: each cell its body moving, all in step (`render_grid_frames`);
- ``.html``: the page of `mocap_exaggerate.viz.page` with every cell's GLB (`render_grid_html`).

The cells are laid out in rows of ``columns`` (the last list's length, as ``--omega 2,4,6`` gives 3),
under a first row holding the captured motion.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.errors import ConfigError
from ..core.motion import Motion
from ..pipeline import PipelineResult
from ..rig.skinning import Skin
from .animation import MAX_FPS, NO_FFMPEG, animation_frames, encode_gif, encode_mp4, gif_quantizer
from .framing import camera_centres, preview_window, telling_frames, view_limits
from .posing import CAPTURED_COLOR, EXAGGERATED_COLOR, facing, pose_captured, pose_exaggerated
from .raster import BATCH, Canvas, draw_body, in_order, write

__all__ = ["Cell", "Ran", "run_cells", "cell_figures", "render_grid_png", "render_grid_frames",
           "render_grid_html", "write_compare", "COMPARE_SUFFIXES", "MAX_CELLS"]

COMPARE_SUFFIXES = (".png", ".gif", ".mp4", ".html")
#: How fine the default body of an animated grid's cells is (`mocap_exaggerate.rig.body.default_skin`): ten
#: bodies a picture, each under 200 pixels tall, need not be as round as one of a preview.
GRID_DETAIL = 0.5
#: The most cells a grid draws (a 6 x 6 sweep): each is a run of the whole pipeline.
MAX_CELLS = 36


@dataclass(frozen=True)
class Cell:
    """One setting of a grid: ``label`` (what differs, ``"sigma 0.1s, omega 2"``), ``words`` (the command
    line options that make it, for ``exaggerate``) and the resolved ``config``."""

    label: str
    words: tuple[str, ...]
    config: object


@dataclass
class Ran:
    """A cell run: its `Cell`, the pipeline's result, `cell_figures` and the numbers they show
    (``summary``: `mocap_exaggerate.analysis.quality.summary`)."""

    cell: Cell
    result: PipelineResult
    figures: dict = field(default_factory=dict)
    summary: dict = field(default_factory=dict)


def cell_figures(motion: Motion, result: PipelineResult, found: dict | None = None) -> dict[str, str]:
    """A run's figures as short texts: ``{"stretch": "1.42x", "jerk": "0.91", "limit": "12 %"}`` (of its
    `mocap_exaggerate.analysis.quality.summary`, ``found`` when the caller has it)."""
    from ..analysis.quality import summary

    found = summary(motion, result) if found is None else found
    return {"stretch": f"{found['stretch']:.2f}x", "jerk": f"{found['jerk']:.2f}",
            "limit": "-" if found["limit"] is None else f"{found['limit']:.0%}"}


def run_cells(motion: Motion, cells: list[Cell], threads: int = 2) -> list[Ran]:
    """Run every cell's pipeline on ``motion`` (in threads: NumPy lets go of the interpreter while it works)."""
    from concurrent.futures import ThreadPoolExecutor

    from ..pipeline import run

    def one(cell: Cell) -> Ran:
        result = run(motion, cell.config)
        from ..analysis.quality import summary

        found = summary(motion, result)
        return Ran(cell, result, cell_figures(motion, result, found), found)

    with ThreadPoolExecutor(max(1, threads)) as pool:
        return list(pool.map(one, cells))


def _lined_up(ran: list[Ran]) -> None:
    """Refuse cells whose outputs do not share frames (a rest pose dropped in one and kept in another)."""
    counts = {r.result.world_positions.shape[0] for r in ran}
    if len(counts) > 1:
        raise ConfigError("the cells' outputs have different frame counts (input.tpose differs between them?); "
                          "compare settings that keep the same frames")


class _Bodies:
    """Every cell's body posed at some frames, the captured one first, and one view for all of them (the
    default body at ``detail``, `mocap_exaggerate.rig.body.default_skin`, where no skin is given)."""

    def __init__(self, motion: Motion, ran: list[Ran], frames: np.ndarray, skin: Skin | None,
                 detail: float = 1.0) -> None:
        from ..jobs.outputs import base_skin

        first = ran[0].result

        def body_of(result: PipelineResult) -> Skin:
            if skin is not None or detail >= 1.0:
                return base_skin(motion, result, skin)
            from ..rig.body import default_skin

            hierarchy = result.hierarchy
            return default_skin(motion.skeleton, hierarchy.rigid if hierarchy is not None else None, detail)

        body = body_of(first)
        captured, self.root, self.axes = pose_captured(motion, first, frames, body, np.float32)
        self.vertices = [captured]
        self.faces = [body.faces]
        self.facing = [facing(body.vertices, body.faces)]
        for r in ran:
            own = body_of(r.result)
            vertices, rubber = pose_exaggerated(motion, r.result, frames, own, np.float32)
            self.vertices.append(vertices)
            self.faces.append(rubber.faces)
            self.facing.append(facing(rubber.vertices, rubber.faces))
        self.colours = [CAPTURED_COLOR] + [EXAGGERATED_COLOR] * len(ran)

    def points(self) -> np.ndarray:
        right, up, _ = self.axes
        return np.concatenate(self.vertices + [self.root[:, None].astype(np.float32)], axis=1)[..., [right, up]]


def _layout(count: int, columns: int) -> list[tuple[int, int]]:
    """(row, column) of each cell: the captured motion alone in row 0, the runs in rows of ``columns``."""
    columns = max(1, min(columns, count - 1 if count > 1 else 1))
    return [(0, 0)] + [(1 + k // columns, k % columns) for k in range(count - 1)]


def _label_width(labels: list[tuple[str, str]]) -> int:
    """Pixels the widest cell's two label lines need (a cell is at least this wide: labels ran into their
    neighbours and past the picture's edge)."""
    from .raster import font

    return int(math.ceil(max(max(font(12).getlength(a), font(10).getlength(b)) for a, b in labels))) + 10


def _labels(ran: list[Ran]) -> list[tuple[str, str]]:
    lines = [("captured", "the motion as read")]
    for r in ran:
        f = r.figures
        lines.append((r.cell.label, f"stretch {f['stretch']}  jerk {f['jerk']}  limit {f['limit']}"))
    return lines


LABEL_ROWS = 34  # pixels above each cell for its two lines


def render_grid_png(motion: Motion, ran: list[Ran], *, columns: int, frames: int = 3, start: float = 0.0,
                    seconds: float | None = None, skin: Skin | None = None, column_px: int = 150) -> bytes:
    """A PNG: every cell (the captured motion first) as a strip of the same ``frames`` frames, one camera per
    frame (centred on the captured root) and one scale for all. The frames are where the strongest run is
    most exaggerated (`telling_frames`), or evenly spaced over ``start`` and ``seconds`` when given."""
    from .stills import png_bytes

    _lined_up(ran)
    begin, end = preview_window(motion, ran[0].result, start=start, seconds=seconds)
    if start == 0.0 and seconds is None:
        # The moments the strongest run (its longest limb) is exaggerated most: the ends of a clip are as captured.
        strongest = max(ran, key=lambda r: r.summary["stretch"])
        picks = np.asarray(telling_frames(motion, strongest.result, frames), dtype=np.int64)
    else:
        picks = np.unique(np.linspace(begin, end - 1, frames).astype(int))
    bodies = _Bodies(motion, ran, picks, skin)
    right = bodies.axes[0]
    half, low, high = view_limits(bodies.points(), bodies.root[:, right])
    scale = column_px / (2.0 * half)
    row_px = max(int(round((high - low) * scale)), 16)
    strip = max(len(picks) * column_px, _label_width(_labels(ran)))
    inset = (strip - len(picks) * column_px) / 2.0  # the frames in the middle of a strip widened for its label
    gap, margin, top = 40, 8, 24
    places = _layout(len(bodies.vertices), columns)
    rows = 1 + max(r for r, _ in places)
    grid_columns = 1 + max(c for _, c in places)
    width = 2 * margin + grid_columns * strip + (grid_columns - 1) * gap
    height = top + rows * (LABEL_ROWS + row_px) + (rows - 1) * gap + margin
    canvas = Canvas(1, height, width)
    texts = [(width / 2, 4, f"{len(ran)} settings side by side, frame{'s' if len(picks) > 1 else ''} "
                           f"{', '.join(str(p) for p in picks)}", 13,
              (30, 30, 30), "mt")]
    everything = np.zeros(len(picks), dtype=np.int64)
    for (row, column), vertices, faces, colour, face, (label, figures) in zip(
            places, bodies.vertices, bodies.faces, bodies.colours, bodies.facing, _labels(ran)):
        left = margin + column * (strip + gap)
        y = top + row * (LABEL_ROWS + row_px + gap)
        lefts = left + inset + column_px * np.arange(len(picks), dtype=np.float64)
        draw_body(canvas, everything, vertices, faces, bodies.axes, colour, lefts, y + LABEL_ROWS, scale,
                  bodies.root[:, right] - half, high, face)
        texts += [(left + strip / 2, y, label, 12, (30, 30, 30), "mt"),
                  (left + strip / 2, y + 16, figures, 10, (90, 90, 90), "mt")]
    return png_bytes(write(canvas.pictures()[0], texts))


def render_grid_frames(motion: Motion, ran: list[Ran], frames: np.ndarray, *, columns: int,
                       cell_px: int = 180, skin: Skin | None = None, finish=None) -> Iterator[np.ndarray]:
    """RGB pictures, one per output frame of ``frames``: every cell's body moving in step, the captured
    one first, one camera (following the captured root where it travels) and one scale for all."""
    _lined_up(ran)
    frames = np.asarray(frames, dtype=np.int64)
    bodies = _Bodies(motion, ran, frames, skin, detail=GRID_DETAIL)
    right, up, _ = bodies.axes
    points = bodies.points()
    tall = motion.skeleton.height()
    shown = (frames[1] - frames[0]) * motion.frame_time if len(frames) > 1 else motion.frame_time
    centre = camera_centres(bodies.root[:, right], points, tall, max(0.4 / shown, 1.0))
    half, low, high = view_limits(points, centre)
    panel_h = max(int(cell_px), 16)
    panel_w = max(math.ceil(panel_h * 2.0 * half / (high - low)), _label_width(_labels(ran)))
    half = 0.5 * panel_w / panel_h * (high - low)
    scale = panel_h / (high - low)
    places = _layout(len(bodies.vertices), columns)
    rows = 1 + max(r for r, _ in places)
    grid_columns = 1 + max(c for _, c in places)
    gap, bottom = 10, 18
    width = grid_columns * panel_w + (grid_columns - 1) * gap
    height = rows * (LABEL_ROWS + panel_h) + (rows - 1) * gap + bottom
    width += width % 2
    height += height % 2
    labels = _labels(ran)
    first = ran[0].result.first

    def draw(begin: int) -> list[np.ndarray]:
        count = min(BATCH, len(frames) - begin)
        chunk = slice(begin, begin + count)
        canvas = Canvas(count, height, width)
        for (row, column), vertices, faces, colour, face in zip(places, bodies.vertices, bodies.faces, bodies.colours,
                                                                bodies.facing):
            left = column * (panel_w + gap)
            y = row * (LABEL_ROWS + panel_h + gap) + LABEL_ROWS
            draw_body(canvas, np.arange(count), vertices[chunk], faces, bodies.axes, colour, left, y, scale,
                      centre[chunk] - half, high, face)
        texts = []
        for (row, column), (label, figures) in zip(places, labels):
            left = column * (panel_w + gap)
            y = row * (LABEL_ROWS + panel_h + gap)
            texts += [(left + panel_w / 2, y + 2, label, 12, (30, 30, 30), "mt"),
                      (left + panel_w / 2, y + 17, figures, 10, (90, 90, 90), "mt")]
        pictures = []
        for k, picture in enumerate(canvas.pictures()):
            frame = frames[begin + k]
            said = texts + [(width / 2, height - 3, f"frame {frame}   {(frame - first) * motion.frame_time:.2f} s",
                             11, (77, 77, 77), "mb")]
            pictures.append(write(picture, said) if finish is None else finish(write(picture, said)))
        return pictures

    yield from in_order(draw, range(0, len(frames), BATCH))


def render_grid_html(motion: Motion, ran: list[Ran], *, skin: Skin | None = None, title: str = "compare") -> bytes:
    """The page of `mocap_exaggerate.viz.page` playing every cell's GLB, the captured motion first."""
    from ..jobs.outputs import captured_glb, make_glb
    from .page import PageFigure, page_ends, page_html, page_sigma

    _lined_up(ran)
    figures = [PageFigure("captured", captured_glb(motion, ran[0].result, skin), {})]
    for r in ran:
        glb, _, _ = make_glb(motion, r.result, skin)
        figures.append(PageFigure(r.cell.label, glb, dict(r.figures)))
    config = ran[0].cell.config
    return page_html(figures, title=title, fps=motion.fps, ends=page_ends(motion),
                     sigma_frames=page_sigma(motion, config)).encode("utf-8")


def write_compare(source, output: str | os.PathLike, cells: list[Cell], *, columns: int, frames: int = 3,
                  start: float = 0.0, seconds: float | None = None, max_fps: float = MAX_FPS,
                  overwrite: bool = False, skin=None, joint_map=None, config=None,
                  label: str | None = None, protect: tuple = ()) -> tuple[Path, list[Ran]]:
    """Run ``cells`` on a clip (path, bytes or stream) and write their grid to ``output`` (by its suffix,
    `COMPARE_SUFFIXES`); the runs, for their figures and command lines. ``config`` (the first cell's by
    default) says how the clip is read and which character is drawn (``skin`` and ``joint_map`` over it);
    ``protect``: more files the output must not land on (the pipeline file it was read from)."""
    import shutil

    from ..io.files import atomic_write
    from .preview import clip_and_character

    output = Path(output)
    suffix = output.suffix.lower()
    if suffix not in COMPARE_SUFFIXES:
        found = f"cannot write {suffix}" if suffix else "no suffix"
        raise ConfigError(f"{output}: {found}; a grid is .png (still frames), .gif or .mp4 (animated) or .html (a page)")
    if suffix == ".mp4" and shutil.which("ffmpeg") is None:
        raise ConfigError(f"{output}: {NO_FFMPEG}")
    if not cells:
        raise ConfigError("nothing to compare: give lists of values, e.g. --omega 2,4,6")
    if len(cells) > MAX_CELLS:
        raise ConfigError(f"{len(cells)} settings to compare; at most {MAX_CELLS} (each is a run of the pipeline)")
    motion, body, where = clip_and_character(source, {"compare": output}, config or cells[0].config, skin=skin,
                                             joint_map=joint_map, overwrite=overwrite, label=label, protect=protect)
    ran = run_cells(motion, cells)
    if suffix == ".png":
        data = render_grid_png(motion, ran, columns=columns, frames=frames, start=start, seconds=seconds, skin=body)
    elif suffix == ".html":
        data = render_grid_html(motion, ran, skin=body, title=f"compare: {Path(where).name}")
    else:
        shown, frame_seconds = animation_frames(motion, ran[0].result, start=start, seconds=seconds, max_fps=max_fps)
        if suffix == ".gif":
            data = encode_gif(render_grid_frames(motion, ran, shown, columns=columns, skin=body, finish=gif_quantizer()),
                              frame_seconds)
        else:
            data = encode_mp4(render_grid_frames(motion, ran, shown, columns=columns, skin=body), frame_seconds)
    atomic_write(output, data, overwrite=True)
    return output, ran
