"""Issue 23, points 1 and 2: the rubber sub-joints' frames follow their sub-links, and the skin's
weights follow the rubber (by where a vertex lies along its chain, never onto an unrelated link)."""

from __future__ import annotations

import numpy as np
import pytest

from mocap_exaggerate.config import resolve_config
from mocap_exaggerate.core.skeleton import Skeleton
from mocap_exaggerate.io.bvh import format_bvh, read_bvh
from mocap_exaggerate.pipeline import run
from mocap_exaggerate.rig.skinning import Skin, reweight, subjoint_bind_positions
from mocap_exaggerate.stages.subjoints import SubjointConfig, build_hierarchy, link_starts

from .helpers import SAMPLE_DIR, all_clip_params, assert_same_bits_or_ulps

IDENTITY = {"extrapolate": {"omega": 1.0}, "correct": {"enabled": False}, "springs": {"enabled": False},
            "contacts": {"enabled": False}}


def bone_misalignment(motion, hierarchy) -> np.ndarray:
    """Degrees between each single child's translation and its OFFSET, over the frames, for every
    joint of the rubber chains with one child at a distance ((F, n) array)."""
    skeleton = motion.skeleton
    children = np.bincount(skeleton.parents[1:], minlength=skeleton.num_joints)
    height = skeleton.height()
    picked = [c for c in range(1, skeleton.num_joints)
              if children[skeleton.parents[c]] == 1 and np.linalg.norm(skeleton.offsets[c]) > 1e-4 * height
              and not hierarchy.rigid[hierarchy.link_child[c]]]
    moved = motion.local_positions[:, picked]
    rest = skeleton.offsets[picked]
    cosine = np.sum(moved * rest, -1) / (np.linalg.norm(moved, axis=-1) * np.linalg.norm(rest, axis=-1))
    return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))


@pytest.mark.parametrize("setting", ["identity", "looney"])
@pytest.mark.parametrize("path", all_clip_params())
def test_every_rubber_bone_points_along_its_sub_link_in_the_written_file(path, setting):
    # Before: 47-85 degrees at worst with no exaggeration (170-178 on iClone thighs), because the
    # sub-joints slerped between the original joints' orientations.
    motion, _ = read_bvh(path)
    overrides = IDENTITY if setting == "identity" else None
    result = run(motion, resolve_config("looney" if setting == "looney" else "cartoon", None, overrides))
    written, _ = read_bvh(format_bvh(result.motion))
    angles = bone_misalignment(written, result.hierarchy)
    assert angles.size and angles.max() <= 1.0, (path.name, setting, angles.max())
    if setting == "identity":  # and the original joints are the captured ones, orientations too
        captured_rot, captured_pos = motion.forward_kinematics()
        from mocap_exaggerate.core.rotations import quat_angle

        assert np.max(quat_angle(result.world_rotations[:, result.original_index], captured_rot)) <= 1e-6


def test_each_cut_link_starts_with_a_zero_length_joint_on_its_original_joint():
    skeleton = _body()
    plain = build_hierarchy(skeleton, SubjointConfig(per_link=3))
    rubber = link_starts(plain)
    names = rubber.skeleton.names
    assert names[:6] == ("Hips", "LeftUpLeg_s0", "LeftUpLeg_s1", "LeftUpLeg_s2", "LeftUpLeg", "LeftLeg_s0")
    starts = np.flatnonzero(rubber.fraction == 0.0)
    assert len(starts) == 8  # one per cut link
    assert not rubber.skeleton.offsets[starts].any()
    assert np.allclose(rubber.skeleton.rest_positions()[rubber.original], skeleton.rest_positions())
    assert [names[j] for j in rubber.original] == list(skeleton.names)
    uncut = build_hierarchy(skeleton, SubjointConfig(per_link=1))
    assert link_starts(uncut) is uncut


