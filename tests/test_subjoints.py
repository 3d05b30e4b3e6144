"""Sub-joint hierarchy, pruning, rubber-joint groups and Bézier positioning."""

import numpy as np
import pytest

from mocap_exaggerate.core.errors import ConfigError
from mocap_exaggerate.core.skeleton import Skeleton
from mocap_exaggerate.io.bvh import read_bvh
from mocap_exaggerate.stages.subjoints import (
    SubjointConfig,
    bezier_points,
    build_hierarchy,
    position_subjoints,
)

from .helpers import all_clip_params, shared, shared_clip_params


def chain_skeleton(lengths, names=None):
    """A straight chain along +X with the given link lengths, End Site on the last joint."""
    count = len(lengths) + 1
    offsets = np.zeros((count, 3))
    offsets[1:, 0] = lengths
    ends = np.full((count, 3), np.nan)
    ends[-1] = [1.0, 0, 0]
    names = names or tuple(f"J{i}" for i in range(count))
    channels = tuple(("Zrotation", "Xrotation", "Yrotation") for _ in range(count))
    return Skeleton(names, np.arange(-1, count - 1), offsets, channels, ends)


def test_names_and_order():
    skeleton = chain_skeleton([2.0, 0.0, 3.0], names=("Root", "Arm", "Elbow", "Hand"))
    h = build_hierarchy(skeleton, SubjointConfig(per_link=3))
    assert h.skeleton.names == ("Root", "Arm_s1", "Arm_s2", "Arm", "Elbow", "Hand_s1", "Hand_s2", "Hand")
    assert list(h.original) == [0, 3, 4, 7]
    assert list(h.skeleton.parents) == [-1, 0, 1, 2, 3, 4, 5, 6]
    assert np.allclose(h.skeleton.offsets[1:4, 0], 2 / 3)
    assert np.allclose(h.skeleton.offsets[5:8, 0], 1.0)
    assert np.allclose(h.skeleton.rest_positions()[h.original], skeleton.rest_positions())
    # End Sites stay on their joints.
    assert np.allclose(h.skeleton.end_sites[7], [1, 0, 0])
    assert np.isnan(h.skeleton.end_sites[:7]).all()


def test_straight_unstretched_chain_gives_evenly_spaced_subjoints():
    skeleton = chain_skeleton([2.0, 1.0, 3.0])
    h = build_hierarchy(skeleton, SubjointConfig(per_link=4))
    assert h.groups == ((0, 1, 2, 3),)
    rest = skeleton.rest_positions()
    # A moving, rotating straight chain: rotate the rest pose about Z over time.
    angle = np.linspace(0, 1.5, 30)
    rot = np.stack([np.cos(angle), np.sin(angle)], 1)
    world = np.zeros((30, 4, 3))
    world[..., 0] = rot[:, None, 0] * rest[None, :, 0] + 5
    world[..., 1] = rot[:, None, 1] * rest[None, :, 0]
    out = position_subjoints(world, h, skeleton.link_lengths())
    steps = np.linalg.norm(np.diff(out, axis=1), axis=-1)
    expected = np.repeat([2.0, 1.0, 3.0], 4) / 4
    assert np.allclose(steps, expected[None, :], atol=1e-12)
    assert np.allclose(out[:, h.original], world)


def test_bezier_passes_through_its_points_and_is_c1():
    rng = np.random.default_rng(5)
    points = rng.normal(size=(7, 5, 3))
    knots = np.array([0.0, 1.0, 1.5, 3.5, 4.0])
    for even in (False, True):
        assert np.allclose(bezier_points(points, knots, knots, even=even), points, atol=1e-12)
    eps = 1e-6

    def slope(k, side, even):
        a, b = (k - eps, k) if side < 0 else (k, k + eps)
        return (bezier_points(points, knots, np.array([b]), even=even)
                - bezier_points(points, knots, np.array([a]), even=even)) / eps

    for k in knots[1:-1]:
        # As Kwon and Lee's curve: C1 in the rest-length parameter.
        assert np.allclose(slope(k, -1, False), slope(k, 1, False), atol=1e-4)
        # Spaced evenly along each segment, it is the same curve, still smooth (G1: one tangent direction).
        left, right = slope(k, -1, True), slope(k, 1, True)
        cos = np.sum(left * right, axis=-1) / np.linalg.norm(left, axis=-1) / np.linalg.norm(right, axis=-1)
        assert np.all(cos > 1 - 1e-4)


