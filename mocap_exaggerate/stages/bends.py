"""Knees and elbows bent the way the capture bends them: the one rule two stages keep.

Exaggeration can carry a nearly straight knee across the hip-ankle line
(the link correction keeps it from there, `keep_bends` on the original joints);
the springs' lag can carry it back (`keep_bends_on_rubber`, the same rule
with the sub-joints either side moving in proportion).
"""

from __future__ import annotations

import numpy as np

from ..core.kinematics import consecutive
from ..core.native import by_frame_halves
from ..core.rotations import sum_last, vector_norm
from ..core.timing import smootherstep

__all__ = ["keep_bends", "keep_bends_on_rubber"]



def keep_bends(positions: np.ndarray, captured: np.ndarray, hinges, *, margin: float = 0.02) -> np.ndarray:
    """Knees and elbows bent the way the capture bends them, never backwards.

    positions, captured : (F, J, 3) exaggerated and captured world positions
    hinges : (base, middle, end) joint triples (hip, knee, ankle; shoulder, elbow, wrist), or
        (hip, knee, ankle, toe): the toes tell which way a knee bends when the leg is straight

    Exaggerating a nearly straight leg can carry the knee across the hip-ankle
    line: a knee bending backwards on a planted leg. The captured knee's side
    of that line, seen across the exaggerated line, is the side it must stay
    on: its offset along that side is kept at least about ``margin`` of the
    limb's length (a C1 soft clamp, unchanged above twice that), with the
    correction faded out where the capture itself is nearly straight and
    says little about its side. Only the middle joint moves; the length
    correction that follows mends the two links. Each frame on its own: a long
    clip's two halves are made on two cores.
    """
    positions = np.asarray(positions, dtype=np.float64)
    return by_frame_halves(lambda part: _keep_bends(positions[part], captured[part], hinges, margin), len(positions))


def _keep_bends(positions: np.ndarray, captured: np.ndarray, hinges, margin: float) -> np.ndarray:
    out = np.array(positions, dtype=np.float64)
    for hinge in hinges:
        base, middle, end = hinge[:3]
        line = out[:, end] - out[:, base]
        reach = vector_norm(line, keepdims=True)
        along = line / np.maximum(reach, 1e-300)
        bent = captured[:, middle] - captured[:, base]
        cap_line = captured[:, end] - captured[:, base]
        cap_line = cap_line / np.maximum(vector_norm(cap_line, keepdims=True), 1e-300)
        side = bent - sum_last(bent * cap_line, keepdims=True) * cap_line
        length = vector_norm(captured[:, middle] - captured[:, base]) + \
            vector_norm(captured[:, end] - captured[:, middle])
        if len(hinge) > 3:  # a foot: knees bend toward the toes, which says so even on a straight leg
            toes = captured[:, hinge[3]] - captured[:, end]
            toes = toes - sum_last(toes * cap_line, keepdims=True) * cap_line
            toes = toes / np.maximum(vector_norm(toes, keepdims=True), 1e-300)
            side = side + 0.1 * length[:, None] * toes
        side = side - sum_last(side * along, keepdims=True) * along
        size = vector_norm(side)
        side = side / np.maximum(size, 1e-300)[:, None]
        offset = out[:, middle] - out[:, base]
        offset = offset - sum_last(offset * along, keepdims=True) * along
        s = sum_last(offset * side)
        floor = margin * length
        # A soft clamp: unchanged from 2 floor up, never below 0 (behind the line).
        low = s < 2.0 * floor
        lifted = s.copy()
        knee = 2.0 * floor[low]  # s -> 2f - 2f (1 - exp((s - 2f) / 2f)): slope 1 at 2f, 0 as s -> -inf
        lifted[low] = knee - knee * (1.0 - np.exp((s[low] - knee) / np.maximum(knee, 1e-300)))
        trust = smootherstep(size / np.maximum(0.05 * length, 1e-300))
        out[:, middle] += ((lifted - s) * trust)[:, None] * side
    return out


def keep_bends_on_rubber(sub_positions: np.ndarray, hierarchy, captured: np.ndarray, hinges, *,
                         in_place: bool = False) -> np.ndarray:
    """`keep_bends` on the original joints of rubber positions ``(F, J', 3)``; a new array (``in_place``:
    ``sub_positions`` itself, a float64 array or a view of one).

    A middle joint (knee, elbow) that moves takes the sub-joints on the links either
    side with it in proportion to their place along them, so the limb bends at the
    joint instead of kinking next to it. (`keep_bends` shares a long clip's frames between two
    cores; whether a hinge moves at all is told from the whole clip, as the sub-joints' moves are
    added to every frame of a hinge that moves anywhere.)
    """
    out = sub_positions if in_place else np.array(sub_positions, dtype=np.float64)
    joints = np.take(out, hierarchy.original, axis=1)
    bent = keep_bends(joints, captured, hinges)
    for hinge in hinges:
        _, middle, end = hinge[:3]
        shift = bent[:, middle] - joints[:, middle]
        if not shift.any():
            continue
        upper = np.flatnonzero(hierarchy.link_child == middle)  # the middle joint and the sub-joints above it
        lower = np.flatnonzero((hierarchy.link_child == end) & ~hierarchy.is_original)
        out[:, consecutive(upper, out.shape[1])] += hierarchy.fraction[upper][None, :, None] * shift[:, None]
        out[:, consecutive(lower, out.shape[1])] += (1.0 - hierarchy.fraction[lower])[None, :, None] * shift[:, None]
    return out
