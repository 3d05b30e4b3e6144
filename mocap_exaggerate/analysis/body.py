"""The body as capsules: where a hand, forearm, foot or shin passes into the torso, pelvis, head or a thigh.

Kwon and Lee name self-penetration as a limitation of their method: exaggerating each joint's
trajectory on its own can put a hand through the chest or fold a shin into its thigh. Without
a mesh, the body is a few capsules around the skeleton's own links, sized from the skeleton
(``shoulders``: the distance between the upper arms' joints; ``hips``: between the thighs'):

- the torso: each link of the spine, radius 0.3 shoulders; the pelvis: hip joint to hip
  joint, radius 0.45 hips; the head: the neck's last link carried on past the head joint by
  its own length, radius 0.3 shoulders; each thigh: 0.35 hips; each upper arm: 0.2 shoulders;
- the parts that move into them: each forearm (elbow to wrist, and the wrist as the hand)
  and each shin (knee to ankle, and the ankle as the foot).

A part is *inside* a capsule when its axis comes within the capsule's radius of the
capsule's axis: a limb grazing the body's surface is not counted, one passing into it is.
Each part is tested against the torso, the pelvis and the head, a leg's against the other
leg's thigh, and each end (wrist, ankle) against its own limb's upper bone (a shin folded
into its thigh). `inside_body` counts frames; `mocap_exaggerate.stages.collide` pushes the
parts out of what the capture's do not enter.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..core.native import by_frame_halves
from ..core.rotations import sum_last, vector_norm

__all__ = ["Capsule", "Part", "body_capsules", "limb_parts", "segment_closest", "CapturedSides", "penetrations",
           "inside_body"]


class Capsule(NamedTuple):
    """A capsule of the body: joints ``a`` and ``b`` at its axis's ends (``b`` carried past its joint by
    ``extend`` of the a-b length), ``radius`` in the skeleton's units."""

    name: str
    a: int
    b: int
    radius: float
    extend: float = 0.0

    def ends(self, positions: np.ndarray, rows: np.ndarray | slice = slice(None)) -> tuple[np.ndarray, np.ndarray]:
        """(F, 3) the axis's two ends in ``positions (F, J, 3)`` (on the frames ``rows``)."""
        a, b = positions[rows, self.a], positions[rows, self.b]
        return a, b + self.extend * (b - a)


class Part(NamedTuple):
    """A moving part: the segment (a, b) of ``limb`` (a == b for a point: the wrist or ankle, which keeps out
    only of its own limb's upper bone), and ``avoid``, the names of the capsules it must stay out of."""

    name: str
    limb: str
    a: int
    b: int
    avoid: tuple[str, ...]


def _width(positions: np.ndarray, limbs: dict, kind: str) -> float:
    left, right = limbs.get(f"left_{kind}"), limbs.get(f"right_{kind}")
    if left is None or right is None:
        return 0.0
    return float(np.median(vector_norm(positions[:, left.base] - positions[:, right.base])))


def body_capsules(limbs: dict, positions: np.ndarray) -> list[Capsule]:
    """The torso, pelvis, head and thigh capsules, sized from the shoulders and hips in ``positions (F, J, 3)``
    (the capture's); empty for a skeleton without both arms or both legs."""
    shoulders, hips = _width(positions, limbs, "arm"), _width(positions, limbs, "leg")
    if shoulders <= 0 or hips <= 0:
        return []
    out = []
    spine = limbs.get("spine")
    if spine is not None:
        out += [Capsule("torso", a, b, 0.3 * shoulders) for a, b in zip(spine.joints[:-1], spine.joints[1:])]
    out.append(Capsule("pelvis", limbs["left_leg"].base, limbs["right_leg"].base, 0.45 * hips))
    neck = limbs.get("neck")
    if neck is not None and len(neck.joints) >= 2:
        out.append(Capsule("head", neck.joints[-2], neck.joints[-1], 0.3 * shoulders, extend=1.0))
    for side in ("left", "right"):
        leg = limbs[f"{side}_leg"]
        out.append(Capsule(f"{side}_thigh", leg.joints[0], leg.joints[1], 0.35 * hips))
    for side in ("left", "right"):
        arm = limbs[f"{side}_arm"]
        out.append(Capsule(f"{side}_upper_arm", arm.joints[0], arm.joints[1], 0.2 * shoulders))
    return out


