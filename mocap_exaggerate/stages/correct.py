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

Because of that, the iteration count each frame needs is known from its
starting error, and `correct` applies those iterations in one step: the
same result as iterating (a frame-by-frame loop oracle in the tests checks
it), at the cost of a single pass over the joints.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError, check_flag, check_number

__all__ = ["CorrectConfig", "CorrectReport", "correct", "stretch_error"]

#: A threshold of 0 is reached only in the limit for delta < 1; stop this close to it.
_TOLERANCE = 1e-9


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
        check_flag("correct.enabled", self.enabled)
        check_number("correct.threshold", self.threshold, 0, 10)
        check_number("correct.delta", self.delta, 0, 1, low_open=True)
        check_number("correct.max_stretch", self.max_stretch, 1, 10)
        if not isinstance(self.max_iter, int) or isinstance(self.max_iter, bool) or not 1 <= self.max_iter <= 100000:
            raise ConfigError(f"correct.max_iter must be a whole number from 1 to 100000, got {self.max_iter!r}")


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
    out = world_pos.copy()
    if float(np.sum(rest_lengths[1:])) <= 0:
        return out, CorrectReport(0, 0, 0.0, 0.0, 0)  # no link to over-stretch
    total = _total_length(rest_lengths)
    num_joints = len(parents)
    x, vec, length = _excess(world_pos, parents, rest_lengths, max_stretch)
    errors = x.sum(axis=1) / total
    active = np.flatnonzero(errors > threshold)
    if not len(active):
        return out, CorrectReport(0, 0, float(errors.max(initial=0.0)), float(errors.max(initial=0.0)), 0)

    # Iteration k leaves (1 - delta)^k of every excess, so the number of
    # iterations a frame needs is known in advance: apply them at once.
    start = errors[active]
    target = max(threshold, _TOLERANCE)
    if delta >= 1.0:
        needed = np.ones(len(active), dtype=np.int64)
    else:
        ratio = np.log(target / start) / np.log1p(-delta)
        # A tiny delta needs more iterations than max_iter (or int64) can count: cap before converting.
        needed = np.clip(np.ceil(ratio - 1e-9), 1, max_iter + 1).astype(np.int64)
        # Guard the rounding of the logs, and land clearly under the target, not on it to the last bit.
        needed += (1.0 - delta) ** needed * start > target * (1.0 - 1e-6)
    steps = np.minimum(needed, max_iter)
    keep = (1.0 - delta) ** steps  # share of each excess left
    xa, vec_a, len_a = x[active], vec[active], length[active]
    new_len = len_a - (1.0 - keep)[:, None] * xa
    scale = np.divide(new_len, len_a, out=np.ones_like(len_a), where=len_a > 0)
    links = vec_a * scale[..., None]
    pos = out[active]
    for j in range(1, num_joints):
        pos[:, j] = pos[:, parents[j]] + links[:, j - 1]
    out[active] = pos

    iterations = int(steps.max())
    unconverged = int(np.sum(needed > max_iter))
    max_before = float(errors.max())
    max_after = float(np.max(np.where(np.isin(np.arange(len(errors)), active), 0.0, errors), initial=0.0))
    max_after = max(max_after, float((keep * start).max()))
    return out, CorrectReport(len(active), iterations, max_before, max_after, unconverged)
