"""Fast joint-hierarchy correction (Kwon & Lee 2008, section 4.2, their Figure 4).

Per frame, every link (p, c) with rest length ``l_c`` and current length ``d``
has excess ``x = max(0, d - max_stretch * l_c)``; the frame error is
``E = sum(x) / sum(l)``. While ``E > threshold``, each link is shortened by
``delta * x`` by moving its child toward its parent, all links at once, the
root fixed, only frames still above threshold iterated.

The child carries its subtree with it, as a joint in a hierarchy does. So a
link's correction changes that link's length and nothing else: every excess
shrinks by exactly ``(1 - delta)`` per iteration, ``E_k = (1 - delta)^k E_0``,
which halts for any delta in (0, 1], and link directions (the exaggerated
pose) are kept while lengths are pulled back.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError

__all__ = ["CorrectConfig", "CorrectReport", "correct", "stretch_error"]


@dataclass(frozen=True, kw_only=True)
class CorrectConfig:
    """Settings of the correction block.

    threshold : the fraction of the skeleton's total link length that may
        remain as stretch in any frame (0.05: at most 5 % summed excess).
    delta : share of each link's excess removed per iteration, in (0, 1].
    max_stretch : stretch up to this factor of a link's rest length is not
        counted as excess (1 counts every stretch).
    max_iter : safety bound on iterations.
    """

    enabled: bool = True
    threshold: float = 0.05
    delta: float = 0.5
    max_stretch: float = 1.0
    max_iter: int = 500

    def __post_init__(self) -> None:
        if not _number(self.threshold) or not 0 <= self.threshold <= 10:
            raise ConfigError(f"correct.threshold must be between 0 and 10, got {self.threshold!r}")
        if not _number(self.delta) or not 0 < self.delta <= 1:
            raise ConfigError(f"correct.delta must be in (0, 1], got {self.delta!r}")
        if not _number(self.max_stretch) or not 1 <= self.max_stretch <= 10:
            raise ConfigError(f"correct.max_stretch must be between 1 and 10, got {self.max_stretch!r}")
        if not isinstance(self.max_iter, int) or isinstance(self.max_iter, bool) or not 1 <= self.max_iter <= 100000:
            raise ConfigError(f"correct.max_iter must be a whole number from 1 to 100000, got {self.max_iter!r}")


def _number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and bool(np.isfinite(value))


@dataclass(frozen=True)
class CorrectReport:
    """What the correction did: frames it touched, iterations, error before and after (max over frames)."""

    frames_corrected: int
    iterations: int
    max_error_before: float
    max_error_after: float
    unconverged_frames: int


def stretch_error(
    world_pos: np.ndarray, parents: np.ndarray, rest_lengths: np.ndarray, *, max_stretch: float = 1.0
) -> np.ndarray:
    """Per-frame error ``E = sum(max(0, d - max_stretch * l)) / sum(l)``, shape ``(F,)``."""
    x, _, _ = _excess(world_pos, parents, rest_lengths, max_stretch)
    return x.sum(axis=1) / _total_length(rest_lengths)


def _total_length(rest_lengths: np.ndarray) -> float:
    total = float(np.sum(rest_lengths[1:]))
    if total <= 0:
        raise ValueError("the skeleton has no link of non-zero length")
    return total


def _excess(world_pos, parents, rest_lengths, max_stretch):
    vec = world_pos[:, 1:] - world_pos[:, parents[1:]]
    length = np.linalg.norm(vec, axis=-1)
    x = np.maximum(0.0, length - max_stretch * rest_lengths[1:])
    return x, vec, length


def correct(
    world_pos: np.ndarray,
    parents: np.ndarray,
    rest_lengths: np.ndarray,
    *,
    threshold: float,
    delta: float = 0.5,
    max_stretch: float = 1.0,
    max_iter: int = 500,
) -> tuple[np.ndarray, CorrectReport]:
    """Pull over-stretched links back until each frame's error is at most ``threshold``.

    Parameters
    ----------
    world_pos : (F, J, 3) float64 world positions (e.g. after extrapolation)
    parents : (J,) int, -1 for the root, parents before children
    rest_lengths : (J,) float64 rest length of the link ending at each joint
    threshold, delta, max_stretch, max_iter : see `CorrectConfig`

    Returns
    -------
    positions : (F, J, 3) float64, a new array; frames at or under threshold
        are copied unchanged, and the root never moves
    report : CorrectReport
    """
    world_pos = np.asarray(world_pos, dtype=np.float64)
    parents = np.asarray(parents)
    rest_lengths = np.asarray(rest_lengths, dtype=np.float64)
    if world_pos.ndim != 3 or world_pos.shape[1:] != (len(parents), 3):
        raise ValueError(f"positions must be (F, {len(parents)}, 3), got {world_pos.shape}")
    if not 0 < delta <= 1:
        raise ValueError(f"delta must be in (0, 1], got {delta}")
    total = _total_length(rest_lengths)
    out = world_pos.copy()
    num_joints = len(parents)

    errors = _excess(out, parents, rest_lengths, max_stretch)[0].sum(axis=1) / total
    max_before = float(errors.max(initial=0.0))
    active = np.flatnonzero(errors > threshold)
    touched = len(active)
    iterations = 0
    while len(active) and iterations < max_iter:
        pos = out[active]
        x, vec, length = _excess(pos, parents, rest_lengths, max_stretch)
        still = x.sum(axis=1) / total > threshold
        if not still.all():
            active, pos, x, vec, length = active[still], pos[still], x[still], vec[still], length[still]
            if not len(active):
                break
        # Step of each link's child toward its parent, then carried down the tree.
        scale = np.divide(delta * x, length, out=np.zeros_like(x), where=length > 0)
        step = -scale[..., None] * vec
        shift = np.zeros_like(pos)
        for j in range(1, num_joints):
            shift[:, j] = shift[:, parents[j]] + step[:, j - 1]
        out[active] = pos + shift
        iterations += 1

    final = _excess(out[active], parents, rest_lengths, max_stretch)[0].sum(axis=1) / total if len(active) else np.zeros(0)
    unconverged = int(np.sum(final > threshold))
    max_after = float((_excess(out, parents, rest_lengths, max_stretch)[0].sum(axis=1) / total).max(initial=0.0))
    report = CorrectReport(touched, iterations, max_before, max_after, unconverged)
    return out, report
