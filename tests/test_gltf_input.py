"""Animated glTF in (issue 26, part 3): a skinned, animated GLB is read as the motion and its own
mesh and weights as the skin, so a game character comes out exaggerated with its own body.

The reference is the glTF's own skinning, computed here straight from the file with pygltflib
(each key's translation, rotation and scale down the node tree, ``world(joint) @ IBM @ v``):
with no exaggeration the run's skinned mesh is where a glTF viewer draws the input's.
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pygltflib
import pytest

from mocap_exaggerate import convert
from mocap_exaggerate.config import PipelineConfig, load_preset
from mocap_exaggerate.core.errors import InputError
from mocap_exaggerate.core.rotations import quat_to_matrix
from mocap_exaggerate.io.gltf_motion import gltf_animations, read_gltf_motion
from mocap_exaggerate.io.skin import load_skin
from mocap_exaggerate.pipeline import run
from mocap_exaggerate.rig.skinning import pose_skin

from .helpers import SHARED_BVH, skinned_vertices

GLTF = SHARED_BVH.parent / "gltf"
FOX = GLTF / "fox_khronos.glb"
ROBOT = GLTF / "robot_expressive_quaternius.glb"

pytestmark = pytest.mark.skipif(not FOX.exists(), reason=f"the shared glTF characters are not at {GLTF}")


def _identity() -> PipelineConfig:
    base = load_preset("cartoon").to_dict()
    for block in ("extrapolate", "correct", "springs", "contacts", "auto_stretch", "subjoints"):
        base[block] = {**base[block], "enabled": False}
    return PipelineConfig.from_dict(base)


def _key_frames(path, clip: str, fps: float) -> list[int]:
    """Frames (at ``fps``) that fall on one of the clip's keys, as (frame, key) pairs."""
    gltf = pygltflib.GLTF2().load(str(path))
    animation = next(a for a in gltf.animations if a.name == clip)
    accessor = gltf.accessors[animation.samplers[0].input]
    view = gltf.bufferViews[accessor.bufferView]
    times = np.frombuffer(gltf.binary_blob(), np.float32, accessor.count,
                          (view.byteOffset or 0) + (accessor.byteOffset or 0)).astype(float)
    frames = np.round((times - times[0]) * fps).astype(int)
    on = np.abs((times - times[0]) * fps - frames) < 1e-3
    return [(int(f), int(k)) for k, f in enumerate(frames) if on[k]]


def _own_skinning(path, clip: str, key: int, *, every_mesh: bool = False) -> np.ndarray:
    """The file's skinned mesh at one of the clip's keys, as a glTF viewer draws it (``every_mesh``:
    every mesh of the scene, skinned or hung rigidly below a node, in the order of their nodes)."""
    gltf = pygltflib.GLTF2().load(str(path))
    blob = gltf.binary_blob()

    def read(index):
        accessor = gltf.accessors[index]
        view = gltf.bufferViews[accessor.bufferView]
        width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}[accessor.type]
        dtype = {pygltflib.FLOAT: np.float32, pygltflib.UNSIGNED_BYTE: np.uint8,
                 pygltflib.UNSIGNED_SHORT: np.uint16, pygltflib.UNSIGNED_INT: np.uint32}[accessor.componentType]
        start = (view.byteOffset or 0) + (accessor.byteOffset or 0)
        return np.frombuffer(blob, dtype, accessor.count * width, start).reshape(accessor.count, width).astype(float)

    trs = {k: [np.array(n.translation or [0, 0, 0], float), np.array(n.rotation or [0, 0, 0, 1], float),
               np.array(n.scale or [1, 1, 1], float)] for k, n in enumerate(gltf.nodes)}
    animation = next(a for a in gltf.animations if a.name == clip)
    for channel in animation.channels:
        sampler = animation.samplers[channel.sampler]
        if channel.target.path in ("translation", "rotation", "scale"):
            trs[channel.target.node][("translation", "rotation", "scale").index(channel.target.path)] = \
                read(sampler.output)[key]
    parent = {c: k for k, n in enumerate(gltf.nodes) for c in (n.children or [])}
    world: dict[int, np.ndarray] = {}

    def place(k):
        if k not in world:
            t, r, s = trs[k]
            local = np.eye(4)
            local[:3, :3] = quat_to_matrix(r / np.linalg.norm(r)) * s
            local[:3, 3] = t
            world[k] = (place(parent[k]) if k in parent else np.eye(4)) @ local
        return world[k]

    def drawn(node):
        primitive = gltf.meshes[node.mesh].primitives[0]
        vertices = read(primitive.attributes.POSITION)
        homogeneous = np.concatenate([vertices, np.ones((len(vertices), 1))], axis=1)
        if node.skin is None:
            return homogeneous @ place(gltf.nodes.index(node)).T[:, :3]
        skin = gltf.skins[node.skin]
        joints = read(primitive.attributes.JOINTS_0).astype(int)
        weights = read(primitive.attributes.WEIGHTS_0)
        ibm = read(skin.inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)
        matrices = np.array([place(joint) for joint in skin.joints]) @ ibm
        moved = np.einsum("vkab,vb->vka", matrices[joints], homogeneous)[..., :3]
        return np.sum(weights[..., None] * moved, axis=1)

    owner = next(n for n in gltf.nodes if n.mesh is not None and n.skin is not None)
    if not every_mesh:
        return drawn(owner)
    return np.concatenate([drawn(owner)] + [drawn(n) for n in gltf.nodes if n.mesh is not None and n is not owner])


