"""Orientation recovery helpers, and the written sub-joint BVH read back by bvhio."""

import bvhio
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocap_exaggerate.config import load_preset, resolve_config
from mocap_exaggerate.core.rotations import quat_angle, quat_between, quat_rotate, quat_slerp
from mocap_exaggerate.io.bvh import format_bvh, read_bvh
from mocap_exaggerate.pipeline import run
from mocap_exaggerate.stages.orient import _fit_turn

from .helpers import SAMPLE_DIR


def test_quat_between_is_the_smallest_rotation():
    rng = np.random.default_rng(1101)
    u = rng.normal(size=(200, 3))
    v = rng.normal(size=(200, 3)) * 3.0
    q = quat_between(u, v)
    turned = quat_rotate(q, u)
    assert np.allclose(turned / np.linalg.norm(turned, axis=1, keepdims=True),
                       v / np.linalg.norm(v, axis=1, keepdims=True))
    cos = np.sum(u * v, 1) / np.linalg.norm(u, axis=1) / np.linalg.norm(v, axis=1)
    assert np.allclose(quat_angle(q, np.tile([0, 0, 0, 1.0], (200, 1))), np.arccos(np.clip(cos, -1, 1)))


def test_quat_between_degenerate_cases():
    u = np.array([[1.0, 0, 0], [0, 2.0, 0], [0, 0, 0], [1.0, 1.0, 0]])
    v = np.array([[-3.0, 0, 0], [0, 0, 0], [1.0, 0, 0], [1.0, 1.0, 0]])
    q = quat_between(u, v)
    assert np.all(np.isfinite(q))
    assert np.allclose(quat_rotate(q[0], u[0]) / 1.0, [-1, 0, 0])
    assert np.allclose(q[1:], [0, 0, 0, 1])


def test_slerp_endpoints_and_midpoint():
    a = Rotation.random(50, random_state=1).as_quat()
    b = Rotation.random(50, random_state=2).as_quat()
    assert np.allclose(quat_angle(quat_slerp(a, b, 0.0), a), 0, atol=1e-7)
    assert np.allclose(quat_angle(quat_slerp(a, b, 1.0), b), 0, atol=1e-7)
    mid = quat_slerp(a, b, 0.5)
    assert np.allclose(quat_angle(a, mid), quat_angle(a, b) / 2, atol=1e-7)


def test_the_fit_recovers_a_known_rotation_and_holds_a_thin_set_steady():
    rng = np.random.default_rng(1102)
    truth = Rotation.random(30, random_state=3)
    u = np.repeat(rng.normal(size=(1, 3, 3)), 30, axis=0)
    v = np.stack([truth[i].apply(u[i]) for i in range(30)])
    # The pull toward "no turn" costs a fraction of a degree on a well spread set...
    assert np.degrees(np.max(quat_angle(_fit_turn(u, v), truth.as_quat()))) < 1.0
    assert np.max(quat_angle(_fit_turn(u, u), np.array([0.0, 0, 0, 1]))) < 1e-9
    # ...and decides the turn about the line of two hips nearly opposite each other: none.
    hips = np.array([[[1.0, -0.02, 0.0], [-1.0, -0.02, 0.0]]])
    jiggled = hips + np.array([[[0.0, 0.0, 0.03], [0.0, 0.0, -0.03]]])  # turned 1.7 degrees about y
    turn = _fit_turn(hips, jiggled)
    assert np.degrees(quat_angle(turn, np.array([0.0, 0, 0, 1]))) < 3.0


def test_written_subjoint_bvh_opens_in_bvhio_with_the_expected_joints(sample_clip, tmp_path):
    motion, _ = read_bvh(sample_clip)
    result = run(motion, load_preset("cartoon"))
    path = tmp_path / "rubber.bvh"
    path.write_bytes(format_bvh(result.motion))
    root = bvhio.readAsHierarchy(str(path))
    layout = root.layout()
    assert len(layout) == result.motion.skeleton.num_joints == result.hierarchy.skeleton.num_joints
    assert [joint.Name for joint, _, _ in layout] == list(result.motion.skeleton.names)
    for frame in (10, 80, 148):
        root.loadPose(frame)
        theirs = np.array([list(joint.PositionWorld) for joint, _, _ in layout])
        assert np.max(np.abs(theirs - result.world_positions[frame])) < 1e-4 * motion.skeleton.height()