def test_twist_between_the_ends_is_spread_along_the_link():
    # A straight arm whose hand turns 90 degrees about the forearm: the forearm's sub-joints take
    # 0, 1/4, 1/2, 3/4 of it, each bone still along the forearm.
    from mocap_exaggerate.core.rotations import quat_angle, quat_from_axis_angle, quat_rotate
    from mocap_exaggerate.stages.orient import curve_frames

    skeleton = Skeleton(("Shoulder", "Elbow", "Hand"), np.array([-1, 0, 1]),
                        np.array([[0.0, 0, 0], [1.0, 0, 0], [1.0, 0, 0]]),
                        tuple(("Zrotation", "Xrotation", "Yrotation") for _ in range(3)),
                        np.array([[np.nan] * 3, [np.nan] * 3, [0.2, 0, 0]]))
    rubber = link_starts(build_hierarchy(skeleton, SubjointConfig(per_link=4)))
    positions = subjoint_bind_positions(skeleton, rubber)[None].repeat(3, axis=0)
    world = np.zeros((3, 3, 4))
    world[..., 3] = 1.0
    world[:, 2] = quat_from_axis_angle("X", np.radians([90.0, 90.0, 90.0]))
    frames = curve_frames(world, positions, rubber)
    forearm = [rubber.skeleton.index(f"Hand_s{k}") for k in range(4)]
    turned = np.degrees(quat_angle(frames[1, forearm], world[1, 0]))
    assert np.allclose(turned, [0.0, 22.5, 45.0, 67.5], atol=1.5)  # eased over a frame: all three equal
    assert np.allclose(quat_rotate(frames[1, forearm], [1.0, 0, 0]), [1.0, 0, 0], atol=1e-9)
    assert np.allclose(frames[:, rubber.original], world)


