"""Binding a character made for another rig: joint pairing across naming conventions, the fit to the
clip's rest pose, the MakeHuman body on real clips, --joint-map and its bad input."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from mocap_exaggerate.core.errors import ConfigError, InputError
from mocap_exaggerate.io.bvh import read_bvh
from mocap_exaggerate.io.skin import load_skin
from mocap_exaggerate.jobs.outputs import at_bind_pose
from mocap_exaggerate.rig.binding import bind_skin, joint_roles, pair_joints, read_joint_map, skin_skeleton
from mocap_exaggerate.rig.body import default_skin
from mocap_exaggerate.rig.skinning import Skin, pose_skin

from .helpers import ROOT, SAMPLE_DIR, SHARED_BVH, shared

SKIN_DIR = SHARED_BVH.parent / "skin"
needs_makehuman = pytest.mark.skipif(not (SKIN_DIR / "makehuman_base.obj").exists(),
                                     reason=f"the MakeHuman body is not at {SKIN_DIR} (../shared/data/skin)")
CLI = [sys.executable, "-m", "mocap_exaggerate_cli.main"]

#: What every humanoid rig among the shared clips must show, whatever its naming convention.
ROLES = {"hips", "head"} | {f"{side}_{part}" for side in ("left", "right")
                           for part in ("upper_arm", "forearm", "hand", "thigh", "shin", "foot")}


@pytest.fixture(scope="module")
def makehuman() -> Skin:
    return load_skin(SKIN_DIR / "makehuman_base.obj")


def all_clips():
    clips = sorted(SHARED_BVH.glob("*.bvh")) if SHARED_BVH.is_dir() else []
    return clips or [pytest.param(None, marks=pytest.mark.skip(reason=f"no shared clips at {SHARED_BVH}"))]


def clip_motion(path):
    return read_bvh(path.read_bytes(), fps=120 if "amc2bvh" in path.name else None)[0]


@needs_makehuman
def test_the_makehuman_rig_shows_every_role_past_its_split_bones(makehuman):
    """MakeHuman cuts each long bone in two (upperarm01/02.L): the upper arm starts at 01, the hand
    is the wrist after lowerarm02, the clavicle is the joint on the spine, not shoulder01 below it."""
    rig = skin_skeleton(makehuman)
    roles, chains = joint_roles(rig)
    named = {role: rig.names[j] for role, j in roles.items()}
    assert named["left_upper_arm"] == "upperarm01.L" and named["left_forearm"] == "lowerarm01.L"
    assert named["left_hand"] == "wrist.L" and named["left_clavicle"] == "clavicle.L"
    assert named["right_thigh"] == "upperleg01.R" and named["right_foot"] == "foot.R"
    assert named["hips"] == "root" and named["head"] == "head"
    assert [rig.names[j] for j in chains["spine"]] == ["spine05", "spine04", "spine03", "spine02", "spine01"]


@needs_makehuman
@pytest.mark.parametrize("path", all_clips(), ids=lambda p: getattr(p, "stem", "none"))
def test_every_shared_rig_pairs_its_main_joints_with_the_makehuman_body(path, makehuman):
    """CMU, Daz, iClone, 3ds Max, assimp, MocapBank and the old MakeHuman game rig: the main joints of
    each pair with the MakeHuman body's by role, side for side."""
    skeleton = clip_motion(path).skeleton
    roles, _ = joint_roles(skeleton)
    assert ROLES <= set(roles), ROLES - set(roles)
    binding = pair_joints(skeleton, makehuman)
    skin_roles, _ = joint_roles(skin_skeleton(makehuman))
    rig = skin_skeleton(makehuman)
    for role in ROLES:
        assert binding.pairs[skeleton.names[roles[role]]] == rig.names[skin_roles[role]], role
    assert binding.unpaired_roles == ()