def test_original_skeleton_output_keeps_the_joint_set_and_channel_orders(sample_clip):
    motion, _ = read_bvh(sample_clip)
    result = run(motion, resolve_config("cartoon", None, {"output": {"skeleton": "original"}}))
    assert result.motion.skeleton.names == motion.skeleton.names
    orders = [motion.skeleton.rotation_order(j) for j in range(motion.skeleton.num_joints)]
    assert [result.motion.skeleton.rotation_order(j) for j in range(motion.skeleton.num_joints)] == orders
    # Springs moved the original joints: the output is not merely the exaggerated positions.
    springs_off = run(motion, resolve_config("cartoon", None, {"output": {"skeleton": "original"},
                                                               "springs": {"enabled": False}}))
    assert not np.allclose(result.world_positions, springs_off.world_positions)


@pytest.mark.parametrize("preset", ["subtle", "cartoon", "looney"])
def test_rubber_limbs_bend(sample_clip, preset):
    # Sub-joints between shoulder and hand leave the straight lines between original joints.
    motion, _ = read_bvh(sample_clip)
    result = run(motion, load_preset(preset))
    h = result.hierarchy
    between = np.flatnonzero(~h.is_original & ~h.rigid[h.link_child])
    a = result.world_positions[:, h.original[h.link_parent[between]]]
    b = result.world_positions[:, h.original[h.link_child[between]]]
    p = result.world_positions[:, between]
    f = h.fraction[between][None, :, None]
    off_line = np.linalg.norm(p - ((1 - f) * a + f * b), axis=-1)
    assert off_line.max() > 0.01 * motion.skeleton.height()


def test_toes_keep_to_the_speed_limit_their_foot_keeps():
    """A toe rides its foot's turn; the foot keeps to the toe's speed and turns no faster than it may go.

    Before, the amc2bvh jump's toes moved 1.7x their captured top speed under a 1.5x limit
    (the shin swung the foot round faster than anything checked).
    """
    from mocap_exaggerate.analysis.branches import rider_joints
    from mocap_exaggerate.stages.extrapolate import extrapolate
    from mocap_exaggerate.stages.orient import recover_orientations
    from mocap_exaggerate.stages.state import uncut_hierarchy

    motion = read_bvh(SAMPLE_DIR / "cmu_16_01_jump_amc2bvh.bvh", fps=120.0)[0]
    skeleton = motion.skeleton
    rot, pos = motion.world_rotations(), motion.world_positions()
    hierarchy = uncut_hierarchy(skeleton)
    top = np.linalg.norm(np.diff(pos, axis=0), axis=-1).max(axis=0)
    moving = hierarchy.rigid & (top > 1e-3 * skeleton.height())
    assert moving.sum() >= 2  # the toes

    def toes(riders, max_speed):
        moved = extrapolate(pos, sigma=24.0, omega=5.0, smooth=6.0, max_speed=1.5, riders=riders)
        _, placed = recover_orientations(moved, hierarchy, motion, rot, pos, max_speed=max_speed)
        assert np.allclose(placed[:, ~hierarchy.rigid], moved[:, ~hierarchy.rigid])  # only riders move
        return (np.linalg.norm(np.diff(placed, axis=0), axis=-1).max(axis=0)[moving] / top[moving]).max()

    assert toes(None, 0.0) > 1.6
    assert toes(rider_joints(skeleton), 1.5) <= 1.5 + 1e-6



