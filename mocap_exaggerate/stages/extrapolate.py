"""Trajectory extrapolation (Kwon & Lee 2008, section 4.1, eq. 1-3).

Each joint's world trajectory ``j_k(t)`` is pushed away from its Gaussian
average ``a_k = j_k * g_sigma``: ``e_k = omega * j_k + (1 - omega) * a_k``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError, check_flag, check_number

__all__ = ["ExtrapolateConfig", "extrapolate", "parse_duration", "parse_frame", "gaussian_average"]

_DURATION = re.compile(r"^\s*([0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)\s*(s|ms|f|frames?)?\s*$")


def parse_duration(value: str | float | int, frame_time: float, *, what: str = "sigma") -> float:
    """A duration in frames from ``0.2``/``"0.2s"`` (seconds), ``"200ms"`` or ``"18f"`` (frames)."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        seconds = float(value)
        if not np.isfinite(seconds) or seconds < 0:
            raise ConfigError(f"{what} must be a duration >= 0, got {value!r}")
        return seconds / frame_time
    match = _DURATION.match(str(value))
    if not match:
        raise ConfigError(f"{what} must look like 0.2s, 200ms or 18f, got {value!r}")
    number, unit = float(match.group(1)), (match.group(2) or "s")
    if not np.isfinite(number):
        raise ConfigError(f"{what} must be a finite duration, got {value!r}")
    if unit == "s":
        return number / frame_time
    if unit == "ms":
        return number / 1000.0 / frame_time
    return number


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
        return int(text)
    if not re.search(r"(s|ms|f|frames?)$", text):
        raise ConfigError(f"{what} must be a frame number or a time such as 1.2s, got {value!r}")
    return int(round(parse_duration(text, frame_time, what=what)))


#: Widest Gaussian accepted, whatever the clip (a minute; 100,000 frames).
MAX_SIGMA_SECONDS = 60.0
MAX_SIGMA_FRAMES = 100_000


@dataclass(frozen=True, kw_only=True)
class ExtrapolateConfig:
    """Settings of the extrapolation block.

    sigma : width of the Gaussian average: seconds (``0.2``, ``"0.2s"``,
        ``"200ms"``) or frames (``"18f"``). Wider means slower swings count as
        "deviation" and get exaggerated.
    omega : how far past the captured motion to go; 1 is the identity, 5 the
        paper's usual value, values below 1 calm the motion down.
    weights : ``(pattern, weight)`` pairs; a pattern is a joint name, a shell
        pattern (``Left*``) or a limb name (``left_arm``). A joint's effective
        omega is ``1 + weight * (omega - 1)``; weight 0 keeps it as captured.
        Later pairs win.
    """

    enabled: bool = True
    sigma: str | float = "0.2s"
    omega: float = 5.0
    weights: tuple[tuple[str, float], ...] = field(default=())

    def __post_init__(self) -> None:
        check_flag("extrapolate.enabled", self.enabled)
        seconds = parse_duration(self.sigma, 1.0, what="extrapolate.sigma")
        frames = parse_duration(self.sigma, np.inf, what="extrapolate.sigma")  # nonzero only for "18f"
        if seconds > MAX_SIGMA_SECONDS if frames == 0 else frames > MAX_SIGMA_FRAMES:
            raise ConfigError(f"extrapolate.sigma must be at most {MAX_SIGMA_SECONDS:g} s or {MAX_SIGMA_FRAMES} "
                              f"frames, got {self.sigma!r}")
        check_number("extrapolate.omega", self.omega, 0, 50)
        for pattern, weight in self.weights:
            check_number(f"extrapolate.weights[{pattern!r}]", weight, 0, 10)

    def sigma_frames(self, frame_time: float, frames: int | None = None) -> float:
        """Sigma in frames; with ``frames`` (the clip's length) also checked against it.

        A Gaussian much wider than the clip averages nothing more, only costs
        time and memory: sigma may be at most twice the clip (or 1000 frames).
        """
        sigma = parse_duration(self.sigma, frame_time, what="extrapolate.sigma")
        if frames is not None and sigma > max(2 * frames, 1000):
            raise ConfigError(
                f"extrapolate.sigma {self.sigma!r} is {sigma:.4g} frames; at most twice the clip's length "
                f"({frames} frames) or 1000 frames"
            )
        return sigma


def gaussian_average(world_pos: np.ndarray, sigma: float, *, axis: int = 0) -> np.ndarray:
    """Gaussian average along time with point-reflected ends.

    The trajectory is extended past each end by reflecting it through the end
    point (``2 j(0) - j(-t)``), so a joint moving at constant velocity has
    itself as its average: clip ends are neither pulled toward zero nor
    toward the interior, and a walking root does not jump at the first frame.

    world_pos : (F, ...) float64, time along ``axis``
    sigma : standard deviation in frames; 0 returns a copy
    """
    world_pos = np.asarray(world_pos, dtype=np.float64)
    if sigma <= 0 or world_pos.shape[axis] < 2:
        return world_pos.copy()
    radius = int(4.0 * sigma + 0.5)
    moved = np.moveaxis(world_pos, axis, 0)
    padded = np.pad(moved, [(radius, radius)] + [(0, 0)] * (moved.ndim - 1), mode="reflect", reflect_type="odd")
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
    flat = padded.reshape(length, -1)
    spectrum = np.fft.rfft(flat, size, axis=0) * np.fft.rfft(kernel, size)[:, None]
    smooth = np.fft.irfft(spectrum, size, axis=0)[2 * radius : 2 * radius + frames]
    return smooth.reshape((frames,) + padded.shape[1:])


def extrapolate(
    world_pos: np.ndarray,
    *,
    sigma: float,
    omega: float,
    weights: np.ndarray | None = None,
    axis: int = 0,
) -> np.ndarray:
    """Exaggerate trajectories away from their Gaussian average.

    Parameters
    ----------
    world_pos : (F, J, 3) float64 world positions, time along ``axis``
    sigma : Gaussian standard deviation in frames
    omega : extrapolation factor; 1 returns the input unchanged
    weights : (J,) float64 or None; per-joint scale of ``omega - 1``

    Returns
    -------
    (F, J, 3) float64 ``j + w (omega - 1) (j - a)``, i.e. eq. (1) with a
    per-joint omega.

    Examples
    --------
    >>> t = np.linspace(0, 2 * np.pi, 101)[:, None, None]
    >>> out = extrapolate(np.sin(t) * np.ones((1, 1, 3)), sigma=3.0, omega=1.0)
    >>> bool(np.allclose(out, np.sin(t)))
    True
    """
    world_pos = np.asarray(world_pos, dtype=np.float64)
    if world_pos.ndim != 3 or world_pos.shape[-1] != 3:
        raise ValueError(f"positions must be (F, J, 3), got {world_pos.shape}")
    gain = np.full(world_pos.shape[1], omega - 1.0)
    if weights is not None:
        weights = np.asarray(weights, dtype=np.float64)
        if weights.shape != gain.shape:
            raise ValueError(f"weights must be ({world_pos.shape[1]},), got {weights.shape}")
        gain = gain * weights
    if not np.any(gain):
        return world_pos.copy()
    average = gaussian_average(world_pos, sigma, axis=axis)
    return world_pos + gain[:, None] * (world_pos - average)