@needs_makehuman
@pytest.mark.parametrize("path", all_clips(), ids=lambda p: getattr(p, "stem", "none"))
def test_the_fitted_body_puts_each_paired_joint_where_the_clip_has_it(path, makehuman):
    """In the clip's rest pose, the fitted mesh around each paired joint sits where that joint is:
    the mesh is in the clip's units and axes, not MakeHuman's decimetres and Y up."""
    motion = clip_motion(path)
    bound, binding = bind_skin(makehuman, motion.skeleton)
    skeleton = at_bind_pose(motion, None, bound)[0].skeleton  # the rest posed as the body is bound
    assert set(bound.joint_names) <= set(skeleton.names)
    np.testing.assert_allclose(bound.weights.sum(axis=1), 1.0, atol=1e-9)
    rest = skeleton.rest_positions()
    height = skeleton.height()
    # Each paired skin joint, carried by its own bone's map, lands on the clip's joint; checked through
    # the vertex groups MakeHuman places its joints by (the mean of a group is the joint).
    rig = json.loads((SKIN_DIR / "makehuman_default.mhskel").read_text())
    moved = bound.vertices
    # Vertices of the body group keep their order: compare heads found as means of the same vertices.
    obj_index = _body_vertex_index()
    for clip_name, skin_name in binding.pairs.items():
        group = rig["joints"][rig["bones"][skin_name]["head"]]
        rows = obj_index[np.asarray(group)]
        rows = rows[rows >= 0]
        if len(rows) < 3:
            continue  # a head joint marked by helper geometry only
        assert np.all(np.isfinite(moved[rows]))
        error = np.linalg.norm(moved[rows].mean(axis=0) - rest[skeleton.index(clip_name)])
        assert error < 0.06 * height, (clip_name, skin_name, error / height)
    # The body is the clip's size along its up axis: the skeleton's height, a little more for the skull
    # above the head joint and the soles.
    up = skeleton.up_axis()
    assert np.ptp(moved[:, up]) == pytest.approx(height, rel=0.3)


_INDEX = None


def _body_vertex_index() -> np.ndarray:
    """OBJ vertex index -> row of the loaded body (-1 for helper geometry the loader drops)."""
    global _INDEX
    if _INDEX is None:
        used = set()
        group = None
        total = 0
        for line in (SKIN_DIR / "makehuman_base.obj").read_text().splitlines():
            if line.startswith("v "):
                total += 1
            elif line.startswith("g "):
                group = line[2:].strip()
            elif line.startswith("f ") and group == "body":
                used.update(int(p.split("/")[0]) - 1 for p in line.split()[1:])
        keep = np.array(sorted(used))
        _INDEX = np.full(total, -1)
        _INDEX[keep] = np.arange(len(keep))
    return _INDEX


@needs_makehuman
@pytest.mark.parametrize("name", ["cmu_12_01_walk.bvh", "cmu_09_01_run_daz.bvh", "assimp_boxing_toes.bvh",
                                  "cmu_06_15_basketball_dribble_shoot_iclone.bvh"])
def test_the_body_stays_on_the_skeleton_through_the_captured_motion(name, makehuman):
    """Posed by the clip at a dozen frames, every vertex of the fitted body stays within a body's
    girth of the skeleton, and few faces stretch (the price of linear blend skinning at shoulders)."""
    from scipy.spatial import cKDTree

    from mocap_exaggerate.rig.skinning import segment_distance

    motion = clip_motion(shared(name))
    motion, _, bound = at_bind_pose(motion, None, bind_skin(makehuman, motion.skeleton)[0])
    skeleton = motion.skeleton
    rotations, positions = motion.forward_kinematics()
    index = np.array([skeleton.index(n) for n in bound.joint_names])
    edges = np.concatenate([bound.faces[:, [0, 1]], bound.faces[:, [1, 2]], bound.faces[:, [2, 0]]])
    rest_length = np.linalg.norm(np.diff(bound.vertices[edges], axis=1)[:, 0], axis=1)
    height = skeleton.height()
    parents = skeleton.parents
    worst = np.zeros(len(bound.faces))
    for frame in np.linspace(0, motion.num_frames - 1, 12).astype(int):
        posed = pose_skin(bound, skeleton.rest_positions(), rotations[frame], positions[frame], index)
        # Distance to the nearest bone (segment parent -> joint), not only the nearest joint.
        heads, tails = positions[frame][parents[1:]], positions[frame][1:]
        near = cKDTree(positions[frame]).query(posed, k=4)[1]
        candidates = np.unique(np.concatenate([near.ravel() - 1, near.ravel()]))
        candidates = candidates[(candidates >= 0) & (candidates < len(tails))]
        distance = segment_distance(posed[:, None, :], heads[candidates][None], tails[candidates][None]).min(axis=1)
        assert distance.max() < 0.2 * height, (frame, distance.max() / height)
        ratio = np.linalg.norm(np.diff(posed[edges], axis=1)[:, 0], axis=1) / rest_length
        worst = np.maximum(worst, ratio.reshape(3, -1).max(axis=0))
    assert np.mean(worst > 2.0) < 0.02  # measured 0.07-0.9 % on these rigs (bench/binding.py)


@needs_makehuman
def test_the_makehuman_body_on_its_own_clip_pairs_every_bone_by_name(makehuman):
    motion = read_bvh(SKIN_DIR / "makehuman_default_tpose.bvh")[0]
    bound, binding = bind_skin(makehuman, motion.skeleton)
    assert len(binding.pairs) == len(makehuman.bind)  # all 163 bones of the .mhskel
    assert set(binding.how.values()) <= {"name", "role"}
    assert binding.scale == pytest.approx(1.0, abs=0.02)  # the same body: no resizing