def test_calming_a_foot_leaves_its_turn_as_it_was_away_from_the_fast_frames():
    """The riders' speed limit is local: a foot turns as recovered (to rounding) on every frame
    farther than its easing reaches from a frame whose toes went over their budget. (Its margin of
    0.98 was once taken on every frame of every pass: the whole clip's feet turned 2 % less a pass.)"""
    from mocap_exaggerate.analysis.branches import riders
    from mocap_exaggerate.stages.extrapolate import extrapolate
    from mocap_exaggerate.stages.orient import recover_orientations
    from mocap_exaggerate.stages.state import uncut_hierarchy

    motion = read_bvh(SAMPLE_DIR / "cmu_16_01_jump_amc2bvh.bvh", fps=120.0)[0]
    skeleton = motion.skeleton
    rot, pos = motion.world_rotations(), motion.world_positions()
    hierarchy = uncut_hierarchy(skeleton)
    moved = extrapolate(pos, sigma=24.0, omega=5.0, smooth=6.0, max_speed=1.5)  # the toes go over
    free_rot, free_pos = recover_orientations(moved, hierarchy, motion, rot, pos)
    calm_rot, _ = recover_orientations(moved, hierarchy, motion, rot, pos, max_speed=1.5)
    reach = 6 * (2 * 6 + 1)  # six passes, each eased over 6 frames (0.05 s) either side
    checked = 0
    for foot, toes in riders(skeleton, hierarchy.rigid).items():
        budget = 1.5 * np.linalg.norm(np.diff(pos[:, toes], axis=0), axis=-1).max(axis=0)
        over = np.flatnonzero((np.linalg.norm(np.diff(free_pos[:, toes], axis=0), axis=-1) > budget).any(axis=1))
        if not len(over):
            continue
        near = np.zeros(len(pos), bool)
        for frame in over:
            near[max(frame - reach, 0) : frame + reach + 2] = True
        assert np.abs(calm_rot[near, foot] - free_rot[near, foot]).max() > 1e-3
        assert np.abs(calm_rot[~near, foot] - free_rot[~near, foot]).max() < 1e-12  # (a turn to the power 1)
        checked += int((~near).sum())
    assert checked > 100

def test_local_rotations_written_over_the_world_ones_are_the_same_bits():
    """The orient stage turns its world rotations into local ones in place (a long clip does not
    hold both): block by block, each read whole before it is written, they are the copy's bits; and
    forward kinematics of the result gives the world rotations and positions back within rounding
    (what the result's world rotations now are)."""
    from mocap_exaggerate.core.kinematics import cache_blocks, forward_kinematics, local_from_world

    motion = read_bvh(SAMPLE_DIR / "cmu_09_01_run_daz.bvh")[0]
    rot, pos = motion.world_rotations(), motion.world_positions()
    rot, pos = np.concatenate([rot] * 8), np.concatenate([pos] * 8)  # 1,192 frames: several blocks
    parents = motion.skeleton.parents
    assert len(cache_blocks(len(rot), len(parents) - 1)) >= 3
    copied_rot, copied_pos = local_from_world(parents, rot, pos)
    buffer = rot.copy()
    local_rot, local_pos = local_from_world(parents, buffer, pos, overwrite_rotations=True)
    assert local_rot is buffer
    assert local_rot.tobytes() == copied_rot.tobytes() and local_pos.tobytes() == copied_pos.tobytes()
    with pytest.raises(TypeError):
        local_from_world(parents, rot.astype(np.float32), pos, overwrite_rotations=True)
    again_rot, again_pos = forward_kinematics(parents, local_rot, local_pos)
    assert np.max(quat_angle(again_rot, rot)) < 1e-12
    assert np.max(np.abs(again_pos - pos)) < 1e-9 * motion.skeleton.height()

    result = run(motion, load_preset("cartoon"))
    placed = result.world_positions
    parents_out = result.motion.skeleton.parents[1:]
    turned = quat_rotate(result.world_rotations[:, parents_out], result.motion.local_positions[:, 1:])
    assert np.max(np.abs(placed[:, parents_out] + turned - placed[:, 1:])) < 1e-9 * result.motion.skeleton.height()
