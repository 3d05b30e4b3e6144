"""Flat-shaded triangles drawn into pictures with NumPy: the previews' renderer.

matplotlib drew each of a body's thousands of triangles as its own path, 60-120 ms a picture, most of
a GIF's time (a 10 s GIF of the MakeHuman body took 26 s). Here every triangle of a batch of pictures
is drawn at once:

1. each triangle's rows of pixel centres, and each row's span between the triangle's edges (all
   rows of the batch laid end to end in one array: ``np.repeat`` of each triangle by its rows);
2. each span's pixels, again laid end to end (``np.repeat`` of each span by its width);
3. the triangles come sorted far to near (`mocap_exaggerate.viz.posing.shaded_triangles`), and one
   scatter of their colour indices into the picture leaves each pixel with the last, nearest one
   (NumPy assigns repeated indices in order: "the last value wins", the painter's algorithm);
4. drawn at ``supersample`` times the size and averaged down, so that edges are smooth.

No GPU, no display, no library beyond NumPy: the same bytes on every machine. (A GPU-less OpenGL,
OSMesa or EGL, is a system library a fresh machine does not have; skia-python's wheel is 15 MB and
needs libEGL; Pillow's polygon drawing is one Python call a triangle.)
"""

from __future__ import annotations

import numpy as np

__all__ = ["Canvas", "draw_triangles", "draw_body", "write", "font", "in_order", "SUPERSAMPLE", "BATCH"]

#: Each picture is drawn at this many times its size across and down, then averaged down.
#: Pictures drawn at once (a batch's supersampled pictures and its triangles' pixels are in memory together).
BATCH = 8
#: Batches drawn at the same time, in threads: NumPy lets go of the interpreter while it works.
THREADS = 2

SUPERSAMPLE = 2  # (at most 2: `Canvas.pictures` sums 4 samples of 8 bits in 10)


class Canvas:
    """A batch of ``count`` pictures of ``height`` x ``width`` pixels, drawn at ``supersample`` times that.

    Colours are kept as indices into a palette (index 0 the background) until `pictures` averages them
    down to RGB: a colour of its own (`colour`) or one of the 256 shades of a body's colour (`shades`),
    so that an index is two bytes.
    """

    def __init__(self, count: int, height: int, width: int, background=(1.0, 1.0, 1.0),
                 supersample: int = SUPERSAMPLE) -> None:
        self.count, self.height, self.width, self.scale = int(count), int(height), int(width), int(supersample)
        self.index = np.zeros((self.count, self.height * self.scale, self.width * self.scale), dtype=np.uint16)
        self.palette = [np.asarray(background, dtype=np.float64)[None]]
        self._size = 1

    def colour(self, rgb) -> int:
        """The index of a new palette colour ``rgb`` (3 floats in [0, 1])."""
        self.palette.append(np.asarray(rgb, dtype=np.float64).reshape(1, 3))
        self._size += 1
        return self._size - 1

    def shades(self, rgb, shade: np.ndarray) -> np.ndarray:
        """Indices of ``shade (N,)`` (in [0, 1]) times the colour ``rgb``, out of 256 shades of it."""
        if self._size + 256 > 1 << 16:
            raise ValueError("a picture of more than 255 colours")
        self.palette.append(np.linspace(0.0, 1.0, 256)[:, None] * np.asarray(rgb, dtype=np.float64))
        first = self._size
        self._size += 256
        return (first + np.rint(np.clip(shade, 0.0, 1.0) * 255.0)).astype(np.uint16)

    def fill(self, picture: slice | int, rows: slice, columns: slice, colour: int) -> None:
        """Fill a rectangle (in picture pixels, not supersampled) with palette colour ``colour``."""
        s = self.scale
        rows = slice(None if rows.start is None else rows.start * s, None if rows.stop is None else rows.stop * s)
        columns = slice(None if columns.start is None else columns.start * s,
                        None if columns.stop is None else columns.stop * s)
        self.index[picture, rows, columns] = colour

    def pictures(self) -> np.ndarray:
        """``(count, height, width, 3) uint8``: the pictures, averaged down from the supersampled drawing.

        Only the pixels with something drawn in them are averaged (a body fills a sixth of its picture);
        the rest are the background."""
        palette = np.rint(np.concatenate(self.palette) * 255.0).clip(0, 255).astype(np.uint32)
        # Each colour packed in one word, 10 bits a channel: the sum of up to 4 samples does not carry over.
        s = self.scale
        packed = (palette[:, 0] << 20) | (palette[:, 1] << 10) | palette[:, 2]
        out = np.empty((self.count, self.height, self.width, 3), dtype=np.uint8)
        out[...] = palette[0].astype(np.uint8)
        half = (s * s) // 2
        for k in range(self.count):  # one picture at a time: a batch's supersampled colours are large
            samples = [self.index[k, i::s, j::s] for i in range(s) for j in range(s)]
            drawn = np.flatnonzero(np.bitwise_or.reduce(samples).ravel())
            total = sum(packed[sample.ravel()[drawn]] for sample in samples)
            picture = out[k].reshape(-1, 3)
            for channel, shift in enumerate((20, 10, 0)):
                picture[drawn, channel] = (((total >> shift) & 1023) + half) // (s * s)
        return out