def test_subjoints_are_evenly_spaced_along_each_segment_of_the_curve():
    """A segment's sub-joints cut its arc into equal pieces, whatever the points' spacing: on a
    stretched forearm beside a captured upper arm no sub-link stretches more than the others."""
    # Shoulder, elbow, wrist, hand: the forearm stretched 1.65x, the elbow bent 10 to 70 degrees.
    bend = np.radians(np.linspace(10.0, 70.0, 5))
    forearm = 1.65 * np.stack([np.cos(bend), np.sin(bend), np.zeros(5)], axis=1)
    points = np.stack([np.zeros((5, 3)), np.tile([1.0, 0.0, 0.0], (5, 1)), [1.0, 0.0, 0.0] + forearm,
                       [1.0, 0.0, 0.0] + forearm * (1.0 + 0.2 / 1.65)], axis=1)
    knots = np.array([0.0, 1.0, 2.0, 2.2])
    params = np.concatenate([np.linspace(knots[i], knots[i + 1], 9)[:-1] for i in range(3)] + [knots[-1:]])
    dense = bezier_points(points, knots, np.linspace(0.0, 2.2, 30001), even=False)
    on = bezier_points(points, knots, params)
    # On the same curve: every even point is within a hair of the parametric curve.
    gap = np.linalg.norm(on[:, :, None] - dense[:, None], axis=-1).min(axis=2)
    assert gap.max() < 1e-3
    steps = np.linalg.norm(np.diff(on, axis=1), axis=-1).reshape(5, 3, 8)
    spread = steps.max(axis=2) / steps.min(axis=2)
    assert spread.max() < 1.02  # chords of equal arcs of a smooth curve
    plain = np.linalg.norm(np.diff(bezier_points(points, knots, params, even=False), axis=1), axis=-1)
    assert (plain.reshape(5, 3, 8).max(axis=2) / plain.reshape(5, 3, 8).min(axis=2)).max() > 1.2  # the test can fail


@pytest.mark.parametrize("path", all_clip_params())
def test_every_clip_builds_finite_subjoints_and_keeps_original_joints(path):
    motion, _ = read_bvh(path)
    skeleton = motion.skeleton
    h = build_hierarchy(skeleton)
    lengths = skeleton.link_lengths()
    # Zero-length links and rigid branches get no sub-joints.
    for j in np.flatnonzero((lengths == 0) | h.rigid):
        if j:
            assert h.skeleton.parents[h.original[j]] == h.original[skeleton.parents[j]]
    world = motion.world_positions()
    out = position_subjoints(world, h, lengths)
    assert np.all(np.isfinite(out))
    assert np.array_equal(out[:, h.original], world)
    names = set(h.skeleton.names)
    assert len(names) == h.skeleton.num_joints
    assert set(skeleton.names) <= names