def test_a_skin_already_on_the_clip_comes_back_unchanged(sample_clip):
    """The default body (no bind pose of its own), or one whose bind pose is the rest pose: as it is."""
    motion, _ = read_bvh(sample_clip)
    body = default_skin(motion.skeleton)
    same, binding = bind_skin(body, motion.skeleton)
    assert same is body and binding is None
    rest = motion.skeleton.rest_positions()
    posed = Skin(body.vertices, body.faces, body.joint_names, body.joints, body.weights,
                 {n: rest[j] for j, n in enumerate(motion.skeleton.names)})
    assert bind_skin(posed, motion.skeleton)[0] is posed


def test_a_body_moved_turned_and_scaled_is_fitted_back_onto_the_clip(sample_clip):
    """Known answer: the default body of a clip, turned a quarter turn, scaled 10x and shifted, with its
    bind pose and hierarchy said: binding it to the clip gives the original body back."""
    motion, _ = read_bvh(sample_clip)
    skeleton = motion.skeleton
    body = default_skin(skeleton)
    turn = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # Y up -> Z up
    moved = lambda p: 10.0 * np.asarray(p) @ turn.T + np.array([3.0, -7.0, 50.0])  # noqa: E731
    rest = skeleton.rest_positions()
    parents = {n: skeleton.names[skeleton.parents[j]] for j, n in enumerate(skeleton.names) if j > 0}
    other = Skin(moved(body.vertices), body.faces, body.joint_names, body.joints, body.weights,
                 {n: moved(rest[j]) for j, n in enumerate(skeleton.names)}, parents)
    bound, binding = bind_skin(other, skeleton)
    assert binding.scale == pytest.approx(0.1, rel=1e-6)
    np.testing.assert_allclose(bound.vertices, body.vertices, atol=1e-6 * skeleton.height())
    np.testing.assert_array_equal([bound.joint_names[j] for j in bound.joints[:, 0]],
                                  [body.joint_names[j] for j in body.joints[:, 0]])


def test_a_forearm_made_shorter_is_stretched_back_along_itself(sample_clip):
    """Known answer for the per-bone fit: a character whose left forearm is 1/1.5 the clip's (its
    capsule squeezed along the bone, the hand and fingers moved up to meet it) is fitted back onto
    the clip's body exactly, the forearm stretched 1.5x along itself and the hand moved, not bent."""
    motion, _ = read_bvh(sample_clip)
    skeleton = motion.skeleton
    body = default_skin(skeleton)
    roles, _ = joint_roles(skeleton)
    fore, hand = roles["left_forearm"], roles["left_hand"]
    rest = skeleton.rest_positions()
    axis = (rest[hand] - rest[fore]) / np.linalg.norm(rest[hand] - rest[fore])
    squeeze = np.eye(3) + (1 / 1.5 - 1.0) * np.outer(axis, axis)
    shift = (1 / 1.5 - 1.0) * (rest[hand] - rest[fore])
    below = set(skeleton.descendants(hand).tolist())
    # Each vertex moved by its joints' moves, blended by its weights (the tubes bend at the wrist).
    owner = np.array([skeleton.index(n) for n in body.joint_names])[body.joints]  # (V, 4)
    squeezed = rest[fore] + (body.vertices - rest[fore]) @ squeeze.T
    moved = np.where((owner == fore)[..., None], squeezed[:, None], body.vertices[:, None])
    moved = moved + np.isin(owner, list(below))[..., None] * shift
    vertices = np.sum(body.weights[..., None] * moved, axis=1)
    bind = {n: rest[j] + (shift if j in below else 0.0) for j, n in enumerate(skeleton.names)}
    parents = {n: skeleton.names[skeleton.parents[j]] for j, n in enumerate(skeleton.names) if j > 0}
    other = Skin(vertices, body.faces, body.joint_names, body.joints, body.weights, bind, parents)
    bound, binding = bind_skin(other, skeleton)
    assert binding.scale == pytest.approx(1.0, abs=1e-9)
    single = body.weights.max(axis=1) == 1.0  # exact where one joint holds a vertex
    np.testing.assert_allclose(bound.vertices[single], body.vertices[single], atol=1e-6 * skeleton.height())
    np.testing.assert_allclose(bound.vertices, body.vertices, atol=0.01 * skeleton.height())


