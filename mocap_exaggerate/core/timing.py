"""Time on a clip: durations and frame numbers as users write them, and the filters along time.

Durations (``0.2``/``"0.2s"`` seconds, ``"200ms"``, ``"18f"`` frames) are read
by `parse_duration` and `parse_frame`; `gaussian_average` is Kwon and Lee's
trajectory average (an FFT convolution with point-reflected ends);
`spread_max` and `step_gain` ease a per-frame need over a radius (the speed
limit, the correction, the contacts); `smootherstep` and `end_ramp` fade in
and out; `soft_limit` eases a length into its most (the springs' lag, a
planted foot's reach). Every stage that works along time uses these.
"""

from __future__ import annotations

import re

import numpy as np

from .errors import ConfigError
from .native import frame_halves, on_both_cores

__all__ = ["parse_duration", "check_duration", "parse_frame", "gaussian_average", "step_gain", "spread_max",
           "smootherstep", "end_ramp", "soft_limit"]

_DURATION = re.compile(r"^\s*([0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)\s*(s|ms|f|frames?)?\s*$")


def parse_duration(value: str | float | int, frame_time: float, *, what: str = "sigma") -> float:
    """A duration in frames from ``0.2``/``"0.2s"`` (seconds), ``"200ms"`` or ``"18f"`` (frames)."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        try:
            seconds = float(value)  # (an integer of 400 digits is past any float)
        except OverflowError:
            seconds = float("inf")
        if not np.isfinite(seconds) or seconds < 0 or not np.isfinite(seconds / frame_time):
            raise ConfigError(f"{what} must be a duration >= 0, got {value!r}")
        return seconds / frame_time
    match = _DURATION.match(str(value))
    if not match:
        raise ConfigError(f"{what} must look like 0.2s, 200ms or 18f, got {value!r}")
    number, unit = float(match.group(1)), (match.group(2) or "s")
    frames = number / frame_time if unit == "s" else number / 1000.0 / frame_time if unit == "ms" else number
    if not (np.isfinite(number) and np.isfinite(frames)):  # (1e308s at 120 fps is past any float)
        raise ConfigError(f"{what} must be a finite duration, got {value!r}")
    return frames


def check_duration(value: str | float | int, what: str, most_seconds: float = 10.0) -> None:
    """Refuse a duration setting longer than ``most_seconds`` (in frames: 1,000 a second, the
    highest frame rate read), before any clip says what a frame is.

    >>> check_duration("3600s", "correct.smooth")
    Traceback (most recent call last):
    mocap_exaggerate.core.errors.ConfigError: correct.smooth must be at most 10 s (or 10000 frames), got '3600s'
    """
    amount = parse_duration(value, 1.0, what=what)  # seconds, or frames for "18f"
    match = _DURATION.match(str(value)) if isinstance(value, str) else None
    in_frames = match is not None and (match.group(2) or "s").startswith("f")
    if amount > most_seconds * (1000.0 if in_frames else 1.0):
        raise ConfigError(f"{what} must be at most {most_seconds:g} s (or {most_seconds * 1000:g} frames), "
                          f"got {value!r}")


def parse_frame(value: str | float | int, frame_time: float, *, what: str) -> int:
    """A frame index from a frame number (``120``, ``"120"``) or a time (``"1.2s"``, ``"800ms"``, ``"96f"``).

    >>> parse_frame("1.5s", 1 / 30, what="start"), parse_frame(12, 1 / 30, what="start")
    (45, 12)
    """
    if isinstance(value, bool):
        raise ConfigError(f"{what} must be a frame number or a time, got {value!r}")
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, float) and value.is_integer():
        return int(value)
    text = str(value).strip()
    if re.fullmatch(r"\d+", text):
        if len(text) > 18:  # (past any clip; Python will not read an integer over 4,300 digits)
            raise ConfigError(f"{what} {text[:20]}... ({len(text)} digits) is past the end of any clip")
        return int(text)
    if not re.search(r"(s|ms|f|frames?)$", text):
        raise ConfigError(f"{what} must be a frame number or a time such as 1.2s, got {value!r}")
    frames = parse_duration(text, frame_time, what=what)
    if abs(frames) > 1e18:  # (past any clip: and a float past 2**63 is no frame number)
        raise ConfigError(f"{what} {text[:20]}{'...' if len(text) > 20 else ''} is past the end of any clip")
    return int(round(frames))



def gaussian_average(world_pos: np.ndarray, sigma: float, *, axis: int = 0, ends: str = "reflect",
                     truncate: float = 4.0) -> np.ndarray:
    """Gaussian average along time with point-reflected ends.

    The trajectory is extended past each end by reflecting it through the end
    point (``2 j(0) - j(-t)``), so a joint moving at constant velocity has
    itself as its average: clip ends are neither pulled toward zero nor
    toward the interior, and a walking root does not jump at the first frame.

    world_pos : (F, ...) float64, time along ``axis``
    sigma : standard deviation in frames; 0 returns a copy
    ends : ``reflect`` (point reflection, as above) or ``nearest`` (the end value held,
        as ``scipy.ndimage.gaussian_filter1d(mode="nearest")``: for values that are not
        positions, such as a twist angle fading to 0)
    truncate : the kernel reaches this many sigmas either side (scipy's ``truncate``)
    """
    world_pos = np.asarray(world_pos, dtype=np.float64)
    if sigma <= 0 or world_pos.shape[axis] < 2:
        return world_pos.copy()
    radius = int(truncate * sigma + 0.5)
    moved = np.moveaxis(world_pos, axis, 0)
    edges = [(radius, radius)] + [(0, 0)] * (moved.ndim - 1)
    padded = np.pad(moved, edges, mode="edge") if ends == "nearest" else np.pad(moved, edges, mode="reflect",
                                                                                 reflect_type="odd")
    return np.moveaxis(_convolve_gaussian(padded, sigma, radius), 0, axis)


def _convolve_gaussian(padded: np.ndarray, sigma: float, radius: int) -> np.ndarray:
    """The Gaussian-weighted average of every ``2 radius + 1`` window along axis 0 ("valid" part).

    The same truncated, normalised kernel as ``scipy.ndimage.gaussian_filter1d``
    (``truncate=4``), applied by FFT: the cost does not grow with sigma, and
    NumPy's FFT spares the command the 0.25 s import of ``scipy.ndimage``
    (the tests check the two agree).
    """
    taps = np.arange(-radius, radius + 1, dtype=np.float64)
    kernel = np.exp(-0.5 * (taps / sigma) ** 2)
    kernel /= kernel.sum()
    length = padded.shape[0]
    frames = length - 2 * radius
    size = 1 << int(np.ceil(np.log2(length + 2 * radius)))
    # Each series contiguous (frames last): NumPy's FFT along a strided axis copies every column in and
    # out on its own, twice the time of the transform itself (180 -> 92 ms on 10,000 x 285; the same bits).
    series = np.ascontiguousarray(padded.reshape(length, -1).T)
    response = np.fft.rfft(kernel, size)
    smooth = np.empty((len(series), frames))

    def convolve(part: slice) -> None:  # (each series on its own: the same bits in halves, on two cores)
        spectrum = np.fft.rfft(series[part], size, axis=-1)
        spectrum *= response
        smooth[part] = np.fft.irfft(spectrum, size, axis=-1)[:, 2 * radius : 2 * radius + frames]

    on_both_cores(convolve, frame_halves(len(series), per_item=length // 64))  # (a series: 1/64 of its frames' work)
    return np.ascontiguousarray(smooth.T).reshape((frames,) + padded.shape[1:])


def step_gain(share: np.ndarray, radius: int) -> np.ndarray:
    """Gains per frame ``(F, ...)`` from the share ``(F-1, ...)`` each one-frame step may keep.

    A step joins two frames: both take its share (the smaller of two), then
    the shortfall is spread over ``radius`` frames by `spread_max`, so a gain
    eases in and out and is never above what any frame needs.
    """
    need = np.ones((share.shape[0] + 1,) + share.shape[1:])
    need[:-1] = np.minimum(need[:-1], share)
    need[1:] = np.minimum(need[1:], share)
    return 1.0 - spread_max(1.0 - need, radius)


def spread_max(values: np.ndarray, radius: int) -> np.ndarray:
    """A running maximum over ``radius`` frames either side, then a Gaussian (sigma = radius / 3) truncated there.

    Along axis 0. Never below ``values`` (every tap of the Gaussian sees a
    maximum over a window that contains the frame), 0 more than ``2 radius``
    frames from any nonzero value, and as smooth as the Gaussian.

    >>> spread_max(np.array([0, 0, 0, 0, 1.0, 0, 0, 0, 0]), 1).round(3).tolist()
    [0.0, 0.0, 0.011, 0.989, 1.0, 0.989, 0.011, 0.0, 0.0]
    """
    values = np.asarray(values, dtype=np.float64)
    if radius < 1 or len(values) < 2:
        return values.copy()
    edges = [(radius, radius)] + [(0, 0)] * (values.ndim - 1)
    peaks = _running_max(np.pad(values, edges, mode="edge"), 2 * radius + 1)
    padded = np.pad(peaks, edges, mode="edge")
    spread = _convolve_gaussian(padded, radius / 3.0, radius)
    # The FFT leaves crumbs of 1e-30 where every tap is 0: those frames are exactly 0.
    spread[_running_max(np.abs(padded), 2 * radius + 1) == 0] = 0.0
    return np.maximum(spread, values)  # guard the last bit of rounding


def _running_max(values: np.ndarray, width: int) -> np.ndarray:
    """The maximum of every ``width`` consecutive rows ("valid" part), by doubling: log2(width) passes."""
    out, span = values, 1
    while span * 2 <= width:  # out[i] = max of rows i .. i + 2 span - 1
        out = np.maximum(out[:-span], out[span:])
        span *= 2
    if span < width:  # the rest: two overlapping windows of `span` rows cover `width`
        out = np.maximum(out[: len(values) - width + 1], out[width - span : width - span + len(values) - width + 1])
    return out


def smootherstep(x: np.ndarray) -> np.ndarray:
    """``6x^5 - 15x^4 + 10x^3`` on [0, 1], clamped: 0 to 1 with zero first and second derivatives at both ends."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * x * (x * (6.0 * x - 15.0) + 10.0)


def soft_limit(value: np.ndarray, knee: np.ndarray, top: np.ndarray) -> np.ndarray:
    """``value`` unchanged up to ``knee``, above it easing into ``top`` (never reached): ``knee + (top - knee)
    tanh((value - knee) / (top - knee))``, continuous with its first derivative; where ``top <= knee``,
    a hard ``min(value, top)``. All arrays broadcast together.

    >>> np.round(soft_limit(np.array([1.0, 1.5, 2.0, 9.0]), 1.5, 2.0), 3).tolist()
    [1.0, 1.5, 1.881, 2.0]
    """
    value, knee, top = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (value, knee, top)))
    out = np.array(value, order="C")  # (most values are under the knee: the tanh is taken only of those over it)
    over = np.flatnonzero(~(value - knee <= 0))  # (a NaN difference too, as the formula takes it)
    if len(over):
        value, knee, top = value.ravel()[over], knee.ravel()[over], top.ravel()[over]
        room = top - knee
        eased = knee + room * np.tanh(np.divide(value - knee, room, out=np.zeros_like(room), where=room > 0))
        out.ravel()[over] = np.where(room > 0, eased, np.minimum(value, top))
    return out


def end_ramp(frames: int, length: float) -> np.ndarray:
    """(frames,) weights rising from 0 at the first frame to 1 over ``length`` frames and falling back at the end.

    On a clip shorter than two ramps the two halves meet below 1.

    >>> np.round(end_ramp(7, 3.0), 3).tolist()
    [0.0, 0.21, 0.79, 1.0, 0.79, 0.21, 0.0]
    """
    t = np.arange(frames, dtype=np.float64)
    return smootherstep(np.minimum(t, frames - 1 - t) / max(length, 1e-12))