EXPECTED_GROUPS = {
    # Arms from the clavicle (hanging from the chest joint) to the hand, legs to the ankle.
    "cmu_01_01_forward_jumps": ["Spine1 > LeftShoulder > LeftArm > LeftForeArm > LeftHand",
                                "Hips > LHipJoint > LeftUpLeg > LeftLeg > LeftFoot", "Spine1 > Neck > Neck1 > Head"],
    "cmu_05_06_dance_cartwheel_start_iclone": [
        "CC_Base_Spine02 > CC_Base_L_Clavicle > CC_Base_L_Upperarm > CC_Base_L_Forearm > CC_Base_L_Hand",
        "CC_Base_Pelvis > CC_Base_R_Thigh > CC_Base_R_Calf > CC_Base_R_Foot"],
    "cmu_09_01_run_daz": ["chest > lCollar > lShldr > lForeArm > lHand", "hip > rButtock > rThigh > rShin > rFoot"],
    "assimp_boxing_toes": ["Chest > RightCollar > RightShoulder > RightElbow > RightWrist",
                           "Hips > LeftHip > LeftKnee > LeftAnkle"],
    "makehuman_zombie_walk_keyframed": ["Spine3 > __Clavicle_L > Clavicle_L > UpArm_L > LoArm_L > Hand_L"],
}


@pytest.mark.parametrize("path", shared_clip_params())
def test_five_groups_on_every_humanoid_clip(path):
    skeleton = read_bvh(path)[0].skeleton
    h = build_hierarchy(skeleton)
    shown = [" > ".join(skeleton.names[j] for j in chain) for chain in h.groups]
    assert len(shown) == 5, shown
    for expected in EXPECTED_GROUPS.get(path.stem, []):
        assert expected in shown


def test_iclone_twist_and_share_bones_ride_rigidly():
    skeleton = read_bvh(shared("cmu_05_06_dance_cartwheel_start_iclone.bvh"))[0].skeleton
    h = build_hierarchy(skeleton)
    for name in ("CC_Base_L_ThighTwist01", "CC_Base_L_KneeShareBone", "CC_Base_L_ToeBase", "CC_Base_L_Index1"):
        assert h.rigid[skeleton.index(name)], name
    for name in ("CC_Base_L_Thigh", "CC_Base_L_Calf", "CC_Base_L_Foot", "CC_Base_L_Upperarm"):
        assert not h.rigid[skeleton.index(name)], name


def test_explicit_groups_and_rigid_patterns(sample_clip):
    skeleton = read_bvh(sample_clip)[0].skeleton
    h = build_hierarchy(skeleton, SubjointConfig(groups=(("lShldr", "lForeArm", "lHand"),), rigid=("r*",)))
    assert h.groups == ((skeleton.index("lShldr"), skeleton.index("lForeArm"), skeleton.index("lHand")),)
    assert h.rigid[skeleton.index("rThigh")] and h.rigid[skeleton.index("rShin")]
    with pytest.raises(ConfigError, match="not a child"):
        build_hierarchy(skeleton, SubjointConfig(groups=(("lShldr", "lHand"),)))
    with pytest.raises(ConfigError, match="no joint named 'Tail'"):
        build_hierarchy(skeleton, SubjointConfig(groups=(("hip", "Tail"),)))
    with pytest.raises(ConfigError, match="rigid"):
        build_hierarchy(skeleton, SubjointConfig(rigid=("Tail*",)))


def test_sublink_length_sets_cuts_per_link(sample_clip):
    skeleton = read_bvh(sample_clip)[0].skeleton
    fine = build_hierarchy(skeleton, SubjointConfig(sublink_length="2%"))
    coarse = build_hierarchy(skeleton, SubjointConfig(sublink_length=15.0))
    assert fine.skeleton.num_joints > coarse.skeleton.num_joints > skeleton.num_joints
    target = 0.02 * skeleton.height()
    lengths = skeleton.link_lengths()
    for j in range(1, skeleton.num_joints):
        cuts = int(np.sum(fine.link_child == j))  # the joint itself and its sub-joints
        if fine.rigid[j] or lengths[j] == 0:
            assert cuts == 1
        else:
            assert cuts == max(1, round(lengths[j] / target)), skeleton.names[j]
    with pytest.raises(ConfigError, match="sublink_length"):
        SubjointConfig(sublink_length="-3%")
    with pytest.raises(ConfigError, match="per_link"):
        SubjointConfig(per_link=0)