@pytest.mark.parametrize("clip", ["Walk", "Run", "Survey"])
def test_the_fox_read_as_motion_moves_its_own_mesh_as_the_file_does(clip):
    motion, report = read_gltf_motion(FOX, clip=clip)
    assert report.clip == clip and report.fps == 24.0  # the keys' own rate
    skin = load_skin(FOX)
    rotations, positions = motion.forward_kinematics()
    index = np.array([motion.skeleton.index(n) for n in skin.joint_names])
    bind = np.array([skin.bind[n] if n in skin.bind else motion.skeleton.rest_positions()[motion.skeleton.index(n)]
                     for n in motion.skeleton.names])
    size = np.ptp(skin.vertices, axis=0).max()
    pairs = _key_frames(FOX, clip, report.fps)
    assert len(pairs) >= 10
    for frame, key in pairs[:: max(len(pairs) // 4, 1)] + pairs[-1:]:
        ours = pose_skin(skin, bind, rotations[frame], positions[frame], index)
        assert np.abs(ours - _own_skinning(FOX, clip, key)).max() <= 1e-4 * size


def test_a_character_of_many_pieces_moves_every_piece_as_the_file_does():
    # The Quaternius robot: two skinned hands and seventeen rigid pieces hung below its bones.
    skin = load_skin(ROBOT)
    gltf = pygltflib.GLTF2().load(str(ROBOT))
    assert skin.num_vertices == sum(gltf.accessors[gltf.meshes[n.mesh].primitives[0].attributes.POSITION].count
                                    for n in gltf.nodes if n.mesh is not None)
    motion, report = read_gltf_motion(ROBOT, clip="Wave")
    rotations, positions = motion.forward_kinematics()
    index = np.array([motion.skeleton.index(n) for n in skin.joint_names])
    bind = np.array([skin.bind.get(n, p) for n, p in zip(motion.skeleton.names, motion.skeleton.rest_positions())])
    size = float(np.ptp(skin.vertices, axis=0).max())
    pairs = _key_frames(ROBOT, "Wave", report.fps)
    for frame, key in pairs[:: max(len(pairs) // 3, 1)]:
        ours = pose_skin(skin, bind, rotations[frame], positions[frame], index)
        assert np.abs(ours - _own_skinning(ROBOT, "Wave", key, every_mesh=True)).max() <= 1e-4 * size


def test_step_keys_hold_from_their_own_frame():
    # A key stored a float32 hair after its frame's time still holds from that frame, not the next.
    motion, _ = read_gltf_motion(FOX, clip="Walk")
    stepped = pygltflib.GLTF2().load(str(FOX))
    for sampler in stepped.animations[1].samplers:
        sampler.interpolation = "STEP"
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as folder:
        copy = Path(folder) / "fox_step.glb"
        stepped.save_binary(str(copy))
        held, _ = read_gltf_motion(copy, clip="Walk")
    # At 24 fps every frame is a key: STEP and LINEAR give the same poses.
    assert np.abs(held.world_positions() - motion.world_positions()).max() < 1e-4 * motion.skeleton.height()


def test_an_identity_run_on_a_glb_writes_the_input_characters_own_skinning(tmp_path):
    record = convert(FOX, tmp_path, _identity(), name="fox")
    assert record.outputs["glb"].exists()
    motion, _ = read_gltf_motion(FOX)  # the first clip, Survey
    result = run(motion, _identity())
    glb = record.outputs["glb"].read_bytes()
    assert record.manifest["outputs"]["units"] == "m"  # glTF is in metres: the output stays the input's size
    size = float(np.ptp(load_skin(FOX).vertices, axis=0).max())
    pairs = _key_frames(FOX, "Survey", motion.fps)
    for frame, key in pairs[:: max(len(pairs) // 4, 1)] + pairs[-1:]:
        ours, _ = skinned_vertices(glb, frame, result, 1.0)
        assert np.abs(ours - _own_skinning(FOX, "Survey", key)).max() <= 1e-4 * size


def test_the_fox_comes_out_exaggerated_with_its_own_body(tmp_path):
    record = convert(FOX, tmp_path, load_preset("looney"), name="fox")
    assert record.frames == 83 and record.manifest["result"]["max_link_stretch"] > 1.0
    motion, _ = read_gltf_motion(FOX)
    result = run(motion, load_preset("looney"))
    moved = np.linalg.norm(result.world_positions[:, result.original_index] - motion.world_positions(), axis=-1)
    # The look-around (on four planted feet) swings the head past the keyframes.
    assert moved[:, motion.skeleton.index("b_Head_05")].max() > 0.02 * motion.skeleton.height()
    body = load_skin(record.outputs["glb"])
    assert len(body.vertices) == len(load_skin(FOX).vertices)


def test_animations_are_listed_and_taken_by_name():
    names = [a["name"] for a in gltf_animations(ROBOT)]
    assert names[:3] == ["Dance", "Death", "Idle"] and len(names) == 14
    motion, report = read_gltf_motion(ROBOT, clip="Walking", fps=60)
    assert report.clip == "Walking" and motion.fps == pytest.approx(60.0)
    assert motion.num_frames == int(np.floor(0.958333 * 60 + 1e-6)) + 1
    # Key times are float32: the Dance's 81 keys over 3.3333 s are 81 frames at their 24 fps, not 80.
    assert read_gltf_motion(ROBOT, clip="Dance")[0].num_frames == 81
    with pytest.raises(InputError, match="no animation called 'Moonwalk'"):
        read_gltf_motion(ROBOT, clip="Moonwalk")


def _cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=180)


def test_the_command_line_takes_a_glb_its_clip_and_lists_the_clips_in_info(tmp_path):
    done = _cli("exaggerate", FOX, "-o", tmp_path / "out", "--clip", "Run", "--preset", "looney", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "out" / "fox_khronos_Run.glb").exists()
    info = _cli("info", FOX, "--clip", "Run", cwd=tmp_path)
    assert info.returncode == 0, info.stderr
    assert "animation   Run: 1.15833 s, 25 keys, 21 channels (this one)" in info.stdout
    bad = _cli("exaggerate", FOX, "-o", tmp_path / "bad", "--clip", "Moonwalk", cwd=tmp_path)
    assert bad.returncode == 2 and "no animation called 'Moonwalk'" in bad.stderr and "Traceback" not in bad.stderr
    assert not (tmp_path / "bad").exists()


def test_a_character_that_leaves_the_clip_s_legs_unpaired_is_warned_of(tmp_path):
    """The robot as the character of a human clip: its legs pair with none of the clip's, and hung still
    with nothing said but the manifest's ``unpaired_roles``. Now a warning says which, and what to do."""
    from .helpers import SAMPLE_DIR

    record = convert(SAMPLE_DIR / "cmu_09_01_run_daz.bvh", tmp_path / "robot", skin=ROBOT)
    said = [w for w in record.warnings if w.startswith("skin: no joint of the character pairs")]
    assert len(said) == 1 and "left_thigh" in said[0] and "--joint-map" in said[0], record.warnings
    unpaired = json.loads(record.outputs["manifest"].read_text())["skin_binding"]["unpaired_roles"]
    assert all(role in said[0] for role in unpaired) and unpaired
    human = convert(SAMPLE_DIR / "cmu_09_01_run_daz.bvh", tmp_path / "human", skin=GLTF.parent / "skin" / "makehuman_base.obj")
    assert not [w for w in human.warnings if w.startswith("skin:")]  # every main role of a human pairs


def test_the_weights_file_indexes_the_glb_s_joints_without_sub_joints_too(tmp_path):
    """With --no-subjoints a bound character's .npz listed only the joints it used (19 of 43), so its
    indices addressed another list than the GLB skin's; now both list the output skeleton's joints."""
    import numpy as np

    from .helpers import SAMPLE_DIR

    config = load_preset("cartoon").to_dict()
    config["subjoints"] = {**config["subjoints"], "enabled": False}
    record = convert(SAMPLE_DIR / "cmu_09_01_run_daz.bvh", tmp_path, PipelineConfig.from_dict(config),
                     skin=GLTF.parent / "skin" / "makehuman_base.obj")
    weights = np.load(record.outputs["weights"])
    gltf = pygltflib.GLTF2().load(str(record.outputs["glb"]))
    assert [str(n) for n in weights["joint_names"]] == [gltf.nodes[j].name for j in gltf.skins[0].joints]
    assert len(weights["joint_names"]) == 43 and weights["joints"].max() < 43
