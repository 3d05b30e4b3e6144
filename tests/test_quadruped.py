"""A quadruped made of rubber (issue 26, part 4): the Khronos fox (CC-BY 4.0: "Fox" by PixelMannen,
rigged and animated by @tomkranis, converted to glTF by AsoboStudio and scurest) through the whole
pipeline, its limbs found from the skeleton's shape, not from its names.
"""

from __future__ import annotations

import numpy as np
import pytest

from mocap_exaggerate.analysis.branches import minor_branches, rubber_groups
from mocap_exaggerate.analysis.limbs import find_limbs, standing_ends
from mocap_exaggerate.analysis.quality import motion_quality
from mocap_exaggerate.config import load_preset
from mocap_exaggerate.io.gltf_motion import read_gltf_motion
from mocap_exaggerate.pipeline import run
from mocap_exaggerate.stages.contacts import ContactConfig, find_contacts, find_effectors
from mocap_exaggerate.viz.framing import view_axes

from .helpers import SHARED_BVH

FOX = SHARED_BVH.parent / "gltf" / "fox_khronos.glb"
pytestmark = pytest.mark.skipif(not FOX.exists(), reason=f"the shared glTF fox is not at {FOX}")

#: Each preset's range of stretch (the springs' limit), which a quadruped's limbs keep too.
RANGE = {"subtle": 1.15, "cartoon": 1.5, "looney": 1.75}


def _fox(clip: str):
    return read_gltf_motion(FOX, clip=clip)[0]


def test_four_legs_a_neck_and_a_tail_are_found_from_the_shape():
    skeleton = _fox("Walk").skeleton
    limbs = find_limbs(skeleton)
    names = {name: [skeleton.names[j] for j in limb.joints] for name, limb in limbs.items()}
    # The hind legs' names (b_LeftLeg01_015) say nothing a humanoid finder knows: found by shape.
    assert names["left_leg"] == ["b_LeftLeg01_015", "b_LeftLeg02_016", "b_LeftFoot01_017"]
    assert names["right_leg"] == ["b_RightLeg01_019", "b_RightLeg02_020", "b_RightFoot01_021"]
    assert names["left_arm"][-1] == "b_LeftHand_011" and names["right_arm"][-1] == "b_RightHand_08"
    # It stands on all four: the front paws go as low as the hind feet.
    heights = _fox("Walk").world_positions()[..., 1]
    assert sorted(skeleton.names[j] for j in standing_ends(skeleton, limbs, heights)) == [
        "b_LeftFoot01_017", "b_LeftHand_011", "b_RightFoot01_021", "b_RightHand_08"]
    # Rubber chains on the four legs, the neck and the tail, by topology alone.
    chains = {skeleton.names[g[-1]] for g in rubber_groups(skeleton, minor_branches(skeleton))}
    assert chains == {"b_Head_05", "b_Tail03_014", "b_LeftFoot01_017", "b_RightFoot01_021", "b_LeftHand_011",
                      "b_RightHand_08"}  # the toes below the hind feet ride on them, as a human's do


def test_a_standing_fox_is_planted_on_its_feet():
    motion = _fox("Survey")
    skeleton = motion.skeleton
    limbs = find_limbs(skeleton)
    effectors = find_effectors(skeleton, limbs, minor_branches(skeleton))
    _, touching = find_contacts(skeleton, motion.world_positions(), motion.frame_time, limbs, effectors,
                                ContactConfig(enabled=True))
    assert set(touching) == set(standing_ends(skeleton, limbs, motion.world_positions()[..., 1]))  # all four
    planted = [skeleton.names[j] for j, runs in touching.items() if len(runs)]
    assert {"b_LeftFoot01_017", "b_RightFoot01_021"} <= set(planted)
    # The planted feet stay where they stood at looney.
    result = run(motion, load_preset("looney"))
    for name in ("b_LeftFoot01_017", "b_RightFoot01_021"):
        j = skeleton.index(name)
        first, last = touching[j][0]
        out = result.world_positions[first:last + 1, result.original_index[j]]
        captured = motion.world_positions()[first:last + 1, j]
        assert np.abs(out - captured).max() < 0.01 * skeleton.height()


@pytest.mark.parametrize("preset", list(RANGE))
@pytest.mark.parametrize("clip", ["Walk", "Run"])
def test_the_fox_walks_and_runs_at_every_preset_within_its_range(clip, preset):
    motion = _fox(clip)
    quality = motion_quality(motion, run(motion, load_preset(preset)))
    assert quality["flips"] == 0 and quality["jump_ratio"] < 2.0 and quality["jerk_ratio"] < 1.5
    for name in ("left_arm", "right_arm", "left_leg", "right_leg"):
        assert quality["stretch"][name]["peak"] <= RANGE[preset] + 0.01, (name, quality["stretch"][name])


def test_a_fox_on_the_spot_is_seen_from_its_side():
    motion = _fox("Run")  # a loop on the spot: the root does not travel
    right, up, depth = view_axes(motion.skeleton, motion.world_positions()[:, 0])
    assert (right, up, depth) == (2, 1, 0)  # along its spine (z) across the picture, from its flank (x)


@pytest.mark.parametrize("clip", ["Walk", "Run"])
def test_the_tail_whips_with_the_springs(clip):
    from dataclasses import replace

    motion = _fox(clip)
    looney = load_preset("looney")
    springs, still = (run(motion, config) for config in (looney, replace(looney, springs=replace(looney.springs,
                                                                                                  enabled=False))))
    tip = springs.original_index[motion.skeleton.index("b_Tail03_014")]
    lag = np.linalg.norm(springs.world_positions[:, tip] - still.world_positions[:, tip], axis=-1)
    assert lag.max() > 0.05 * motion.skeleton.height()  # it swings behind the body (0.10-0.11 h)
    # and stays a tail: no sub-link of it past looney's range of stretch
    tail = [motion.skeleton.index(n) for n in ("b_Tail01_012", "b_Tail02_013", "b_Tail03_014")]
    lengths = np.linalg.norm(np.diff(springs.world_positions[:, springs.original_index[tail]], axis=1), axis=-1)
    rest = np.linalg.norm(np.diff(motion.skeleton.rest_positions()[tail], axis=0), axis=-1)
    assert (lengths / rest).max() <= 1.76