def _body() -> Skeleton:
    """Hips with two legs and a spine, every link 1 long, legs along -Y, spine along +Y."""
    names = ("Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "RightUpLeg", "RightLeg", "RightFoot", "Spine", "Head")
    parents = np.array([-1, 0, 1, 2, 0, 4, 5, 0, 7])
    offsets = np.array([[0, 1, 0], [0.3, 0, 0], [0, -1, 0], [0, -1, 0], [-0.3, 0, 0], [0, -1, 0], [0, -1, 0],
                        [0, 1, 0], [0, 1, 0]], dtype=float)
    ends = np.full((9, 3), np.nan)
    ends[[3, 6]] = [0, 0, 0.2]
    ends[8] = [0, 0.3, 0]
    channels = tuple(("Zrotation", "Xrotation", "Yrotation") for _ in range(9))
    return Skeleton(names, parents, offsets, channels, ends)


def _weights_by_name(skin: Skin, vertex: int) -> dict[str, float]:
    return {skin.joint_names[j]: w for j, w in zip(skin.joints[vertex], skin.weights[vertex]) if w > 0}


def test_a_branch_joints_weight_stays_on_the_link_a_vertex_lies_by_on_a_skin_made_per_link():
    skeleton = _body()
    rubber = link_starts(build_hierarchy(skeleton, SubjointConfig(per_link=4)))
    # Three vertices bound to the hips: by the left hip link, by the right one, up the spine, on a
    # skin made link by link (the default body's tubes): each follows its own link's sub-links.
    vertices = np.array([[0.25, 0.95, 0.1], [-0.25, 0.95, 0.1], [0.0, 1.5, 0.1]])
    skin = Skin(vertices, np.array([[0, 1, 2]]), ("Hips",), np.zeros((3, 1), np.int64), np.ones((3, 1)),
                per_link=True)
    out = reweight(skin, skeleton, rubber)
    left, right, spine = (_weights_by_name(out, v) for v in range(3))
    assert left and all(n.startswith("LeftUpLeg_s") for n in left), left
    assert right and all(n.startswith("RightUpLeg_s") for n in right), right
    assert spine and all(n.startswith("Spine_s") for n in spine), spine
    for weights in (left, right, spine):
        assert abs(sum(weights.values()) - 1.0) < 1e-12


def test_a_painted_characters_branch_joint_keeps_its_own_frame():
    # The same vertices on a painted character's skin: a belly, a buttock or the top of a shoulder
    # painted to the hips or the chest was shaped for that one rigid frame; handed to the sub-links
    # of the links it wraps it rolled and stretched with them (the MakeHuman body tore more on the
    # rubber skeleton than on straight links, with no exaggeration at all). It stays on the joint.
    skeleton = _body()
    rubber = link_starts(build_hierarchy(skeleton, SubjointConfig(per_link=4)))
    vertices = np.array([[0.25, 0.95, 0.1], [-0.25, 0.95, 0.1], [0.0, 1.5, 0.1]])
    skin = Skin(vertices, np.array([[0, 1, 2]]), ("Hips", "Spine"), np.array([[0, 1]] * 3),
                np.array([[1.0, 0.0], [1.0, 0.0], [0.5, 0.5]]))
    out = reweight(skin, skeleton, rubber)
    assert _weights_by_name(out, 0) == pytest.approx({"Hips": 1.0})
    assert _weights_by_name(out, 1) == pytest.approx({"Hips": 1.0})
    # The spine's own half still follows its link's sub-links (a chain joint, not a branch).
    spine = _weights_by_name(out, 2)
    assert spine["Hips"] == pytest.approx(0.5)
    assert sum(w for n, w in spine.items() if n.startswith(("Head_s", "Spine_s"))) == pytest.approx(0.5)


def test_coincident_sibling_links_are_told_apart_by_the_links_after_them():
    # On a skin made per link (the default body): an Assimp or mocapbank chest starts the neck and
    # both collars at one point and ends them at another, so every vertex is as near to one as to
    # the others. A vertex on the neck goes to the neck (it continues to the head), one over a
    # shoulder to that collar (it continues to the arm); an even three-way split tore the neck 48x
    # on a looney crouch.
    names = ("Chest", "Neck", "Head", "LeftCollar", "LeftShoulder", "RightCollar", "RightShoulder")
    parents = np.array([-1, 0, 1, 0, 3, 0, 5])
    offsets = np.array([[0, 1, 0], [0, 0.2, 0], [0, 0.2, 0], [0, 0.2, 0], [0.3, 0, 0], [0, 0.2, 0],
                        [-0.3, 0, 0]], dtype=float)
    ends = np.full((7, 3), np.nan)
    ends[[2, 4, 6]] = [[0, 0.2, 0], [0.3, 0, 0], [-0.3, 0, 0]]
    channels = tuple(("Zrotation", "Xrotation", "Yrotation") for _ in range(7))
    skeleton = Skeleton(names, parents, offsets, channels, ends)
    rubber = link_starts(build_hierarchy(skeleton, SubjointConfig(per_link=4)))
    chest = skeleton.rest_positions()[0]
    vertices = chest + np.array([[0.0, 0.1, 0.05], [0.15, 0.17, 0.05], [-0.15, 0.17, 0.05]])
    skin = Skin(vertices, np.array([[0, 1, 2]]), ("Chest",), np.zeros((3, 1), np.int64), np.ones((3, 1)),
                per_link=True)
    out = reweight(skin, skeleton, rubber)
    neck, left, right = (_weights_by_name(out, v) for v in range(3))
    assert neck and sum(w for n, w in neck.items() if n.startswith("Neck_s")) > 0.99, neck
    assert left and sum(w for n, w in left.items() if n.startswith("LeftCollar_s")) > 0.99, left
    assert right and sum(w for n, w in right.items() if n.startswith("RightCollar_s")) > 0.99, right


def test_a_knee_blends_the_thigh_into_the_shin():
    skeleton = _body()
    rubber = link_starts(build_hierarchy(skeleton, SubjointConfig(per_link=4)))
    # Bound wholly to the thigh (LeftUpLeg), at the knee: half on the thigh's last sub-link, half on
    # the shin's first; at the thigh's middle: all on the sub-links there.
    hip_y, knee_y = skeleton.rest_positions()[1:3, 1]
    # At the knee; at the peak of the thigh's second sub-link; at the shin's first, still bound to the thigh.
    vertices = np.array([[0.35, knee_y, 0.05], [0.35, hip_y - 0.375, 0.05], [0.35, knee_y - 0.125, 0.05]])
    skin = Skin(vertices, np.array([[0, 1, 2]]), ("LeftUpLeg",), np.zeros((3, 1), np.int64), np.ones((3, 1)))
    out = reweight(skin, skeleton, rubber)
    knee, middle, below = (_weights_by_name(out, v) for v in range(3))
    assert knee == pytest.approx({"LeftLeg_s3": 0.5, "LeftFoot_s0": 0.5})  # thigh's last, shin's first
    assert middle == pytest.approx({"LeftLeg_s1": 1.0})
    assert below == pytest.approx({"LeftFoot_s0": 1.0})


def test_a_stretched_straight_chain_stretches_its_skin_evenly():
    # Linear blend skinning of a uniformly stretched straight chain: with each owner peaking at its
    # sub-link's middle, the distance between any two vertices along the chain stretches by exactly
    # the chain's factor (with the old inverse-distance shares it did not).
    skeleton = _body()
    rubber = link_starts(build_hierarchy(skeleton, SubjointConfig(per_link=4)))
    bind = subjoint_bind_positions(skeleton, rubber)
    hip = bind[rubber.original[1]]
    ys = np.linspace(hip[1] - 0.2, hip[1] - 1.8, 9)
    vertices = np.stack([np.full(9, hip[0] + 0.05), ys, np.zeros(9)], axis=1)
    owners = np.where(ys > hip[1] - 1.0, 1, 2)  # the thigh's joint above the knee, the shin's below
    skin = Skin(vertices, np.array([[0, 1, 2]]), ("LeftUpLeg", "LeftLeg"), owners[:, None] - 1, np.ones((9, 1)))
    out = reweight(skin, skeleton, rubber)
    factor = 1.7
    posed = bind.copy()
    posed[:, 1] = hip[1] + factor * (bind[:, 1] - hip[1])  # every joint of the leg slides down the line
    moved = np.einsum("vk,vkc->vc", out.weights, vertices[:, None] + (posed - bind)[out.joints])
    steps = np.diff(moved[:, 1])
    assert np.allclose(steps, factor * np.diff(ys), rtol=1e-9)


def test_skin_at_a_branch_joint_keeps_the_joints_own_frame():
    # At the hips themselves (behind every link's head) a vertex bound to the hips stays on them:
    # shared among the first sub-joints of both legs and the spine, it tore the crotch 5x on a run.
    skeleton = _body()
    rubber = link_starts(build_hierarchy(skeleton, SubjointConfig(per_link=4)))
    hips = skeleton.rest_positions()[0]
    vertices = hips + np.array([[0.0, -0.05, 0.1], [0.0, 0.0, -0.1], [0.0, -0.01, 0.0]])
    skin = Skin(vertices, np.array([[0, 1, 2]]), ("Hips",), np.zeros((3, 1), np.int64), np.ones((3, 1)))
    out = reweight(skin, skeleton, rubber)
    for v in range(3):
        assert _weights_by_name(out, v) == pytest.approx({"Hips": 1.0})


def test_a_stretched_chain_stretches_its_skin_evenly_into_its_end_joint():
    # On to the foot (an end joint): the shin's last sub-link hands over to the foot's own frame half a
    # sub-link past the ankle, so the skin across the ankle stretches as the rest of the leg does and
    # past that moves with the foot (the old shares left the last half sub-link unstretched and
    # tore the skin against the foot's).
    skeleton = _body()
    rubber = link_starts(build_hierarchy(skeleton, SubjointConfig(per_link=4)))
    bind = subjoint_bind_positions(skeleton, rubber)
    hip = bind[rubber.original[1]]
    ys = np.linspace(hip[1] - 1.1, hip[1] - 2.125, 11)  # from below the knee to half a sub-link past the ankle
    below = hip[1] - np.array([2.2, 2.3])  # farther down: the foot's
    vertices = np.stack([np.full(13, hip[0] + 0.05), np.concatenate([ys, below]), np.zeros(13)], axis=1)
    skin = Skin(vertices, np.array([[0, 1, 2]]), ("LeftLeg",), np.zeros((13, 1), np.int64), np.ones((13, 1)))
    out = reweight(skin, skeleton, rubber)
    assert _weights_by_name(out, 10) == pytest.approx({"LeftFoot": 1.0})
    factor = 1.7
    posed = bind.copy()
    posed[:, 1] = hip[1] + factor * (bind[:, 1] - hip[1])
    moved = np.einsum("vk,vkc->vc", out.weights, vertices[:, None] + (posed - bind)[out.joints])
    assert np.allclose(np.diff(moved[:11, 1]), factor * np.diff(ys), rtol=1e-9)
    foot = posed[rubber.original[3]] - bind[rubber.original[3]]
    assert np.allclose(moved[11:], vertices[11:] + foot, atol=1e-12)


@pytest.mark.parametrize("name", ["cmu_09_01_run_daz", "cmu_16_01_jump_amc2bvh", "mocapbank_sit_down_stand_up"])
def test_a_limbs_sub_links_stretch_evenly_after_the_springs_and_contacts(name):
    # The springs' lag and the contacts' bending bunched sub-joints along a link: the middle sub-link
    # of a run's thigh stretched 1.47x its neighbours' mean (tearing the skin on it). Spread again
    # evenly along the bend, no sub-link of a real link is 8 % longer than its link's mean.
    from mocap_exaggerate.config import load_preset

    motion, _ = read_bvh(SAMPLE_DIR / f"{name}.bvh")
    result = run(motion, load_preset("looney"))
    rubber, positions = result.hierarchy, result.motion.forward_kinematics()[1]
    parents = np.asarray(rubber.skeleton.parents)
    lengths, height = motion.skeleton.link_lengths(), motion.skeleton.height()
    for child in np.unique(rubber.link_child[~rubber.is_original]):
        if lengths[child] < 0.1 * height:
            continue
        cut = np.flatnonzero((rubber.link_child == child) & ~rubber.is_original & (rubber.fraction > 0))
        cut = cut[np.argsort(rubber.fraction[cut])]
        chain = [parents[cut[0]], *cut, rubber.original[child]]
        sub_links = np.linalg.norm(np.diff(positions[:, chain], axis=1), axis=2)
        spread = (sub_links.max(axis=1) / sub_links.mean(axis=1)).max()
        assert spread < 1.08, (motion.skeleton.names[child], spread)


def _orient_inputs(path, preset: str):
    """What the orient stage hands `curve_frames` on a clip: the original joints' orientations, the
    rubber skeleton's positions and its hierarchy (caught from a real run)."""
    from mocap_exaggerate.config import load_preset
    from mocap_exaggerate.stages import orient

    caught = {}
    real = orient.curve_frames

    def catch(world, positions, hierarchy, **options):
        caught["inputs"] = (world.copy(), positions.copy(), hierarchy)
        return real(world, positions, hierarchy, **options)

    orient.curve_frames = catch
    try:
        run(read_bvh(path)[0], load_preset(preset))
    finally:
        orient.curve_frames = real
    return caught["inputs"]


@pytest.mark.parametrize("preset", ["subtle", "looney"])
@pytest.mark.parametrize("path", all_clip_params())
def test_the_compiled_kernels_give_numpys_bits(path, preset):
    """core/_kernels.c (forward kinematics, world to local, the frames carried along the rubber links and
    the twist spread along them) against the NumPy code it replaces, on every clip: the same bits, so an
    install without a C compiler writes the same bytes. (Built without fused multiply-add, each operation
    in NumPy's order; the twist's sine and cosine the C library's, which are NumPy's where it has no
    vector loop of its own for them, as here.)"""
    from mocap_exaggerate.core import kinematics
    from mocap_exaggerate.stages.orient import curve_frames

    if kinematics._kernels is None:
        pytest.skip("core/_kernels.c was not built (no C compiler at install); the NumPy code is what runs")
    world, positions, hierarchy = _orient_inputs(path, preset)
    fast = curve_frames(world.copy(), positions, hierarchy)
    slow = curve_frames(world.copy(), positions, hierarchy, compiled=False)
    assert_same_bits_or_ulps(fast, slow)  # the twist's sine and cosine are the C library's
    parents = hierarchy.skeleton.parents if len(positions[0]) == hierarchy.skeleton.num_joints else None
    parents = link_starts(hierarchy).skeleton.parents if parents is None else parents
    ours = kinematics.local_from_world(parents, fast, positions)
    theirs = kinematics.local_from_world(parents, fast, positions, compiled=False)
    assert np.array_equal(ours[0], theirs[0]) and np.array_equal(ours[1], theirs[1])
    overwritten = fast.copy()
    assert np.array_equal(kinematics.local_from_world(parents, overwritten, positions, overwrite_rotations=True)[0],
                          theirs[0])
    world = kinematics.forward_kinematics(parents, *ours)
    again = kinematics.forward_kinematics(parents, *ours, compiled=False)
    assert np.array_equal(world[0], again[0]) and np.array_equal(world[1], again[1])
    assert np.array_equal(kinematics.forward_kinematics(parents, ours[0][:1], ours[1][:1])[1], again[1][:1])


def test_the_compiled_kernels_are_built_where_ci_runs_and_refuse_what_they_cannot_read():
    """.ci/run installs on a machine with a C compiler: the kernels must be there. They check every
    buffer and index they are given (a ValueError, never a read outside an array)."""
    from mocap_exaggerate.core import kinematics, native

    if not native.ENABLED:
        pytest.skip(f"{native.NUMPY_ONLY} is set: the NumPy code runs")
    assert kinematics._kernels is not None, "core/_kernels.c was not built: pip install -e . (setup.py builds it)"
    kernels = kinematics._kernels
    parents = np.array([-1, 0, 1])
    rot, pos = np.tile([0.0, 0, 0, 1], (2, 3, 1)), np.zeros((2, 3, 3))
    with pytest.raises(ValueError, match="parents"):
        kernels.local_from_world(np.array([-1, 2, 1]), rot, pos, rot.copy(), pos.copy(), 2, 3)
    with pytest.raises(ValueError, match="world_pos"):
        kernels.local_from_world(parents, rot, pos[:1], rot.copy(), pos.copy(), 2, 3)
    with pytest.raises(ValueError, match="world_rot"):
        kernels.local_from_world(parents, rot.astype(np.float32), pos, rot.copy(), pos.copy(), 2, 3)
    with pytest.raises(ValueError, match="pos"):
        kernels.forward_kinematics(parents, rot.copy(), pos[:1].copy(), 2, 3)
    with pytest.raises(ValueError, match="parents"):
        kernels.forward_kinematics(np.array([0, 0, 1]), rot.copy(), pos.copy(), 2, 3)
    with pytest.raises(ValueError, match="outside"):
        kernels.chain_frames(rot.copy(), pos, np.array([0]), np.array([1]), np.array([2]), np.zeros((1, 3)), 2, 3, 1)
    # Sizes and indices whose sums or products would wrap (a review found a crash and reads past the arrays):
    with pytest.raises(ValueError, match="outside"):
        kernels.chain_frames(rot.copy(), pos, np.array([0]), np.array([2]), np.array([2**63 - 1]), np.zeros((1, 3)),
                             2, 3, 1)
    with pytest.raises(ValueError, match="count|buffer"):
        kernels.chain_frames(rot.copy(), pos, np.array([0]), np.array([1]), np.array([1]), np.zeros((1, 3)), 2, 3,
                             2**61 + 1)
    with pytest.raises(ValueError, match="count|buffer"):
        kernels.forward_kinematics(np.array([-1]), np.zeros((0, 4)), np.zeros((0, 3)), 0, 2**61 + 1)
    with pytest.raises(ValueError, match="count|buffer"):
        kernels.local_from_world(np.array([-1]), rot, pos, rot.copy(), pos.copy(), 2**40, 2**40)
    with pytest.raises(ValueError, match="contiguous"):  # (NumPy's own refusal to lend a strided view)
        kernels.chain_frames(rot[:, ::2], pos, np.array([0]), np.array([1]), np.array([1]), np.zeros((1, 3)), 2, 3, 1)
    with pytest.raises(ValueError, match="read-only"):  # an output NumPy will not lend for writing
        frozen = rot.copy()
        frozen.setflags(write=False)
        kernels.chain_frames(frozen, pos, np.array([0]), np.array([1]), np.array([1]), np.zeros((1, 3)), 2, 3, 1)
    # The twist along the links and the Euler angles read from a clip:
    angle = np.zeros((2, 1))
    with pytest.raises(ValueError, match="outside"):
        kernels.twist_frames(rot.copy(), angle, np.array([1]), np.array([3]), np.zeros((1, 3)), 2, 3, 1)
    with pytest.raises(ValueError, match="outside"):
        kernels.twist_frames(rot.copy(), angle, np.array([-1]), np.array([1]), np.zeros((1, 3)), 2, 3, 1)
    with pytest.raises(ValueError, match="angle"):
        kernels.twist_frames(rot.copy(), angle[:1], np.array([0]), np.array([2]), np.zeros((1, 3)), 2, 3, 1)
    with pytest.raises(ValueError, match="count|buffer"):
        kernels.twist_frames(rot.copy(), angle, np.array([0]), np.array([2]), np.zeros((1, 3)), 2, 3, 2**61 + 1)
    codes = np.array([[2, 0, 1, 1]] * 3)
    with pytest.raises(ValueError, match="three different axes"):
        kernels.quat_from_euler(pos, rot.copy(), np.array([[2, 0, 1, 1], [0, 0, 1, 1], [2, 0, 1, 1]]), 2, 3)
    with pytest.raises(ValueError, match="three different axes"):
        kernels.quat_from_euler(pos, rot.copy(), np.array([[2, 0, 1, 3]] * 3), 2, 3)
    with pytest.raises(ValueError, match="euler"):
        kernels.quat_from_euler(pos[:1], rot.copy(), codes, 2, 3)
    with pytest.raises(ValueError, match="count|buffer"):
        kernels.quat_from_euler(pos, rot.copy(), codes, 2**40, 2**40)
    carried = (np.zeros((3, 3)), np.zeros(3, np.int64), np.zeros((3, 3)), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="parity"):
        kernels.euler_continuity(pos.copy(), carried[0], np.zeros(3), *carried[2:], 2, 3, False)
    with pytest.raises(ValueError, match="first"):
        kernels.euler_continuity(pos[:1].copy(), *carried, 2, 3, False)
    with pytest.raises(ValueError, match="count|buffer"):
        kernels.euler_continuity(pos.copy(), *carried, 2**40, 2**40, False)
    kernels.quat_from_euler(pos, rot, np.full((3, 4), -1), 2, 3)  # every joint left as it is
    assert np.array_equal(rot, np.tile([0.0, 0, 0, 1], (2, 3, 1)))