def limb_parts(limbs: dict) -> list[Part]:
    """The forearms, hands, shins and feet, and the capsules each must stay out of."""
    parts = []
    for side, other in (("left", "right"), ("right", "left")):
        arm, leg = limbs.get(f"{side}_arm"), limbs.get(f"{side}_leg")
        trunk = ("torso", "pelvis", "head")
        if arm is not None and len(arm.joints) == 3:
            parts.append(Part(f"{side}_forearm", f"{side}_arm", arm.joints[1], arm.joints[2], trunk))
            parts.append(Part(f"{side}_hand", f"{side}_arm", arm.joints[2], arm.joints[2], (f"{side}_upper_arm",)))
        if leg is not None and len(leg.joints) == 3:
            parts.append(Part(f"{side}_shin", f"{side}_leg", leg.joints[1], leg.joints[2], trunk + (f"{other}_thigh",)))
            parts.append(Part(f"{side}_foot", f"{side}_leg", leg.joints[2], leg.joints[2], (f"{side}_thigh",)))
    return parts


def segment_closest(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray):
    """Closest points of segments p0-p1 and q0-q1, all ``(F, 3)``: returns (s, t, gap) with the points
    ``p0 + s (p1 - p0)``, ``q0 + t (q1 - q0)`` and ``gap (F, 3)`` from the second to the first
    (Ericson, Real-Time Collision Detection, 5.1.9; a segment may be a point)."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a = np.sum(d1 * d1, -1)
    e = np.sum(d2 * d2, -1)
    f = np.sum(d2 * r, -1)
    c = np.sum(d1 * r, -1)
    b = np.sum(d1 * d2, -1)
    tiny = 1e-12
    denom = a * e - b * b
    s = np.where(denom > tiny, np.clip(np.divide(b * f - c * e, denom, out=np.zeros_like(denom), where=denom > tiny),
                                       0.0, 1.0), 0.0)
    t = np.divide(b * s + f, e, out=np.zeros_like(e), where=e > tiny)
    # t outside [0, 1]: clamp it and recompute s for it.
    low, high = t < 0, t > 1
    t = np.clip(t, 0.0, 1.0)
    s = np.where(low, np.clip(np.divide(-c, a, out=np.zeros_like(a), where=a > tiny), 0.0, 1.0), s)
    s = np.where(high, np.clip(np.divide(b - c, a, out=np.zeros_like(a), where=a > tiny), 0.0, 1.0), s)
    s = np.where(a > tiny, s, 0.0)
    gap = (p0 + s[:, None] * d1) - (q0 + t[:, None] * d2)
    return s, t, gap


class CapturedSides:
    """The way (n, 3) from a capsule's axis to a part in ``reference (F, J, 3)`` (the capture), for
    `penetrations`: it does not change while the output is pushed. Worked out only for the frames a
    penetration test asks about (those where the part comes near the capsule), each as on the whole clip
    (each frame's numbers its own: the same bits)."""

    def __init__(self, reference: np.ndarray) -> None:
        self.reference = reference

    def __len__(self) -> int:
        return len(self.reference)

    def frames(self, frames: slice) -> CapturedSides:
        """The sides of a run of the clip's frames (a half, on its own core)."""
        return CapturedSides(self.reference[frames])

    def side(self, part: Part, capsule: Capsule, rows: np.ndarray) -> np.ndarray:
        """(len(rows), 3) the way from ``capsule``'s axis to ``part`` on the frames ``rows``."""
        at = self.reference
        return segment_closest(at[rows, part.a], at[rows, part.b], *capsule.ends(at, rows))[2]


def penetrations(positions: np.ndarray, capsules: list[Capsule], parts: list[Part],
                 reference: CapturedSides | None = None) -> dict[str, tuple]:
    """Per part, how deep it is in the body at each frame: ``(depth (F,), away (F, 3) unit, along (F,),
    trunk (F,) bool)``: the most any of its capsules' radius exceeds the distance between the axes (<= 0:
    outside; -inf where the part is clear of every capsule's bounding box, which is not measured), the way
    out from that capsule's axis at the closest point, where along the part (0 at its first joint), and
    whether that capsule is the torso, pelvis or head (0 and False where it is outside every capsule).

    reference : the capture's `CapturedSides`: where the part is near the capsule's
        axis (within half its radius) the way out is then the side the captured part is on, so a part
        passing through the axis is not pushed one way and then the other; elsewhere its own shortest
        way (pushed back across the body to the captured side, a hand went round and round it).

    Each frame on its own: a long clip's two halves are made on two cores.
    """
    def half(frames: slice) -> dict[str, tuple]:
        sides = None if reference is None else reference.frames(frames)
        return _penetrations(positions[frames], capsules, parts, sides)

    return by_frame_halves(half, len(positions))


def _penetrations(positions: np.ndarray, capsules: list[Capsule], parts: list[Part],
                  reference: CapturedSides | None) -> dict:
    by_name: dict[str, list[Capsule]] = {}
    for capsule in capsules:
        by_name.setdefault(capsule.name, []).append(capsule)
    boxes: dict[Capsule, tuple] = {}  # each capsule's axis and its box, made once for every part that avoids it
    out = {}
    frames = len(positions)
    for part in parts:
        depth = np.full(frames, -np.inf)
        away = np.zeros((frames, 3))
        along = np.zeros(frames)
        trunk = np.zeros(frames, bool)
        p0, p1 = positions[:, part.a], positions[:, part.b]
        low, high = np.minimum(p0, p1), np.maximum(p0, p1)
        for name in part.avoid:
            for capsule in by_name.get(name, ()):
                if capsule not in boxes:
                    q0, q1 = capsule.ends(positions)
                    boxes[capsule] = q0, q1, np.minimum(q0, q1), np.maximum(q0, q1)
                q0, q1, q_low, q_high = boxes[capsule]
                # Only the frames where the part may be within the radius of the axis: the gap between the
                # two segments' boxes is at most their distance. (Elsewhere the part is outside this capsule,
                # and its depth, way out and place along it are what another capsule says, or none.)
                box = np.maximum(np.maximum(q_low - high, low - q_high), 0.0)
                rows = np.flatnonzero(np.einsum("fc,fc->f", box, box) < (capsule.radius * (1.0 + 1e-6)) ** 2)  # (slack
                # for rounding: a frame measured needlessly costs nothing, one left out at tangency would)
                if not len(rows):
                    continue
                q0, q1 = q0[rows], q1[rows]
                s, _, gap = segment_closest(p0[rows], p1[rows], q0, q1)
                distance = vector_norm(gap)
                # On the axis itself the way out is any way across it.
                axis = q1 - q0
                across = np.cross(axis, np.eye(3)[np.argmin(np.abs(axis), axis=-1)])
                gap = np.where((distance < 1e-12)[:, None], across, gap)
                if reference is not None:
                    side = reference.side(part, capsule, rows)
                    unit = axis / np.maximum(vector_norm(axis, keepdims=True), 1e-12)
                    side = side - sum_last(side * unit, keepdims=True) * unit
                    # (the captured side where the part is near the axis, its own way out where it is
                    # clearly on one side: pushed back across the body to the captured side it went
                    # round and round)
                    known = (vector_norm(side) > 0.05 * capsule.radius) & (distance < 0.5 * capsule.radius)
                    gap = np.where(known[:, None], side, gap)
                deeper = capsule.radius - distance > depth[rows]
                depth[rows] = np.where(deeper, capsule.radius - distance, depth[rows])
                away[rows] = np.where(deeper[:, None], gap / np.maximum(vector_norm(gap), 1e-12)[:, None],
                                      away[rows])
                along[rows] = np.where(deeper, s, along[rows])
                trunk[rows] = np.where(deeper, name in ("torso", "pelvis", "head"), trunk[rows])
        out[part.name] = (depth, away, along, trunk)
    return out


def inside_body(limbs: dict, positions: np.ndarray, sized_from: np.ndarray | None = None) -> np.ndarray:
    """(F,) bool: frames with any hand, forearm, foot or shin inside the body (capsules sized from
    ``sized_from``, the capture, or ``positions`` themselves)."""
    capsules = body_capsules(limbs, positions if sized_from is None else sized_from)
    if not capsules:
        return np.zeros(len(positions), bool)
    found = penetrations(positions, capsules, limb_parts(limbs))
    inside = np.zeros(len(positions), bool)
    for depth, *_ in found.values():
        inside |= depth > 0
    return inside