@needs_makehuman
def test_a_glb_this_tool_wrote_is_a_character_for_another_rig(tmp_path):
    """Our own rubber GLB of a Daz clip, as the skin of a CMU walk: its sub-joints (lShin_s1 ...)
    are pieces of their links, not knees, so the knee pairs with the knee and the foot with the foot."""
    from mocap_exaggerate.config import load_preset
    from mocap_exaggerate.jobs.outputs import make_glb
    from mocap_exaggerate.pipeline import run

    daz, _ = read_bvh(SAMPLE_DIR / "cmu_09_01_run_daz.bvh")
    glb, _, _ = make_glb(daz, run(daz, load_preset("cartoon")))
    (tmp_path / "daz.glb").write_bytes(glb)
    walk = clip_motion(shared("cmu_12_01_walk.bvh"))
    binding = pair_joints(walk.skeleton, load_skin(tmp_path / "daz.glb"))
    for clip_joint, skin_joint in [("LeftLeg", "lShin"), ("LeftFoot", "lFoot"), ("RightHand", "rHand"),
                                   ("RightForeArm", "rForeArm"), ("Head", "head"), ("Hips", "hip")]:
        assert binding.pairs[clip_joint] == skin_joint, clip_joint


def test_skins_that_cannot_be_placed_are_refused_saying_why(sample_clip):
    motion, _ = read_bvh(sample_clip)
    skeleton = motion.skeleton
    body = default_skin(skeleton)
    rest = skeleton.rest_positions()
    names = skeleton.names
    in_one_place = Skin(body.vertices, body.faces, body.joint_names, body.joints, body.weights,
                        {n: np.zeros(3) for n in names})
    with pytest.raises(ConfigError, match="all sit in one place"):
        bind_skin(in_one_place, skeleton, {n: n for n in names[:5]})
    spine = [skeleton.index(n) for n in ("hip", "abdomen", "chest", "neck", "head")]
    on_a_line = Skin(body.vertices, body.faces, body.joint_names, body.joints, body.weights,
                     {names[j]: rest[j] * [0, 1, 0] for j in spine})
    with pytest.raises(ConfigError, match="lie on one line"):
        bind_skin(on_a_line, skeleton, {names[j]: names[j] for j in spine})
    with pytest.raises(ConfigError, match=r"this skin \(an .npz\) has no bind pose"):
        bind_skin(body, skeleton, {"hip": "hip"})


def test_a_joint_map_pairs_what_names_and_roles_cannot(sample_clip):
    """A skin whose joints have meaningless names and no hierarchy: nothing pairs; a joint map names them."""
    motion, _ = read_bvh(sample_clip)
    skeleton = motion.skeleton
    body = default_skin(skeleton)
    rest = skeleton.rest_positions()
    alias = {n: f"bone{j:03d}" for j, n in enumerate(skeleton.names)}
    other = Skin(body.vertices + 5.0, body.faces, [alias[n] for n in body.joint_names], body.joints, body.weights,
                 {alias[n]: rest[j] + 5.0 for j, n in enumerate(skeleton.names)})
    with pytest.raises(ConfigError, match=r"only 0 of the skin's joints could be paired.*--joint-map"):
        bind_skin(other, skeleton)
    bound, binding = bind_skin(other, skeleton, alias)
    assert set(binding.how.values()) == {"map"}
    np.testing.assert_allclose(bound.vertices, body.vertices, atol=1e-6 * skeleton.height())
    with pytest.raises(ConfigError, match="'Hipz', which is not a joint of the clip"):
        bind_skin(other, skeleton, {"Hipz": "bone000"})
    with pytest.raises(ConfigError, match="'bone999', which is not a joint of the skin"):
        bind_skin(other, skeleton, {skeleton.names[0]: "bone999"})


@pytest.mark.parametrize("text, message", [
    ("Hips thigh\n", r"map\.txt:1: expected 'clip joint = skin joint'"),
    ("# only a comment\n\n", "no 'clip joint = skin joint' lines"),
    ("A = b\nA = c\n", r"map\.txt:2: clip joint 'A' is named twice"),
    ("A = b\nC = b\n", r"map\.txt:2: skin joint 'b' is named twice \(first on line 1\)"),
    ("A = b = c\n", r"map\.txt:1: expected"),
    (" = b\n", r"map\.txt:1: expected"),
])
def test_bad_joint_map_files_are_refused_naming_the_line(tmp_path, text, message):
    path = tmp_path / "map.txt"
    path.write_text(text)
    with pytest.raises(InputError, match=message):
        read_joint_map(path)


def test_an_absurdly_long_name_in_a_joint_map_is_quoted_short(sample_clip, tmp_path):
    """A 100,000-character name is refused in a line of reasonable length, as users run it."""
    path = tmp_path / "map.txt"
    path.write_text("lThigh = " + "x" * 100_000 + "\n")
    done = subprocess.run([*CLI, "exaggerate", str(sample_clip), "-o", str(tmp_path / "o"), "--skin",
                           str(tmp_path / "body.glb"), "--joint-map", str(path)], capture_output=True, text=True,
                          cwd=ROOT, timeout=300)
    assert done.returncode == 2 and len(done.stderr) < 400  # the skin file is missing: said first, briefly
    motion, _ = read_bvh(sample_clip)
    body = default_skin(motion.skeleton)
    rest = motion.skeleton.rest_positions()
    other = Skin(body.vertices, body.faces, body.joint_names, body.joints, body.weights,
                 {n: rest[j] for j, n in enumerate(motion.skeleton.names)})
    with pytest.raises(ConfigError) as caught:
        bind_skin(other, motion.skeleton, read_joint_map(path))
    assert "which is not a joint of the skin" in str(caught.value) and len(str(caught.value)) < 200


