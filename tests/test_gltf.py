"""Skinned GLB output: the Khronos validator, reading it back, and the skinned mesh following the skeleton."""

from __future__ import annotations

import dataclasses
import io
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pygltflib
import pytest
import trimesh

from mocap_exaggerate.config import load_preset, resolve_config
from mocap_exaggerate.core.rotations import quat_mul, quat_rotate
from mocap_exaggerate.io.bvh import read_bvh
from mocap_exaggerate.io.gltf import unit_scale
from mocap_exaggerate.io.skin import load_skin
from mocap_exaggerate.jobs.outputs import make_glb, output_thickness
from mocap_exaggerate.pipeline import run
from mocap_exaggerate.rig.body import default_skin
from mocap_exaggerate.rig.skinning import Skin, reweight, subjoint_bind_positions
from mocap_exaggerate.stages.subjoints import build_hierarchy

from .helpers import ROOT, SHARED_BVH, all_clip_params, shared, skinned_vertices

VALIDATOR = Path(__file__).parent / "gltf" / "validate.mjs"
HAS_VALIDATOR = shutil.which("node") is not None and (Path(__file__).parent / "gltf" / "node_modules" / "gltf-validator").exists()
needs_validator = pytest.mark.skipif(
    not HAS_VALIDATOR, reason="Khronos gltf-validator not installed (run: npm ci --prefix tests/gltf; .ci/run does)"
)


def glb_for(path: Path, preset: str = "cartoon", overrides: dict | None = None):
    motion, _ = read_bvh(path)
    result = run(motion, resolve_config(preset, None, overrides))
    glb, weights, how = make_glb(motion, result, None, "auto")
    return motion, result, glb, weights


