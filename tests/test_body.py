"""The default body on real rigs: one closed tube per run of links, never welding limbs
together, that stays joined to its skeleton over the captured and the exaggerated motion."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from mocap_exaggerate.analysis.limbs import find_limbs
from mocap_exaggerate.analysis.quality import face_stretch as edge_stretch
from mocap_exaggerate.config import load_preset
from mocap_exaggerate.core.skeleton import Skeleton
from mocap_exaggerate.io.bvh import read_bvh
from mocap_exaggerate.jobs.outputs import output_skin
from mocap_exaggerate.pipeline import run
from mocap_exaggerate.rig.body import default_skin
from mocap_exaggerate.stages.subjoints import build_hierarchy

from .helpers import SAMPLE_CLIPS, mesh_pieces, shared, shared_clip_params

ICLONE = "cmu_06_15_basketball_dribble_shoot_iclone.bvh"
#: Rigs whose rest pose packs the limbs together: iClone (legs and arms up beside the spine),
#: 3ds Max and MocapBank (arms down against the hips). The old welded body tore on all four.
PACKED = [ICLONE, "cmu_05_06_dance_cartwheel_start_iclone.bvh", "cmu_131_01_walk_start_stop_max.bvh",
          "mocapbank_sit_down_stand_up.bvh"]


def body_of(path):
    motion, _ = read_bvh(path)
    return motion, default_skin(motion.skeleton, build_hierarchy(motion.skeleton).rigid)


def pieces(skin) -> list[np.ndarray]:
    """The vertex indices of each connected piece of the mesh."""
    label = mesh_pieces(skin)
    return [np.flatnonzero(label == k) for k in range(label.max() + 1)]


@pytest.mark.parametrize("path", SAMPLE_CLIPS, ids=lambda p: p.stem)
def test_every_piece_is_a_closed_outward_tube_of_consecutive_links(path):
    motion, body = body_of(path)
    parents = motion.skeleton.parents
    assert body.joints.shape == body.weights.shape == (body.num_vertices, 4)
    np.testing.assert_allclose(body.weights.sum(axis=1), 1.0)
    assert np.all(body.weights[:, 2:] == 0)  # two joints at most: the two ends of a bend
    for piece in pieces(body):
        inside = np.isin(body.faces, piece).all(axis=1)
        mesh = trimesh.Trimesh(body.vertices, body.faces[inside], process=False)
        assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
        # The joints that move a tube run down one chain: each but the first is its predecessor's child.
        moving = np.unique(body.joints[piece][body.weights[piece] > 0])
        assert sum(parents[j] not in moving for j in moving) == 1, [motion.skeleton.names[j] for j in moving]


@pytest.mark.parametrize("path", SAMPLE_CLIPS, ids=lambda p: p.stem)
def test_arms_and_legs_are_one_tube_each_from_shoulder_and_hip(path):
    """Kwon and Lee's cat is one rubber figure: the links of an arm or a leg that run on from one
    another in the rest pose are one tube, so they cannot part at an elbow or a knee."""
    motion, body = body_of(path)
    skeleton = motion.skeleton
    limbs = find_limbs(skeleton)
    piece_of = np.zeros(body.num_vertices, np.int64)
    for number, piece in enumerate(pieces(body)):
        piece_of[piece] = number
    for name in ("left_arm", "right_arm", "left_leg", "right_leg"):
        limb = limbs[name]
        # Upper limb, its joint (elbow, knee) and lower limb: the links moved by these two joints.
        upper, lower = limb.joints[-3], limb.joints[-2]
        carried = [np.unique(piece_of[(body.joints == j).any(axis=1) & (body.weights.max(axis=1) > 0)]) for j in (upper, lower)]
        assert len(set(carried[0]) | set(carried[1])) == 1, (name, carried)
@pytest.mark.parametrize("path", SAMPLE_CLIPS, ids=lambda p: p.stem)
def test_the_default_rigid_set_is_the_pipelines(path):
    """Called without ``rigid`` (a --skin made from it), twist bones and fingers add nothing either."""
    motion, body = body_of(path)
    alone = default_skin(motion.skeleton)
    np.testing.assert_array_equal(alone.vertices, body.vertices)
    np.testing.assert_array_equal(alone.joints, body.joints)


def test_the_exaggerated_skin_keeps_four_influences_summing_to_one(sample_clip):
    motion, body = body_of(sample_clip)
    bound = output_skin(motion, run(motion, load_preset("cartoon")), body)
    assert bound.joints.shape[1] == 4
    np.testing.assert_allclose(bound.weights.sum(axis=1), 1.0)


@pytest.mark.parametrize("name", PACKED)
def test_no_piece_joins_an_arm_to_the_torso_or_a_leg(name):
    motion, body = body_of(shared(name))
    skeleton = motion.skeleton
    limbs = find_limbs(skeleton)
    sides = {limb: set(skeleton.descendants(limbs[limb].base).tolist()) for limb in ("left_arm", "right_arm",
                                                                                   "left_leg", "right_leg")}
    sides["spine"] = set(limbs["spine"].joints)
    for piece in pieces(body):
        joints = set(body.joints[piece][body.weights[piece] > 0].tolist())
        # A tube starting at a branch (a collar from the chest) moves its first link with the branch joint.
        joints -= {j for j in joints if skeleton.parents[j] not in joints and len(joints) > 1}
        touched = [limb for limb, members in sides.items() if joints & members]
        assert len(touched) <= 1, (touched, [skeleton.names[j] for j in joints])
    # Every link of each arm and leg moves some of the body.
    moved = set(body.joints[body.weights > 0].tolist())
    for limb in ("left_arm", "right_arm", "left_leg", "right_leg"):
        assert set(limbs[limb].joints) <= moved, limb


def test_iclone_twist_and_share_bones_add_no_bulge_and_hands_feet_head_are_there():
    motion, body = body_of(shared(ICLONE))
    names = {motion.skeleton.names[j] for j in np.unique(body.joints[:, 0])}
    assert not {n for n in names if "ShareBone" in n or ("Twist" in n and "Neck" not in n)}
    # Their fingers, toes and face ride rigidly; the hand, foot and head joints still get a piece.
    assert {"CC_Base_L_Hand", "CC_Base_R_Hand", "CC_Base_L_Foot", "CC_Base_R_Foot", "CC_Base_Head"} <= names
    # One tube per run of links (no finger, toe, eye, twist piece): each leg from the pelvis side to
    # the toes, each arm from the chest through collar, arm and hand, the spine, the neck, the
    # head's ball, and the two pelvis sides and the upper chest, which turn off at sharp angles.
    assert len(pieces(body)) == 10


@pytest.mark.parametrize("path", shared_clip_params())
def test_captured_motion_bends_the_tubes_without_tearing_them(path):
    """The tubes bend at the joints by linear blend skinning, handing over within a radius of
    each joint (within two radii): over the captured clip no face passes 2.5x its rest size
    and at most 0.2 % pass 2x (the worst shared clips: 0.13 % on the 3ds Max walk, 0.09 % on
    the iClone cartwheel; the rest none)."""
    motion, body = body_of(path)
    skeleton = motion.skeleton
    rotations, positions = motion.forward_kinematics()
    index = np.array([skeleton.index(n) for n in body.joint_names])
    frames = np.unique(np.linspace(0, motion.num_frames - 1, min(motion.num_frames, 150)).astype(int))
    stretch = edge_stretch(body, skeleton.rest_positions(), rotations, positions, index, frames)
    assert stretch.max() < 2.5
    assert np.mean(stretch > 2.0) < 0.002


@pytest.mark.parametrize("name", PACKED)
def test_exaggerated_motion_leaves_at_most_one_face_in_a_hundred_stretched_threefold(name):
    """On the rubber skeleton the capsules bend along their links' curves. Before, 31-33 % of the
    iClone faces (9 % on 3ds Max, 6 % on MocapBank) stretched more than 3x; now at most 0.6 %
    do, where iClone's ankles turn the lowest shin sub-joints towards the foot. The bound keeps
    that margin and fails on any return of welds or cross-limb weights."""
    motion, body = body_of(shared(name))
    result = run(motion, load_preset("cartoon"))
    bound = output_skin(motion, result, body)
    out = result.motion.skeleton
    index = np.array([out.index(n) for n in bound.joint_names])
    count = result.world_positions.shape[0]
    frames = np.unique(np.linspace(0, count - 1, min(count, 150)).astype(int))
    stretch = edge_stretch(bound, out.rest_positions(), result.world_rotations, result.world_positions, index, frames)
    assert np.mean(stretch > 3.0) < 0.01


def _star(children: int) -> Skeleton:
    rng = np.random.default_rng(7)
    offsets = np.vstack([np.zeros(3), rng.normal(size=(children, 3))])
    return Skeleton(tuple(f"j{i}" for i in range(children + 1)), np.array([-1] + [0] * children), offsets,
                    tuple(("Xrotation", "Yrotation", "Zrotation") for _ in range(children + 1)),
                    np.full((children + 1, 3), np.nan))


def test_a_root_with_hundreds_of_children_stays_bounded_and_closed():
    body = default_skin(_star(600))
    assert body.num_vertices < 20_000
    mesh = trimesh.Trimesh(body.vertices, body.faces, process=False)
    assert mesh.is_watertight and mesh.volume > 0


def test_a_lone_root_is_a_ball():
    body = default_skin(_star(0))
    mesh = trimesh.Trimesh(body.vertices, body.faces, process=False)
    assert mesh.is_watertight and mesh.volume > 0 and np.all(body.joints == 0)
