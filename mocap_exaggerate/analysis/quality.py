"""Does an output read as animation or as noise? Figures comparing a result with its capture.

`motion_quality` measures what an animator sees (h = skeleton height; every frame counts,
kept rest frames included, so a pop where the rest pose ends shows):

- ``jerk_ratio``: the 99th percentile over (frame, original joint) of |third difference of
  world position| on the output, over the same on the capture.
- ``jump_ratio``: per original joint, the largest one-frame move on the output over the
  largest on the capture; the worst joint (``jump_joint``, ``jump_frame``). Joints whose
  captured largest move is under 0.1 % h are left out (``jumps``: every joint's ratio, 0 for those).
- ``flips``: (sub-)joint frames whose written local rotation turns more than 60 degrees in
  one frame while the captured joints at both ends of its link turn less than 30 degrees.
- ``stretch``: per limb, its length along the output skeleton (through its sub-joints) over
  its rest length: ``peak``, ``p95`` and ``above`` (share of frames over 1.5x); ``links`` is
  the largest ratio of any original link's straight length to its rest length;
  ``torso_within_limbs`` whether the spine's and neck's peaks are at most every arm's and
  leg's peak (within 1 % of rest length: a dragged leg that never stretches is not a limb
  the torso must stay under to the last decimal).
- ``inside``: frames with a hand, forearm, foot or shin inside the body (`mocap_exaggerate.analysis.body`,
  capsules sized from the capture), ``inside_captured`` the capture's own; ``backwards``: limb-frames with
  a knee or elbow more than 1 % h on the wrong side of its limb's line (`hinge_pole`) where the captured one
  bends the right way.
- ``drift`` (h/s): the mean speed of the root on frames where the captured root moves slower
  than 0.1 h/s for at least 0.5 s (None when there are none), and ``drift_captured``.

``bench/quality.py`` prints them for every shared clip and preset; the tests hold the
presets to them.

`face_stretch` measures a skinned mesh instead: how far its faces stretch when posed. `summary` is the
three figures a compare grid labels each cell with, cheaply.
"""

from __future__ import annotations

import numpy as np

from ..core.motion import Motion
from ..core.rotations import quat_angle, vector_norm
from .body import inside_body
from .limbs import behind_line, find_limbs, hinge_pole

__all__ = ["motion_quality", "summary", "turn_degrees", "still_frames", "STRETCHED"]

#: A limb longer than this many times its rest length counts as stretched.
STRETCHED = 1.5


def turn_degrees(local: np.ndarray) -> np.ndarray:
    """(F-1, J) angle in degrees each joint's rotation turns from one frame to the next."""
    return np.degrees(quat_angle(local[:-1], local[1:]))


def still_frames(captured: np.ndarray, frame_time: float, height: float) -> np.ndarray:
    """(F,) frames inside a run of at least 0.5 s where the captured root is slower than 0.1 h/s."""
    if len(captured) < 2:
        return np.zeros(len(captured), bool)
    speed = vector_norm(np.gradient(captured[:, 0], frame_time, axis=0)) / height
    still = speed < 0.1
    shortest = int(round(0.5 / frame_time))
    out = np.zeros_like(still)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], still.astype(int), [0]])))
    for start, end in zip(edges[::2], edges[1::2]):
        if end - start >= shortest:
            out[start:end] = True
    return out


def _path(skeleton, base: int, end: int) -> list[int]:
    """Joints from ``end`` up to (not including) ``base``: each ends one link of the path."""
    above = skeleton.ancestors(end)
    if base not in above:
        raise ValueError("base is not above end")
    return above[:above.index(base)]