def validate(glb: bytes, tmp_path: Path) -> dict:
    file = tmp_path / "check.glb"
    file.write_bytes(glb)
    done = subprocess.run(["node", str(VALIDATOR), str(file)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


@needs_validator
@pytest.mark.parametrize("path", all_clip_params())
def test_validator_finds_no_errors_or_warnings(path, tmp_path):
    _, _, glb, _ = glb_for(path)
    report = validate(glb, tmp_path)
    issues = report["issues"]
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, issues["messages"][:5]


@needs_validator
def test_validator_on_the_original_skeleton_and_a_given_skin(sample_clip, tmp_path):
    _, _, glb, _ = glb_for(sample_clip, overrides={"output": {"skeleton": "original"}})
    assert validate(glb, tmp_path)["issues"]["numErrors"] == 0
    motion, _ = read_bvh(sample_clip)
    skin_file = tmp_path / "given.npz"
    body = default_skin(motion.skeleton)
    np.savez(skin_file, vertices=body.vertices, faces=body.faces, joint_names=np.array(body.joint_names),
             joints=body.joints, weights=body.weights)
    result = run(motion, load_preset("cartoon"))
    glb, _, _ = make_glb(motion, result, load_skin(skin_file), "cm")
    report = validate(glb, tmp_path)
    assert report["issues"]["numErrors"] == 0 and report["issues"]["numWarnings"] == 0


@pytest.mark.parametrize("clip", ["cmu_09_01_run_daz.bvh", "mocapbank_sit_down_stand_up.bvh"])
def test_read_back_counts_weights_and_the_mesh_follows_the_skeleton(clip):
    path = ROOT / "sample_data" / clip
    motion, result, glb, weights_npz = glb_for(path)
    gltf = pygltflib.GLTF2.load_from_bytes(glb)
    assert len(gltf.skins[0].joints) == result.motion.skeleton.num_joints
    # A translation and a rotation track per joint, and a scale track on each joint whose world
    # scale (output_thickness: its bone stretches or squashes, keeping volume) differs from its
    # parent's at some frame.
    thickness = output_thickness(result)
    parents = result.motion.skeleton.parents
    relative = thickness / np.where(parents >= 0, thickness[:, np.maximum(parents, 0)], 1.0)
    scaled = np.any(np.abs(relative - 1.0) > 1e-6, axis=0)
    assert 0 < scaled.sum() < result.motion.skeleton.num_joints
    assert len(gltf.animations[0].channels) == 2 * result.motion.skeleton.num_joints + scaled.sum()
    tracks = {(c.target.node, c.target.path) for c in gltf.animations[0].channels}
    assert {node for node, path in tracks if path == "scale"} == set(np.flatnonzero(scaled))
    stored = np.load(io.BytesIO(weights_npz))
    height = motion.skeleton.height()
    assert list(stored["joint_names"]) == list(result.motion.skeleton.names)
    meters = unit_scale("auto", height)[0]
    for frame in (10, motion.num_frames // 2, motion.num_frames - 1):
        vertices, weights = skinned_vertices(glb, frame, result, meters)
        assert np.allclose(weights.sum(axis=1), 1.0, atol=1e-6)
        assert len(vertices) == len(stored["vertices"])
        # Every vertex stays near the posed skeleton: within a limb's thickness of some joint.
        joints = result.world_positions[frame] * meters
        nearest = np.min(np.linalg.norm(vertices[:, None] - joints[None], axis=-1), axis=1)
        assert np.median(nearest) < 0.08 * height * meters
        assert np.max(nearest) < 0.35 * height * meters


def test_default_body_is_closed_watertight_pieces_on_every_sample_clip():
    for path in sorted((ROOT / "sample_data").glob("*.bvh")):
        motion, _ = read_bvh(path)
        body = default_skin(motion.skeleton, build_hierarchy(motion.skeleton).rigid)
        mesh = trimesh.Trimesh(body.vertices, body.faces, process=False)
        assert mesh.is_watertight and mesh.volume > 0
        for piece in mesh.split(only_watertight=False):  # one closed capsule per link (body.py says why)
            assert piece.is_watertight and piece.is_winding_consistent and piece.volume > 0
        assert np.allclose(body.weights.sum(axis=1), 1.0)


def test_reweighting_shares_each_weight_along_the_link_by_where_the_vertex_lies(sample_clip):
    # Each sub-link's owner peaks at the sub-link's middle (1/8, 3/8, 5/8, 7/8 of a link cut in four)
    # and hands over linearly to the next: worked out by hand for vertices at 0.2, 0.5 and 0.8.
    motion, _ = read_bvh(sample_clip)
    skeleton = motion.skeleton
    hierarchy = build_hierarchy(skeleton)
    arm = skeleton.index("lShldr")
    rest = skeleton.rest_positions()
    elbow = skeleton.index("lForeArm")
    # Three vertices beside the upper arm (3 units off it, square to it), each bound only to it.
    link = rest[elbow] - rest[arm]
    beside = np.cross(link, [0.0, 1.0, 0.0])
    along = rest[arm] + np.array([0.2, 0.5, 0.8])[:, None] * link + 3.0 * beside / np.linalg.norm(beside)
    skin = Skin(along, np.array([[0, 1, 2]]), ("lShldr",), np.zeros((3, 1), int), np.ones((3, 1)))
    out = reweight(skin, skeleton, hierarchy, max_influences=8)
    names = out.joint_names
    expected = [{"lShldr": 0.7, "lForeArm_s1": 0.3}, {"lForeArm_s1": 0.5, "lForeArm_s2": 0.5},
                {"lForeArm_s2": 0.3, "lForeArm_s3": 0.7}]
    for v in range(3):
        got = {names[j]: w for j, w in zip(out.joints[v], out.weights[v]) if w > 0}
        assert got == pytest.approx(expected[v], abs=1e-9)


def test_makehuman_skin_reweights_fast_and_sensibly():
    skin = load_skin(shared("../skin/makehuman_base.obj"))
    motion, _ = read_bvh(SHARED_BVH.parent / "skin" / "makehuman_default_tpose.bvh")
    hierarchy = build_hierarchy(motion.skeleton)
    assert len(skin.joint_names) == 139 and skin.num_vertices == 13380
    out = reweight(skin, motion.skeleton, hierarchy)
    assert np.allclose(out.weights.sum(axis=1), 1.0)
    assert out.joints.shape == (13380, 4)
    bind = subjoint_bind_positions(motion.skeleton, hierarchy, skin.bind)
    distance = np.linalg.norm(skin.vertices - bind[out.joints[:, 0]], axis=1)
    assert np.median(distance) < 0.05 * np.ptp(skin.vertices[:, 1])  # strongest joint is close by
    used = {out.joint_names[j] for j in np.unique(out.joints[out.weights > 0])}
    assert any(name.startswith("upperarm02.L_s") for name in used)


def animation_at(glb: bytes, frame: int):
    """Each node's translation, rotation and (uniform) scale at a frame, from the GLB's own samplers."""
    gltf = pygltflib.GLTF2.load_from_bytes(glb)
    blob = gltf.binary_blob()

    def read(index, width):
        accessor = gltf.accessors[index]
        view = gltf.bufferViews[accessor.bufferView]
        return np.frombuffer(blob, dtype=np.float32, count=accessor.count * width, offset=view.byteOffset).reshape(-1, width)

    count = len(gltf.skins[0].joints)
    translation = np.array([gltf.nodes[j].translation for j in range(count)], dtype=np.float64)
    rotation = np.tile([0.0, 0.0, 0.0, 1.0], (count, 1))
    scale = np.ones(count)
    animation = gltf.animations[0]
    for channel in animation.channels:
        sampler = animation.samplers[channel.sampler]
        width = {"translation": 3, "rotation": 4, "scale": 3}[channel.target.path]
        value = read(sampler.output, width)[frame].astype(np.float64)
        if channel.target.path == "translation":
            translation[channel.target.node] = value
        elif channel.target.path == "rotation":
            rotation[channel.target.node] = value
        else:
            assert np.allclose(value, value[0])  # uniform: children are never sheared
            scale[channel.target.node] = value[0]
    children = {j: gltf.nodes[j].children or [] for j in range(count)}
    return translation, rotation, scale, children


@needs_validator
def test_volume_preserving_scale_keeps_every_joint_in_place(tmp_path):
    motion, _ = read_bvh(shared("assimp_boxing_toes.bvh"))
    config = resolve_config("cartoon", "[[stretch]]\nlimb = 'right_arm'\nstart = 1230\nend = 1251\nscale = 3.0\naxes = 'xz'\n")
    result = run(motion, config)
    glb, _, _ = make_glb(motion, result)
    report = validate(glb, tmp_path)
    assert report["issues"]["numErrors"] == 0 and report["issues"]["numWarnings"] == 0
    meters = unit_scale("auto", motion.skeleton.height())[0]
    translation, rotation, scale, children = animation_at(glb, 1251)
    parents = result.motion.skeleton.parents
    world_pos = np.zeros_like(translation)
    world_rot = np.zeros_like(rotation)
    world_scale = np.ones(len(scale))
    world_pos[0], world_rot[0], world_scale[0] = translation[0], rotation[0], scale[0]
    for j in range(1, len(scale)):
        p = parents[j]
        world_pos[j] = world_pos[p] + quat_rotate(world_rot[p], world_scale[p] * translation[j])
        world_rot[j] = quat_mul(world_rot[p], rotation[j])
        world_scale[j] = world_scale[p] * scale[j]
    assert np.max(np.abs(world_pos - result.world_positions[1251] * meters)) < 1e-4
    # Every joint's world scale is its link's volume-keeping thickness; the stretched arm is
    # thinner than the other one, which cartoon's exaggeration alone stretches far less.
    np.testing.assert_allclose(world_scale, output_thickness(result)[1251], atol=1e-5)
    names = result.motion.skeleton.names
    arm = [k for k, n in enumerate(names) if n.startswith("RightElbow_s")]
    other = [k for k, n in enumerate(names) if n.startswith("LeftElbow_s")]
    assert np.all(world_scale[arm] < 0.95)
    assert world_scale[arm].max() < world_scale[other].min() - 0.05


@needs_validator
def test_eight_influences_and_a_glb_skin(sample_clip, tmp_path):
    motion, _ = read_bvh(sample_clip)
    original = run(motion, resolve_config("cartoon", None, {"output": {"skeleton": "original"}}))
    glb, _, _ = make_glb(motion, original, units="m")
    skin_file = tmp_path / "character.glb"
    skin_file.write_bytes(glb)
    # Our own tube body, made link by link: its branch joints' weight follows the links (Skin.per_link).
    skin = dataclasses.replace(load_skin(skin_file), per_link=True)
    assert len(skin.joint_names) == motion.skeleton.num_joints and len(skin.bind) == motion.skeleton.num_joints
    rubber = run(motion, load_preset("cartoon"))
    glb8, _, _ = make_glb(motion, rubber, skin, "m", influences=8)
    report = validate(glb8, tmp_path)
    assert report["issues"]["numErrors"] == 0 and report["issues"]["numWarnings"] == 0
    gltf = pygltflib.GLTF2.load_from_bytes(glb8)
    attributes = gltf.meshes[0].primitives[0].attributes
    assert getattr(attributes, "JOINTS_1", None) is not None and getattr(attributes, "WEIGHTS_1", None) is not None
    back = load_skin_bytes(glb8, tmp_path)
    assert back.joints.shape[1] == 8 and np.allclose(back.weights.sum(axis=1), 1.0, atol=1e-6)
    assert (back.weights > 0).sum(axis=1).max() > 4
    # A character bound in another pose, axes and units (MakeHuman: A-pose, Y up, decimetres) is fitted
    # to the clip (`mocap_exaggerate.rig.binding`): a clean GLB, on the rubber skeleton, with 8 influences.
    if (SHARED_BVH.parent / "skin").is_dir():
        makehuman = load_skin(SHARED_BVH.parent / "skin" / "makehuman_base.obj")
        glb_mh, _, _ = make_glb(motion, rubber, makehuman, "cm", influences=8)
        report = validate(glb_mh, tmp_path)
        assert report["issues"]["numErrors"] == 0 and report["issues"]["numWarnings"] == 0, report["issues"]["messages"][:3]
        assert load_skin_bytes(glb_mh, tmp_path).num_vertices == makehuman.num_vertices


def load_skin_bytes(glb: bytes, folder: Path):
    path = folder / "back.glb"
    path.write_bytes(glb)
    return load_skin(path)


def test_vertex_normals_are_trimeshs(sample_clip):
    from mocap_exaggerate.io.gltf import vertex_normals

    skin = default_skin(read_bvh(sample_clip)[0].skeleton)
    expected = trimesh.Trimesh(skin.vertices, skin.faces, process=False).vertex_normals
    np.testing.assert_allclose(vertex_normals(skin.vertices, skin.faces), expected, atol=1e-9)
    # A vertex on no face still gets a unit normal (the validator checks them).
    lonely = vertex_normals(np.vstack([skin.vertices, [[0.0, 0.0, 0.0]]]), skin.faces)
    np.testing.assert_allclose(np.linalg.norm(lonely, axis=1), 1.0)


def test_blocked_reweighting_equals_the_whole_expansion(sample_clip, monkeypatch):
    """Re-weighting in blocks of a few rows gives what one block of everything gives."""
    import mocap_exaggerate.rig.skinning as skinning

    skeleton = read_bvh(sample_clip)[0].skeleton
    hierarchy = run(read_bvh(sample_clip)[0].slice(slice(0, 5)), load_preset("cartoon")).hierarchy
    skin = default_skin(skeleton, hierarchy.rigid)
    whole = reweight(skin, skeleton, hierarchy)
    monkeypatch.setattr(skinning, "_BLOCK_ROWS", 7)
    blocked = reweight(skin, skeleton, hierarchy)
    np.testing.assert_array_equal(blocked.joints, whole.joints)
    np.testing.assert_allclose(blocked.weights, whole.weights, atol=1e-15)


def test_gltf_json_is_pygltflibs_text(tmp_path):
    """The fast JSON writer gives pygltflib's own text, character for character, on real documents:
    8 influences (two attribute sets), looney volume scales, a 3,000-frame clip of 75 joints."""
    import mocap_exaggerate.io.gltf as gltf_module
    from mocap_exaggerate.jobs.job import convert

    seen = []

    def both(document):
        ours = gltf_json(document)
        assert ours == document.gltf_to_json(separators=(",", ":"), indent=None)
        seen.append(len(ours))
        return ours

    gltf_json = gltf_module.gltf_json
    clips = [ROOT / "sample_data" / "cmu_09_01_run_daz.bvh"]
    if SHARED_BVH.is_dir():
        clips.append(SHARED_BVH / "assimp_boxing_toes.bvh")
    try:
        gltf_module.gltf_json = both
        for k, clip in enumerate(clips):
            convert(clip, tmp_path / str(k), influences=8 if k == 0 else 4)
        convert(clips[0], tmp_path / "looney", preset="looney")
    finally:
        gltf_module.gltf_json = gltf_json
    assert len(seen) == len(clips) + 1 and min(seen) > 10_000


def test_the_config_names_the_same_units_as_the_glb_writer():
    # config.py keeps its own list so reading a pipeline file does not import the glTF writer.
    from mocap_exaggerate.config import GLB_UNITS
    from mocap_exaggerate.io.gltf import UNITS

    assert GLB_UNITS == ("auto", *UNITS)