def draw_triangles(canvas: Canvas, pictures: np.ndarray, triangles: np.ndarray, colours: np.ndarray) -> None:
    """Draw triangles into ``canvas`` (in place), later ones over earlier ones.

    pictures : (N,) int, the picture each triangle is drawn into
    triangles : (N, 3, 2) float, corners in picture pixels (x across from the left, y down from the top;
        a pixel's centre is at its index + 0.5)
    colours : (N,) int palette indices (`Canvas.colour`, `Canvas.shades`)

    Scanlines: each triangle's rows of pixel centres, each row's span between its edges, each span's
    pixels; so only the pixels a triangle covers are made (its bounding box's were twice as many).
    """
    s = canvas.scale
    rows, columns = canvas.index.shape[1:]
    corners = np.asarray(triangles, dtype=np.float32) * s - 0.5  # pixel centres at integers
    # Corners sorted top to bottom: the long edge 0-2 spans every row, the short ones 0-1 and 1-2 meet at 1.
    order = np.argsort(corners[..., 1], axis=1, kind="stable")
    corners = np.take_along_axis(corners, order[..., None], axis=1)
    (x0, y0), (x1, y1), (x2, y2) = corners[:, 0].T, corners[:, 1].T, corners[:, 2].T
    first = np.maximum(np.ceil(y0), 0).astype(np.int64)
    last = np.minimum(np.floor(y2), rows - 1).astype(np.int64)
    count = np.maximum(last - first + 1, 0)
    owner = np.repeat(np.arange(len(count)), count)
    if not len(owner):
        return
    y = (np.repeat(first - np.cumsum(count) + count, count) + np.arange(len(owner))).astype(np.float32)
    x0, y0, x1, y1, x2, y2 = (v[owner] for v in (x0, y0, x1, y1, x2, y2))

    def along(xa, ya, xb, yb):
        """x of the edge (a, b) at height y (a's x where the edge is level)."""
        rise = yb - ya
        return xa + (y - ya) * np.divide(xb - xa, rise, out=np.zeros_like(rise), where=rise > 1e-12)

    long_edge = along(x0, y0, x2, y2)
    short_edge = np.where(y < y1, along(x0, y0, x1, y1), along(x1, y1, x2, y2))
    low = np.maximum(np.ceil(np.minimum(long_edge, short_edge) - 1e-9), 0).astype(np.int64)
    high = np.minimum(np.floor(np.maximum(long_edge, short_edge) + 1e-9), columns - 1).astype(np.int64)
    width = np.maximum(high - low + 1, 0)
    spans = np.flatnonzero(width)
    width = width[spans]
    start = ((np.asarray(pictures)[owner[spans]] * rows + y[spans].astype(np.int64)) * columns + low[spans])
    pixels = np.repeat(start - np.cumsum(width) + width, width) + np.arange(int(width.sum()))
    canvas.index.reshape(-1)[pixels] = np.repeat(np.asarray(colours)[owner[spans]], width)


def draw_body(canvas: Canvas, pictures: np.ndarray, vertices: np.ndarray, faces: np.ndarray,
              axes: tuple[int, int, int], colour, left: float | np.ndarray, top: float, scale: float,
              origin: np.ndarray, high: float, facing: int = 0) -> None:
    """Draw a posed, shaded body into some of ``canvas``'s pictures.

    pictures : (F,) the picture each frame of ``vertices (F, V, 3)`` is drawn into
    left, top : where the view's left edge (``origin (F,)`` across, in world units) and top (``high``
        up) are, in picture pixels; ``scale`` pixels per world unit
    """
    from .posing import shaded_triangles

    if not len(faces) or not len(vertices):
        return
    frame, screen, shade = shaded_triangles(vertices, faces, axes, facing)  # far to near in each frame
    pixels = np.empty_like(screen)
    pixels[..., 0] = np.asarray(np.broadcast_to(left, len(vertices)), dtype=np.float32)[frame, None] + (
        screen[..., 0] - np.asarray(origin, dtype=np.float32)[frame, None]) * scale
    pixels[..., 1] = top + (high - screen[..., 1]) * scale
    draw_triangles(canvas, np.asarray(pictures)[frame], pixels, canvas.shades(colour, shade))


_FONTS: dict[int, object] = {}


def font(size: int):
    """Pillow's own font at ``size`` pixels (bundled with Pillow: the same letters everywhere)."""
    from PIL import ImageFont

    if size not in _FONTS:
        _FONTS[size] = ImageFont.load_default(size=size)
    return _FONTS[size]


def write(picture: np.ndarray, texts: list[tuple[float, float, str, int, tuple, str]]) -> np.ndarray:
    """``picture (H, W, 3) uint8`` with ``texts`` written on it: (x, y, text, size, rgb 0-255, anchor) each,
    anchor as Pillow's (``"mt"``: x is the middle, y the top)."""
    from PIL import Image, ImageDraw

    image = Image.fromarray(picture)
    draw = ImageDraw.Draw(image)
    for x, y, text, size, colour, anchor in texts:
        draw.text((x, y), text, fill=tuple(colour), font=font(size), anchor=anchor)
    return np.asarray(image)


def in_order(draw, batches):
    """``draw(batch)`` (a list of pictures) for each batch, in `THREADS` threads, yielded picture by
    picture in the batches' order (at most ``THREADS + 1`` batches held at once)."""
    from concurrent.futures import ThreadPoolExecutor

    batches = list(batches)
    with ThreadPoolExecutor(THREADS) as pool:
        running = [pool.submit(draw, batch) for batch in batches[:THREADS]]
        for number in range(len(batches)):
            done = running.pop(0).result()
            if number + THREADS < len(batches):
                running.append(pool.submit(draw, batches[number + THREADS]))
            yield from done