def test_a_joint_map_reads_names_with_spaces_and_comments(tmp_path):
    path = tmp_path / "map.txt"
    path.write_bytes("\ufeff# 3ds Max biped to MakeHuman\nBip01 L Thigh = upperleg01.L   # the thigh\r\n\nBip01 Pelvis=root\n"
                     .encode("utf-8"))
    assert read_joint_map(path) == {"Bip01 L Thigh": "upperleg01.L", "Bip01 Pelvis": "root"}
    (tmp_path / "bin.txt").write_bytes(b"\xff\xfe\x00bad")
    with pytest.raises(InputError, match="not a text file"):
        read_joint_map(tmp_path / "bin.txt")


@needs_makehuman
def test_the_cli_binds_the_makehuman_body_and_says_how(tmp_path):
    """As users run it: --skin with the MakeHuman .obj on a CMU clip writes a GLB whose manifest says
    how the skin was bound; a bad joint map is one line, exit 2, nothing written."""
    clip = SAMPLE_DIR / "cmu_09_01_run_daz.bvh"
    out = tmp_path / "out"
    done = subprocess.run([*CLI, "exaggerate", str(clip), "-o", str(out), "--skin", str(SKIN_DIR / "makehuman_base.obj")],
                          capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert done.returncode == 0, done.stderr
    info = json.loads((out / "cmu_09_01_run_daz.json").read_text())
    assert info["skin_binding"]["pairs"] >= 19 and info["skin_binding"]["by"]["role"] >= 19
    assert (out / "cmu_09_01_run_daz.glb").stat().st_size > 1_000_000

    bad = tmp_path / "map.txt"
    bad.write_text("lThigh upperleg01.L\n")
    again = tmp_path / "again"
    done = subprocess.run([*CLI, "exaggerate", str(clip), "-o", str(again), "--skin", str(SKIN_DIR / "makehuman_base.obj"),
                           "--joint-map", str(bad)], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert done.stderr.strip().count("\n") == 0 and "map.txt:1: expected 'clip joint = skin joint'" in done.stderr
    assert not again.exists() or not any(again.iterdir())

    wrong = tmp_path / "wrong.txt"
    wrong.write_text("lThigh = upperleg01.L\nlShinn = lowerleg01.L\n")
    done = subprocess.run([*CLI, "exaggerate", str(clip), "-o", str(again), "--skin", str(SKIN_DIR / "makehuman_base.obj"),
                           "--joint-map", str(wrong)], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert "'lShinn', which is not a joint of the clip (close: lShin" in done.stderr
    assert not again.exists() or not any(again.iterdir())

    done = subprocess.run([*CLI, "exaggerate", str(clip), "-o", str(again), "--joint-map", str(wrong)],
                          capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert done.returncode == 2 and "give the skin too" in done.stderr


def test_a_rest_pose_turned_by_hand_moves_the_offsets_and_keeps_every_frame():
    """Known answer: a chain root -> a -> b along +Y, its rest posed by a quarter turn about Z at the
    root, rests along -X (offsets turned into the pose); a frame with no rotation keeps its positions
    along +Y, its root now turned back a quarter (-90 degrees about Z) and ``a`` untouched."""
    from mocap_exaggerate.core.motion import Motion
    from mocap_exaggerate.core.skeleton import Skeleton

    rotation = ("Zrotation", "Xrotation", "Yrotation")
    skeleton = Skeleton(("root", "a", "b"), [-1, 0, 1], [[0, 0, 0], [0, 1, 0], [0, 1, 0]],
                        (("Xposition", "Yposition", "Zposition") + rotation, rotation, rotation),
                        np.array([[np.nan] * 3, [np.nan] * 3, [0, 0.5, 0]]))
    motion = Motion(skeleton, 1 / 30, np.tile([0.0, 0, 0, 1], (1, 3, 1)), skeleton.offsets[None].copy())
    half = np.sqrt(0.5)
    posed = motion.with_rest(np.array([[0, 0, half, half], [0, 0, 0, 1], [0, 0, 0, 1]]))
    np.testing.assert_allclose(posed.skeleton.rest_positions(), [[0, 0, 0], [-1, 0, 0], [-2, 0, 0]], atol=1e-12)
    np.testing.assert_allclose(posed.skeleton.end_sites[2], [-0.5, 0, 0], atol=1e-12)
    assert np.isnan(posed.skeleton.end_sites[:2]).all()
    np.testing.assert_allclose(posed.world_positions()[0], [[0, 0, 0], [0, 1, 0], [0, 2, 0]], atol=1e-12)
    np.testing.assert_allclose(posed.local_rotations[0], [[0, 0, -half, half], [0, 0, 0, 1], [0, 0, 0, 1]],
                               atol=1e-12)
    with pytest.raises(ValueError, match="pose must be"):
        motion.with_rest(np.zeros((2, 4)))


ICLONE = ["cmu_06_15_basketball_dribble_shoot_iclone.bvh", "cmu_05_06_dance_cartwheel_start_iclone.bvh"]


def _beyond_twice(skin: Skin, own: np.ndarray, vertices: list[np.ndarray]) -> float:
    """Share of faces with an edge past 2x its length on ``own`` (the body's own vertices) in any of ``vertices``."""
    edges = np.concatenate([skin.faces[:, [0, 1]], skin.faces[:, [1, 2]], skin.faces[:, [2, 0]]])
    length = np.linalg.norm(np.diff(own[edges], axis=1)[:, 0], axis=1)
    worst = np.zeros(len(skin.faces))
    for v in vertices:
        ratio = np.linalg.norm(np.diff(v[edges], axis=1)[:, 0], axis=1) / length
        worst = np.maximum(worst, ratio.reshape(3, -1).max(axis=0))
    return float(np.mean(worst > 2.0))


@needs_makehuman
@pytest.mark.parametrize("name", ICLONE)
def test_a_rig_resting_with_its_limbs_straight_up_is_bound_with_them_posed_like_the_body(name, makehuman):
    """iClone's (Reallusion CC) rest pose has every bone along +Y: legs and arms straight up. Fitted
    there, each leg's map turned the mesh by 170 degrees and skinning pinched the hips and shoulders
    shut as the limbs came back down: 2.2 % of the faces past twice their length on the body itself
    before any motion, 3.7 % through the clip. Bound with the clip's limbs posed like the body's
    (measured 0.5 % and 1.7-2.5 %), with every frame's positions as they were."""
    motion = clip_motion(shared(name))
    bound, binding = bind_skin(makehuman, motion.skeleton)
    assert binding.posed >= 8 and len(bound.pose) == binding.posed
    posed, _, body = at_bind_pose(motion, None, bound)
    assert not body.pose  # taken into the skeleton's rest: not applied twice
    height = motion.skeleton.height()
    np.testing.assert_allclose(posed.world_positions(), motion.world_positions(), atol=1e-9 * height)
    rest = posed.skeleton.rest_positions()
    roles = joint_roles(motion.skeleton)[0]
    for side in ("left", "right"):  # the legs hang and the arms come down, as on the body (an A-pose)
        assert rest[roles[f"{side}_foot"], 1] < rest[roles[f"{side}_thigh"], 1] - 60.0
        assert rest[roles[f"{side}_hand"], 1] < rest[roles[f"{side}_upper_arm"], 1] - 20.0
    own = makehuman.vertices * binding.scale
    assert _beyond_twice(body, own, [body.vertices]) < 0.01
    rotations, positions = posed.forward_kinematics()
    index = np.array([posed.skeleton.index(n) for n in body.joint_names])
    frames = np.linspace(0, motion.num_frames - 1, 12).astype(int)
    shapes = [pose_skin(body, rest, rotations[f], positions[f], index) for f in frames]
    assert _beyond_twice(body, own, shapes) < 0.03


@needs_makehuman
@pytest.mark.parametrize("name", ["cmu_09_01_run_daz.bvh", "cmu_12_01_walk.bvh", ICLONE[0]])
def test_only_a_rig_resting_far_from_the_body_is_posed_and_then_only_in_its_limbs(name, makehuman):
    """A T-pose rig (Daz, CMU: arms 45-70 degrees from the body's A-pose) is fitted as it rests, with
    no pose, as before; iClone's limbs turn, its trunk and root do not (the placement is fitted to
    them); a default body carries no pose, and taking none changes nothing."""
    motion = clip_motion(shared(name))
    bound, binding = bind_skin(makehuman, motion.skeleton)
    roles, chains = joint_roles(motion.skeleton)
    trunk = {motion.skeleton.names[j] for j in [roles["hips"], *chains["spine"], *chains.get("neck", []), 0]}
    if "iclone" in name:
        assert len(bound.pose) == binding.posed == 12 and not (set(bound.pose) & trunk)
        assert motion.skeleton.names[roles["left_thigh"]] in bound.pose
    else:
        assert not bound.pose and binding.posed == 0
        assert at_bind_pose(motion, None, bound)[0] is motion
    body = default_skin(motion.skeleton)
    assert not body.pose and at_bind_pose(motion, None, body)[0] is motion


@needs_makehuman
def test_the_glb_and_the_weights_of_a_body_bound_in_its_own_pose_reproduce_the_run(makehuman, tmp_path):
    """iClone with the MakeHuman body (bound with the clip's limbs posed like its own): the GLB's joints
    sit where the run puts them, its mesh skinned by its own bind matrices is the preview's body, and
    the weights ``.npz`` (its ``rest_pose`` says how the GLB's rest is posed) read back as a skin on the
    BVH written poses to that mesh too. (Without ``rest_pose`` it streaked the limbs across the picture:
    16 % of the faces past 2x, the worst edge 173x.)"""
    from dataclasses import replace

    from mocap_exaggerate.config import load_preset
    from mocap_exaggerate.io.bvh import format_bvh
    from mocap_exaggerate.io.gltf import unit_scale
    from mocap_exaggerate.jobs.outputs import glb_files
    from mocap_exaggerate.pipeline import run
    from mocap_exaggerate.viz.posing import pose_bodies

    from .helpers import glb_joint_positions, skinned_vertices

    motion = clip_motion(shared(ICLONE[0]))
    config = load_preset("cartoon")
    config = replace(config, output=replace(config.output, preserve_volume=False))  # the .npz has no scale
    result = run(motion, config)
    files = glb_files(motion, result, makehuman)
    glb = b"".join(files.glb)
    height = motion.skeleton.height()
    meters = unit_scale("auto", height)[0]
    posed = at_bind_pose(motion, result, bind_skin(makehuman, motion.skeleton)[0])[1]
    assert posed is not result
    frames = [0, 100, 200]
    bodies = pose_bodies(motion, result, np.array(frames), makehuman)
    written = read_bvh(format_bvh(result.motion))[0]
    path = tmp_path / "body.weights.npz"
    path.write_bytes(files.weights)
    skin = load_skin(path)
    assert skin.pose and set(skin.pose) <= set(written.skeleton.names)
    again, _, again_skin = at_bind_pose(written, None, skin)
    rotations, positions = again.forward_kinematics()
    index = np.array([again.skeleton.index(n) for n in again_skin.joint_names])
    names = result.motion.skeleton.names
    for k, frame in enumerate(frames):
        joints = glb_joint_positions(glb, frame)  # (iClone stands on +Y: the GLB is not turned)
        placed = np.array([joints[name] for name in names])
        assert np.abs(placed - result.world_positions[frame] * meters).max() < 1e-5 * height * meters
        vertices, _ = skinned_vertices(glb, frame, posed, meters)
        assert np.abs(vertices - bodies.exaggerated[k] * meters).max() < 1e-4 * height * meters
        mesh = pose_skin(again_skin, again.skeleton.rest_positions(), rotations[frame], positions[frame], index)
        assert np.abs(mesh - bodies.exaggerated[k]).max() < 1e-3 * height


@pytest.mark.parametrize("pose, why", [
    (np.zeros((3, 4)), "3 rows and joint_names names 2"),
    (np.zeros((2, 3)), "must be"),
    (np.full((2, 4), np.nan), "not finite"),
    (np.array([[0.0, 0, 0, np.inf], [0, 0, 0, 1]]), "not finite"),
    (np.array([[0.0, 0, 0, 2], [0, 0, 0, 1]]), "unit length"),
    (np.full((2, 4), 1e308), "unit length"),  # (its norm overflowed into a RuntimeWarning on stderr)
    (np.array([["a", "b", "c", "d"]] * 2), "must be"),
])
def test_a_weights_file_with_a_bad_rest_pose_is_refused_in_one_line(tmp_path, pose, why):
    from mocap_exaggerate.io.skin import npz_bytes

    path = tmp_path / "bad.npz"
    path.write_bytes(npz_bytes(vertices=np.zeros((3, 3)), faces=np.array([[0, 1, 2]]), joint_names=np.array(["a", "b"]),
                               joints=np.zeros((3, 1), int), weights=np.ones((3, 1)), rest_pose=pose))
    with pytest.raises(InputError, match=why):
        load_skin(path)
    clip = SAMPLE_DIR / "cmu_09_01_run_daz.bvh"
    done = subprocess.run(CLI + ["exaggerate", str(clip), "-o", str(tmp_path / "out"), "--skin", str(path)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and why in done.stderr
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_a_weights_file_made_for_another_skeleton_is_refused_naming_the_file(tmp_path):
    """A run's weights .npz fits the BVH it wrote; on another clip its joints (or the pose it is bound
    in) name joints that clip does not have: one line naming the file and the joints, exit 2, nothing
    written (it was a ConfigError from the re-weighting that named neither)."""
    from mocap_exaggerate.io.skin import npz_bytes

    path = tmp_path / "other rig.weights.npz"
    path.write_bytes(npz_bytes(vertices=np.zeros((3, 3)), faces=np.array([[0, 1, 2]]),
                               joint_names=np.array(["hip", "abdomen_s0"]), joints=np.zeros((3, 1), int),
                               weights=np.ones((3, 1)), rest_pose=np.array([[0.0, 0, 0, 1], [0, 0.6, 0, 0.8]])))
    clip = SAMPLE_DIR / "cmu_16_01_jump_amc2bvh.bvh"
    done = subprocess.run(CLI + ["exaggerate", str(clip), "-o", str(tmp_path / "out"), "--skin", str(path)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    line = done.stderr.strip()
    assert len(line.splitlines()) == 1 and str(path) in line and "'abdomen_s0'" in line, line
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


ROBOT = SHARED_BVH.parent / "gltf" / "robot_expressive_quaternius.glb"


@pytest.mark.skipif(not ROBOT.exists(), reason=f"the Quaternius robot is not at {ROBOT} (../shared/data/gltf)")
@pytest.mark.parametrize("command", [["preview", "-o", "{out}/look.png"],
                                     ["compare", "--omega", "2,3", "-o", "{out}/grid.png"]])
def test_the_pictures_say_what_the_binding_left_unpaired_as_exaggerate_does(tmp_path, command):
    """`preview --skin` is where a user looks before rendering (the guide says so), yet it said only
    'wrote ...' where `exaggerate` warned that the robot's legs pair with no joint of the clip (found by a
    new-user trial); `-q` keeps it quiet."""
    clip = SAMPLE_DIR / "cmu_09_01_run_daz.bvh"
    args = [a.format(out=tmp_path) for a in command]
    done = subprocess.run(CLI + [args[0], str(clip), *args[1:], "--skin", str(ROBOT)], capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "no joint of the character pairs with the clip's left_thigh" in done.stderr
    quiet = subprocess.run(CLI + ["-q", args[0], str(clip), *args[1:], "--skin", str(ROBOT), "--overwrite"],
                           capture_output=True, text=True, timeout=300)
    assert quiet.returncode == 0 and quiet.stderr == "", quiet.stderr


@needs_makehuman
def test_two_makehuman_weights_files_beside_the_body_are_refused_not_one_picked(tmp_path):
    """With a second .mhw beside the .obj the first by name was used without a word (a new-user trial
    edited a copy and saw nothing change): now one line naming both, exit 2."""
    import shutil

    for name in ("makehuman_base.obj", "makehuman_default_weights.mhw", "makehuman_default.mhskel"):
        shutil.copy(SKIN_DIR / name, tmp_path / name)
    shutil.copy(SKIN_DIR / "makehuman_default_weights.mhw", tmp_path / "aaa_other.mhw")
    with pytest.raises(InputError, match="2 .mhw weights files beside the .obj .aaa_other.mhw, makehuman_default"):
        load_skin(tmp_path / "makehuman_base.obj")
    clip = SAMPLE_DIR / "cmu_09_01_run_daz.bvh"
    done = subprocess.run(CLI + ["preview", str(clip), "-o", str(tmp_path / "look.png"), "--skin",
                                 str(tmp_path / "makehuman_base.obj")], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1 and "aaa_other.mhw" in done.stderr
    assert not (tmp_path / "look.png").exists()


def test_a_skins_rest_pose_counts_in_the_parameters_digest(tmp_path):
    """Two weights files that differ only in their rest_pose make different GLBs: `batch --resume` must
    not take one's outputs for the other's (a review found the digest blind to it). A skin with no pose
    keeps the digest it had."""
    from mocap_exaggerate.config import PipelineConfig
    from mocap_exaggerate.io.skin import npz_bytes
    from mocap_exaggerate.jobs.job import parameters_digest

    arrays = dict(vertices=np.zeros((3, 3)), faces=np.array([[0, 1, 2]]), joint_names=np.array(["a", "b"]),
                  joints=np.zeros((3, 1), int), weights=np.ones((3, 1)))
    digests = []
    for k, pose in enumerate([None, [[0.0, 0, 0, 1], [0, 0, 0, 1]], [[0.0, 0, 0, 1], [0, 0.6, 0, 0.8]]]):
        path = tmp_path / f"{k}.npz"
        path.write_bytes(npz_bytes(**arrays, **({} if pose is None else {"rest_pose": np.array(pose)})))
        digests.append(parameters_digest(PipelineConfig(), skin=path))
    assert digests[0] == digests[1] != digests[2]