def motion_quality(motion: Motion, result) -> dict:
    """The figures above for a `PipelineResult` of ``motion`` (the captured clip it was run on)."""
    if result.rest_frames_dropped:  # compare with the frames that were kept
        motion = motion.slice(slice(result.rest_frames, None))
    skeleton, dt = motion.skeleton, motion.frame_time
    h = skeleton.height()
    cap_rot, cap = motion.forward_kinematics()
    out_all = result.world_positions
    out = out_all[:, result.original_index]

    def jerk(p):
        return vector_norm(np.diff(p, 3, axis=0))

    jerk_ratio = float(np.percentile(jerk(out), 99) / max(np.percentile(jerk(cap), 99), 1e-12)) \
        if len(cap) > 3 else 1.0
    cap_jump = vector_norm(np.diff(cap, axis=0)).max(axis=0, initial=0.0)
    out_steps = vector_norm(np.diff(out, axis=0))  # (F-1, J)
    out_jump = out_steps.max(axis=0, initial=0.0)
    ratios = np.where(cap_jump > 1e-3 * h, out_jump / np.maximum(cap_jump, 1e-12), 0.0)
    worst = int(np.argmax(ratios))
    worst_frame = int(np.argmax(out_steps[:, worst])) if len(out) > 1 else 0

    out_skeleton = result.motion.skeleton
    turns = turn_degrees(result.motion.local_rotations)
    cap_turns = turn_degrees(motion.local_rotations)
    if result.hierarchy is not None and out_skeleton.num_joints != skeleton.num_joints:
        ends = np.stack([result.hierarchy.link_parent, result.hierarchy.link_child], axis=1)
        ends = np.where(ends < 0, ends[:, 1:2], ends)
        reference = cap_turns[:, ends].max(axis=2)
    else:
        reference = cap_turns
    flips = (turns > 60.0) & (reference < 30.0)

    rest = skeleton.link_lengths()
    stretch = {}
    for name, limb in find_limbs(skeleton).items():
        rest_length = sum(rest[j] for j in _path(skeleton, limb.base, limb.end))
        if rest_length <= 1e-6 * h:
            continue
        chain = _path(out_skeleton, int(result.original_index[limb.base]), int(result.original_index[limb.end]))
        length = vector_norm(out_all[:, chain] - out_all[:, out_skeleton.parents[chain]]).sum(axis=1)
        ratio = length / rest_length
        stretch[name] = {"peak": float(ratio.max()), "p95": float(np.percentile(ratio, 95)),
                         "above": float(np.mean(ratio > STRETCHED))}
    long_links = rest > 1e-3 * h
    long_links[0] = False
    links = vector_norm(out[:, long_links] - out[:, skeleton.parents[long_links]]) / rest[long_links]

    still = still_frames(cap, dt, h)
    root = int(result.original_index[0])

    def drift(p):
        return float((vector_norm(np.gradient(p, dt, axis=0))[still] / h).mean()) if still.any() else None

    limbs = find_limbs(skeleton)
    inside = inside_body(limbs, out, cap)
    inside_captured = inside_body(limbs, cap)
    backwards = 0
    for name in ("left_arm", "right_arm", "left_leg", "right_leg"):
        limb = limbs.get(name)
        if limb is None or len(limb.joints) != 3:
            continue
        pole = hinge_pole(cap[:, list(limb.joints)], cap_rot[:, limb.base])
        if pole is not None:
            backwards += int(np.sum((behind_line(out, limb.joints, pole)[0] > 0.01 * h)
                                    & (behind_line(cap, limb.joints, pole)[0] < 0)))

    limb_peaks = [v["peak"] for k, v in stretch.items() if k.endswith(("_arm", "_leg"))]
    torso_peaks = [v["peak"] for k, v in stretch.items() if k in ("spine", "neck")]
    return {
        "jerk_ratio": jerk_ratio,
        "jump_ratio": float(ratios[worst]), "jump_joint": skeleton.names[worst], "jump_frame": worst_frame,
        "jumps": ratios.tolist(),
        "flips": int(flips.sum()), "stretch": stretch, "links": float(links.max()) if links.size else 1.0,
        "torso_within_limbs": (max(torso_peaks) <= min(limb_peaks) + 0.01) if torso_peaks and limb_peaks else None,
        "drift": drift(out_all[:, root]), "drift_captured": drift(cap[:, 0]),
        "inside": int(inside.sum()), "inside_captured": int(inside_captured.sum()), "backwards": backwards,
    }


def face_stretch(skin, bind: np.ndarray, rotations: np.ndarray, positions: np.ndarray, joint_index: np.ndarray,
                 frames) -> np.ndarray:
    """Per face of ``skin``, its longest edge's largest stretch (posed length over bound length)
    at ``frames`` (a few: one posed mesh at a time), posed by `mocap_exaggerate.rig.skinning.pose_skin`.

    bind : (J, 3) the skeleton's bind positions; rotations, positions : (F, J, ...) world transforms
    joint_index : skeleton index of each of the skin's joints
    """
    from ..rig.skinning import pose_skin

    edges = np.concatenate([skin.faces[:, [0, 1]], skin.faces[:, [1, 2]], skin.faces[:, [2, 0]]])
    rest = np.linalg.norm(np.diff(skin.vertices[edges], axis=1)[:, 0], axis=1)
    worst = np.zeros(len(skin.faces))
    for frame in frames:
        posed = pose_skin(skin, bind, rotations[frame], positions[frame], joint_index)
        ratio = np.linalg.norm(np.diff(posed[edges], axis=1)[:, 0], axis=1) / rest
        worst = np.maximum(worst, ratio.reshape(3, -1).max(axis=0))
    return worst


def summary(motion: Motion, result) -> dict[str, float | None]:
    """Three figures of a run, for a label (``compare``): ``stretch``, the longest any arm or leg gets over
    its rest length (through its sub-joints); ``jerk``, the jerk p99 ratio of `motion_quality`; ``limit``,
    the share of the exaggeration the speed limit took (None without a limit)."""
    if result.rest_frames_dropped:
        motion = motion.slice(slice(result.rest_frames, None))
    skeleton = motion.skeleton
    cap = motion.world_positions()
    out_all = result.world_positions
    out = out_all[:, result.original_index]
    jerk = vector_norm(np.diff(out, 3, axis=0)) if len(out) > 3 else None
    cap_jerk = vector_norm(np.diff(cap, 3, axis=0)) if len(cap) > 3 else None
    ratio = (float(np.percentile(jerk, 99) / max(np.percentile(cap_jerk, 99), 1e-12))
             if jerk is not None and cap_jerk is not None else 1.0)
    rest = skeleton.link_lengths()
    out_skeleton = result.motion.skeleton
    longest = 1.0
    for name, limb in find_limbs(skeleton).items():
        if not name.endswith(("_arm", "_leg")):
            continue
        rest_length = sum(rest[j] for j in _path(skeleton, limb.base, limb.end))
        if rest_length <= 0:
            continue
        chain = _path(out_skeleton, int(result.original_index[limb.base]), int(result.original_index[limb.end]))
        length = vector_norm(out_all[:, chain] - out_all[:, out_skeleton.parents[chain]]).sum(axis=1)
        longest = max(longest, float(length.max() / rest_length))
    report = result.speed_report
    return {"stretch": longest, "jerk": ratio, "limit": None if report is None else float(report.taken)}
