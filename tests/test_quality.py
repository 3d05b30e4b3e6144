"""Issue 11's done-means on every shared clip: motion that reads as animation, presets that keep their word.

The figures are `mocap_exaggerate.analysis.quality.motion_quality` (``bench/quality.py`` prints them
all). Skipped, saying why, where ../shared/data is absent.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mocap_exaggerate import load_preset
from mocap_exaggerate.analysis.quality import motion_quality
from mocap_exaggerate.io.bvh import read_bvh
from mocap_exaggerate.pipeline import run

from .helpers import shared_clip_params

#: Jerk p99 over the capture's, as issue 11 asks.
JERK = {"subtle": 1.5, "cartoon": 2.0, "looney": 3.0}
#: The ranges the presets' descriptions promise (README, "Presets"): the longest any arm or leg
#: gets, and the longest the spine or neck gets, in rest lengths.
LIMBS = {"subtle": 1.15, "cartoon": 1.5, "looney": 1.75}
TORSO = {"subtle": 1.05, "cartoon": 1.05, "looney": 1.15}


def _run(path, preset):
    motion, _ = read_bvh(path, fps=120.0 if "amc2bvh" in path.name else None)
    result = run(motion, load_preset(preset))
    return motion, result, motion_quality(motion, result)


@pytest.mark.parametrize("preset", ["subtle", "cartoon", "looney"])
@pytest.mark.parametrize("path", shared_clip_params())
def test_presets_read_as_animation_and_keep_their_word(path, preset):
    motion, result, q = _run(path, preset)
    where = f"{path.name} at {preset}"
    assert q["jerk_ratio"] <= JERK[preset], (where, q["jerk_ratio"])
    # No written joint spins round in a frame while the capture turns gently (it did 90-147 degrees).
    assert q["flips"] == 0, where
    # No pops: no joint moves in a frame more than twice the most it ever moves in the capture,
    # rest-pose ends included. Toes, fingers and twist bones ride rigidly on their foot or
    # forearm: the foot keeps to its toes' speed, turns no faster than they may go, and eases
    # onto a landing only so fast that they keep to it too (the amc2bvh jump's toes reached 2.14x).
    jumps = np.array(q["jumps"])
    assert jumps.max() <= 2.0, (where, q["jump_joint"], q["jump_frame"], jumps.max())
    limbs = [v["peak"] for k, v in q["stretch"].items() if k.endswith(("_arm", "_leg"))]
    torso = [v["peak"] for k, v in q["stretch"].items() if k in ("spine", "neck")]
    assert max(limbs) <= LIMBS[preset], (where, q["stretch"])
    assert max(torso) <= TORSO[preset], (where, q["stretch"])
    assert q["torso_within_limbs"], (where, q["stretch"])  # cartoon torsos stretch less than limbs
    # Issue 25: hands, forearms, feet and shins stay out of the torso, pelvis, head and thighs where
    # the capture's do (before: more frames inside than captured on 9 of these 12 clips at looney, the
    # boxer's forearms 433 frames against 0; then the boxer's shin in the pelvis for 3 frames as he sat
    # on the canvas, the floor lifting his pelvis onto his heel after the pass); knees and elbows bend
    # the captured way.
    assert q["inside"] <= q["inside_captured"], (where, q["inside"], q["inside_captured"])
    assert q["backwards"] == 0, (where, q["backwards"])


@pytest.mark.parametrize("path", [p for p in shared_clip_params() if p.values[0] is None or
                                  p.values[0].name in ("cmu_01_01_forward_jumps.bvh", "cmu_16_01_jump_amc2bvh.bvh",
                                                       "assimp_boxing_toes.bvh")])
def test_a_body_waiting_in_the_capture_does_not_float_about(path):
    # The hop: the exaggerated body drifted 0.44 body heights a second while the actor stood
    # still (0.05). What is left is the anticipation and settle of the moves either side.
    _, _, q = _run(path, "looney")
    assert q["drift"] is not None and q["drift"] <= 0.25, q["drift"]


@pytest.mark.parametrize("path", [p for p in shared_clip_params() if p.values[0] is None or
                                  p.values[0].name in ("assimp_boxing_toes.bvh", "cmu_05_06_dance_cartwheel_start_iclone.bvh")])
def test_rubber_limbs_do_not_kink_next_to_the_shoulder_or_hip(path):
    # The first sub-joint after a limb's root, where the swinging limb meets the solid body: with
    # the whole follow-through next to a root that does not swing, it folded 60-167 degrees in
    # 11-16 % of the boxer's looney frames. The capture's own bend there is a few degrees.
    motion, result, _ = _run(path, "looney")
    hierarchy, skeleton, points = result.hierarchy, result.hierarchy.skeleton, result.world_positions
    from mocap_exaggerate.analysis.limbs import find_limbs

    for name, limb in find_limbs(motion.skeleton).items():
        if not name.endswith(("_arm", "_leg")):
            continue
        base = hierarchy.original[limb.base]
        first = next(j for j in range(skeleton.num_joints)
                     if skeleton.parents[j] == base and hierarchy.link_child[j] == limb.joints[1])
        if not skeleton.offsets[first].any():  # the link's zero-length start joint sits on the root
            first = next(j for j in range(skeleton.num_joints) if skeleton.parents[j] == first)
        second = next(j for j in range(skeleton.num_joints) if skeleton.parents[j] == first)
        a, b = points[:, first] - points[:, base], points[:, second] - points[:, first]
        cosine = np.sum(a * b, -1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
        bend = np.degrees(np.arccos(np.clip(cosine, -1, 1)))
        assert np.mean(bend > 60.0) <= 0.02, (path.name, name, np.mean(bend > 60.0), bend.max())  # 1.2 % at most: the fall


@pytest.mark.parametrize("path", [p for p in shared_clip_params() if p.values[0] is None or
                                  p.values[0].name == "cmu_131_01_walk_start_stop_max.bvh"])
def test_knees_bend_toward_the_toes_as_captured(path):
    # The 3ds Max walk at looney bent a knee backwards (behind the hip-ankle line by more than 1 %
    # of the body's height, while the captured knee bent forward) in 426 frames before issue 11.
    motion, result, _ = _run(path, "looney")
    skeleton, captured = motion.skeleton, motion.world_positions()
    out = result.world_positions[:, result.original_index]

    def forward(p, hip, knee, ankle, toe):
        line = p[:, ankle] - p[:, hip]
        line /= np.linalg.norm(line, axis=-1, keepdims=True)
        bend = p[:, knee] - p[:, hip]
        bend -= np.sum(bend * line, -1, keepdims=True) * line
        toes = p[:, toe] - p[:, ankle]
        toes -= np.sum(toes * line, -1, keepdims=True) * line
        return np.sum(bend * toes, -1) / np.linalg.norm(toes, axis=-1)

    backwards = 0
    for side in ("Left", "Right"):
        joints = [skeleton.index(side + name) for name in ("Hip", "Knee", "Ankle", "Toe")]
        backwards += int(np.sum((forward(out, *joints) < -0.01 * skeleton.height()) & (forward(captured, *joints) > 0)))
    assert backwards <= 60, backwards  # measured 41 of 1988 leg-frames


@pytest.mark.parametrize("preset", ["subtle", "cartoon", "looney"])
@pytest.mark.parametrize("path", shared_clip_params(wide=True))
def test_no_knee_pops_without_subjoints(path, preset):
    """Issue 25: the two-bone solve of a planted foot moved a knee 3.9-13.6x its largest captured
    one-frame step (the boxer at looney) as the leg passed straight or folded shut. Every joint now
    stays within 2x on every shared clip, the wider corpus too. The last two: the boxer's kneel at
    looney (2.004x, the knee's move eased over 2 frames) and the sit-down's knee at looney (2.09x,
    the correction letting go of a thigh within 3 frames at 30 fps)."""
    motion, _ = read_bvh(path, fps=120.0 if "amc2bvh" in path.name else None)
    config = load_preset(preset)
    config = replace(config, subjoints=replace(config.subjoints, enabled=False))
    jumps = motion_quality(motion, run(motion, config))
    assert jumps["jump_ratio"] <= 2.0, (path.name, preset, jumps["jump_joint"], jumps["jump_frame"],
                                        jumps["jump_ratio"])
