"""Detecting the synthetic rest pose that many CMU conversions put first.

The cgspeed conversions prepend a T-pose frame; the Daz-friendly ones then
take a few more frames to settle (fingers swing 150 % of the body height per
frame). Some iClone conversions put a first frame at the origin, in the
clip's own pose, from which the body teleports to where the motion starts
(1.6 heights on CMU 07_04). A temporal filter rings on such a jump, so these
leading frames are kept out of every time filter and written back unchanged.
"""

from __future__ import annotations

import numpy as np

from ..core.motion import Motion
from ..core.rotations import quat_angle, vector_norm

__all__ = ["detect_rest_frames", "REST_POSE_MAX_ANGLE", "JUMP_FACTOR", "TELEPORT", "TELEPORT_SPEED"]

#: Frame 0 counts as a rest pose only if no non-root joint is turned more than this (degrees).
REST_POSE_MAX_ANGLE = 30.0
#: A leading frame is synthetic when the pose jumps this many times the clip's median per-frame change.
JUMP_FACTOR = 8.0
#: A leading frame is synthetic, whatever its pose, when the root leaves it by more than this many
#: skeleton heights in one frame, and `TELEPORT_SPEED` (and `JUMP_FACTOR` times its median step): no
#: body runs that fast. The 33 shared clips' largest real first step is 0.056 heights.
TELEPORT = 0.25
#: ... and by more than this many skeleton heights a second (18 m/s on a 1.8 m body: past a sprint),
#: so a keyframed clip at a few frames a second is not cut at a fast first step.
TELEPORT_SPEED = 10.0


def detect_rest_frames(motion: Motion, world_positions: np.ndarray | None = None) -> int:
    """Number of leading frames that are a synthetic rest pose and its settling (0 if none).

    Frame 0 is a rest frame when either
    (a) every non-root joint is within `REST_POSE_MAX_ANGLE` of its rest
        orientation and the root-relative pose then jumps by more than
        `JUMP_FACTOR` times the clip's median per-frame change (and by over
        1 % of the skeleton height), or
    (b) the root teleports from it: more than `TELEPORT` heights in one frame
        (and `TELEPORT_SPEED` heights a second, and `JUMP_FACTOR` times its
        median step), whatever the pose.
    Frames after it count too while the jump into the next frame stays that
    large. ``world_positions`` (F, J, 3) saves recomputing forward kinematics.
    """
    if motion.num_frames < 4:
        return 0
    world = motion.world_positions() if world_positions is None else world_positions
    height = motion.skeleton.height()
    step = vector_norm(world[1:, 0] - world[:-1, 0])
    teleport = step > max(JUMP_FACTOR * float(np.median(step)), TELEPORT * height,
                          TELEPORT_SPEED * height * motion.frame_time)
    if not teleport[0]:
        rot = motion.local_rotations
        identity = np.zeros(4)
        identity[3] = 1.0
        turned = np.degrees(quat_angle(rot[0, 1:], identity))
        if turned.size and turned.max() > REST_POSE_MAX_ANGLE:
            return 0
    # Median over joints: a handful of wobbling fingers should not decide it.
    first_jump = float(np.median(vector_norm((world[1] - world[1, :1]) - (world[0] - world[0, :1]))))
    if not teleport[0] and not first_jump > 0.01 * height:  # (below any limit: the clip's medians are not needed)
        return 0
    pose = world - world[:, :1]
    jump = np.median(vector_norm(pose[1:] - pose[:-1]), axis=1)
    typical = float(np.median(jump))
    limit = max(JUMP_FACTOR * typical, 0.01 * height)
    above = (jump > limit) | teleport
    if not above[0]:
        return 0
    # Leading run of large jumps; frames up to and including its last start are synthetic.
    run = int(np.argmin(above)) if not above.all() else len(above)
    return min(run, motion.num_frames - 2)
