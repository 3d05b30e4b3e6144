"""Reading a glTF skin as it stands in its file's scene: node transforms, bind poses, the joint tree, mirrors."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pygltflib as gl
import pytest

from mocap_exaggerate.analysis.limbs import standing_up
from mocap_exaggerate.config import resolve_config
from mocap_exaggerate.core.errors import InputError
from mocap_exaggerate.core.motion import Motion
from mocap_exaggerate.core.rotations import quat_mul, quat_rotate, quat_to_matrix
from mocap_exaggerate.core.skeleton import Skeleton
from mocap_exaggerate.io.bvh import format_bvh, load_bvh
from mocap_exaggerate.io.gltf import UPRIGHT, unit_scale
from mocap_exaggerate.io.skin import load_gltf_skin, load_skin
from mocap_exaggerate.jobs.outputs import make_glb
from mocap_exaggerate.pipeline import run

from .helpers import SAMPLE_DIR

HALF = float(np.sqrt(0.5))
#: -90 degrees about X: Blender's armature turn from its Z up to glTF's Y up, (x, y, z) -> (x, z, -y).
Z_TO_Y_UP = [-HALF, 0.0, 0.0, HALF]


def bar(along: int = 2, rings: tuple[float, ...] = (0.0, 50.0, 100.0), half: float = 10.0):
    """A closed square bar along axis ``along``: one ring of 4 vertices per joint, capped, wound outward.

    Returns vertices (12, 3), faces (20, 3), joints (12, 4) and weights (12, 4): ring k follows joint k.
    """
    a, b = [axis for axis in range(3) if axis != along]
    square = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=np.float64) * half
    vertices = np.zeros((4 * len(rings), 3))
    for k, height in enumerate(rings):
        vertices[4 * k: 4 * k + 4, a] = square[:, 0]
        vertices[4 * k: 4 * k + 4, b] = square[:, 1]
        vertices[4 * k: 4 * k + 4, along] = height
    faces = []
    for k in range(len(rings) - 1):
        for i in range(4):
            p, q = 4 * k + i, 4 * k + (i + 1) % 4
            faces += [[p, q, q + 4], [p, q + 4, p + 4]]
    last = 4 * (len(rings) - 1)
    faces += [[0, 2, 1], [0, 3, 2], [last, last + 1, last + 2], [last, last + 2, last + 3]]
    faces = np.array(faces, dtype=np.int64)
    if signed_volume(vertices, faces) < 0:
        faces = faces[:, ::-1]
    joints = np.zeros((len(vertices), 4), dtype=np.int64)
    joints[:, 0] = np.repeat(np.arange(len(rings)), 4)
    weights = np.zeros((len(vertices), 4))
    weights[:, 0] = 1.0
    return vertices, faces, joints, weights


def signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """The volume a closed mesh encloses, positive when its faces wind outward."""
    corners = vertices[faces]
    return float(np.einsum("ij,ij->i", corners[:, 0], np.cross(corners[:, 1], corners[:, 2])).sum() / 6.0)


def trs(translation=(0.0, 0.0, 0.0), rotation=(0.0, 0.0, 0.0, 1.0), scale=(1.0, 1.0, 1.0)) -> np.ndarray:
    """The 4x4 matrix of a glTF node's translation, rotation (x, y, z, w) and scale."""
    matrix = np.eye(4)
    matrix[:3, :3] = quat_to_matrix(np.asarray(rotation, dtype=np.float64)) * np.asarray(scale, dtype=np.float64)
    matrix[:3, 3] = translation
    return matrix


def apply(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ matrix[:3, :3].T + matrix[:3, 3]


def write_skin_glb(path: Path, nodes: list[gl.Node], skin_joints: list[int], inverse_bind: np.ndarray | None,
                   vertices: np.ndarray, faces: np.ndarray, joints: np.ndarray, weights: np.ndarray,
                   roots: list[int]) -> Path:
    """A GLB of ``nodes`` (one of them with ``mesh=0, skin=0``), one skin and the mesh, as pygltflib writes it."""
    gltf = gl.GLTF2(asset=gl.Asset(version="2.0"), scene=0, scenes=[gl.Scene(nodes=roots)], nodes=nodes)
    blob = bytearray()

    def add(array: np.ndarray, kind: str, component: int, target: int | None = None) -> int:
        data = np.ascontiguousarray(array).tobytes()
        gltf.bufferViews.append(gl.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data), target=target))
        blob.extend(data + b"\x00" * (-len(data) % 4))
        gltf.accessors.append(gl.Accessor(bufferView=len(gltf.bufferViews) - 1, componentType=component,
                                          count=len(array), type=kind))
        return len(gltf.accessors) - 1

    attributes = gl.Attributes(
        POSITION=add(vertices.astype(np.float32), "VEC3", gl.FLOAT, gl.ARRAY_BUFFER),
        JOINTS_0=add(joints.astype(np.uint8), "VEC4", gl.UNSIGNED_BYTE, gl.ARRAY_BUFFER),
        WEIGHTS_0=add(weights.astype(np.float32), "VEC4", gl.FLOAT, gl.ARRAY_BUFFER),
    )
    indices = add(faces.astype(np.uint16).reshape(-1), "SCALAR", gl.UNSIGNED_SHORT, gl.ELEMENT_ARRAY_BUFFER)
    gltf.meshes.append(gl.Mesh(primitives=[gl.Primitive(attributes=attributes, indices=indices)]))
    ibm = None
    if inverse_bind is not None:  # column-major: the transpose, row by row
        ibm = add(np.asarray(inverse_bind, dtype=np.float32).transpose(0, 2, 1).reshape(-1, 16), "MAT4", gl.FLOAT)
    gltf.skins.append(gl.Skin(joints=skin_joints, inverseBindMatrices=ibm))
    gltf.buffers.append(gl.Buffer(byteLength=len(blob)))
    gltf.set_binary_blob(bytes(blob))
    gltf.save_binary(str(path))
    return path


def armature_file(path: Path, armature: dict, mesh_node: dict | None = None,
                  spine: dict | None = None) -> tuple[Path, np.ndarray]:
    """Blender's layout: an ``Armature`` node (``armature`` TRS) over a 3-joint chain along its Z (in cm),
    the mesh node a scene root of its own; IBMs are the joints' inverse armature-space rest matrices.
    ``spine`` poses the middle joint away from its rest.

    Returns the file and the bar's stored vertices.
    """
    vertices, faces, joints, weights = bar(along=2, rings=(100.0, 150.0, 200.0))
    nodes = [
        gl.Node(name="Armature", children=[1], **armature),
        gl.Node(name="Hips", translation=[0.0, 0.0, 100.0], children=[2]),
        gl.Node(name="Spine", translation=[0.0, 0.0, 50.0], children=[3], **(spine or {})),
        gl.Node(name="Head", translation=[0.0, 0.0, 50.0]),
        gl.Node(name="Body", mesh=0, skin=0, **(mesh_node or {})),
    ]
    rest = np.array([[0.0, 0.0, 100.0], [0.0, 0.0, 150.0], [0.0, 0.0, 200.0]])
    inverse_bind = np.stack([trs(translation=-p) for p in rest])
    write_skin_glb(path, nodes, [1, 2, 3], inverse_bind, vertices, faces, joints, weights, roots=[0, 4])
    return path, vertices


def test_an_armature_turned_upright_and_scaled_to_metres_is_honoured(tmp_path):
    """Armature scale 0.01 and -90 degrees about X (Z up -> Y up): a stored vertex (x, y, z) cm is
    (x, z, -y) / 100 m in the scene, the joints likewise; the mesh node's own move is not drawn."""
    path, stored = armature_file(tmp_path / "blender.glb", {"rotation": Z_TO_Y_UP, "scale": [0.01] * 3},
                                 {"translation": [3.0, 0.0, 0.0]})
    skin = load_skin(path)
    expected = np.column_stack([stored[:, 0], stored[:, 2], -stored[:, 1]]) / 100.0
    np.testing.assert_allclose(skin.vertices, expected, atol=1e-6)
    assert skin.joint_names == ("Hips", "Spine", "Head")
    for name, height in (("Hips", 1.0), ("Spine", 1.5), ("Head", 2.0)):
        np.testing.assert_allclose(skin.bind[name], [0.0, height, 0.0], atol=1e-6)
    assert skin.parents == {"Spine": "Hips", "Head": "Spine"}
    assert signed_volume(skin.vertices, skin.faces) > 0
    assert skin.vertices[:, 1].min() == pytest.approx(1.0)  # standing on +Y, a metre up


def test_a_matrix_node_is_the_same_as_its_trs(tmp_path):
    """An armature given as a column-major ``matrix`` reads as the same TRS would."""
    matrix = trs(translation=(0.5, 0.0, -0.25), rotation=Z_TO_Y_UP, scale=(0.01,) * 3)
    by_matrix = load_skin(armature_file(tmp_path / "m.glb", {"matrix": [float(v) for v in matrix.T.ravel()]})[0])
    by_trs = load_skin(armature_file(tmp_path / "t.glb", {"translation": [0.5, 0.0, -0.25],
                                                          "rotation": Z_TO_Y_UP, "scale": [0.01] * 3})[0])
    np.testing.assert_allclose(by_matrix.vertices, by_trs.vertices, atol=1e-9)
    for name in by_trs.bind:
        np.testing.assert_allclose(by_matrix.bind[name], by_trs.bind[name], atol=1e-9)
    np.testing.assert_allclose(by_trs.bind["Hips"], [0.5, 1.0, -0.25], atol=1e-6)


def test_joints_posed_away_from_bind_use_the_mesh_node_and_the_inverse_bind_matrices(tmp_path):
    """The file's nodes stand in another pose (the middle joint turned 90 degrees about Z): the mesh
    is where its own node puts it, and each bind position is that node's matrix times the inverse IBM."""
    vertices, faces, joints, weights = bar(along=1, rings=(0.0, 1.0, 2.0), half=0.1)
    rest = np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 2.0, 0.0]])
    mesh_matrix = trs(translation=(1.0, 2.0, 3.0), scale=(2.0, 2.0, 2.0))
    nodes = [
        gl.Node(name="root", translation=[0.0, 0.0, 0.0], children=[1]),
        gl.Node(name="elbow", translation=[0.0, 1.0, 0.0], rotation=[0.0, 0.0, HALF, HALF], children=[2]),
        gl.Node(name="hand", translation=[0.0, 1.0, 0.0]),
        gl.Node(name="mesh", mesh=0, skin=0, translation=[1.0, 2.0, 3.0], scale=[2.0, 2.0, 2.0]),
    ]
    inverse_bind = np.stack([trs(translation=-p) for p in rest])
    path = write_skin_glb(tmp_path / "posed.glb", nodes, [0, 1, 2], inverse_bind, vertices, faces, joints, weights,
                          roots=[0, 3])
    skin = load_skin(path)
    np.testing.assert_allclose(skin.vertices, apply(mesh_matrix, vertices), atol=1e-6)
    for name, position in zip(("root", "elbow", "hand"), rest):
        np.testing.assert_allclose(skin.bind[name], apply(mesh_matrix, position[None])[0], atol=1e-6)
    # Not the posed hand: the elbow's turn would have put it at (-1, 1, 0) before the mesh node's matrix.
    assert np.linalg.norm(skin.bind["hand"] - apply(mesh_matrix, np.array([[-1.0, 1.0, 0.0]]))[0]) > 1.0
    assert signed_volume(skin.vertices, skin.faces) > 0


def test_parents_follow_the_node_tree_past_nodes_that_are_not_joints(tmp_path):
    """Joint parents skip a non-joint node between two joints (and one above the root); roots are absent.
    A joint listed before its parent in the skin, and a node outside every scene, still get theirs."""
    vertices, faces, joints, weights = bar(along=1, rings=(0.0, 1.0, 2.0), half=0.1)
    nodes = [
        gl.Node(name="Armature", children=[1]),
        gl.Node(name="pelvis", children=[2]),
        gl.Node(name="pelvis_twist_helper", translation=[0.0, 0.5, 0.0], children=[3]),
        gl.Node(name="chest", translation=[0.0, 0.5, 0.0], children=[4]),
        gl.Node(name="neck", translation=[0.0, 1.0, 0.0]),
        gl.Node(name="mesh", mesh=0, skin=0),
    ]
    rest = np.array([[0.0, 2.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]])
    inverse_bind = np.stack([trs(translation=-p) for p in rest])
    path = write_skin_glb(tmp_path / "tree.glb", nodes, [4, 3, 1], inverse_bind, vertices, faces, joints, weights,
                          roots=[5])  # the armature is in no scene
    skin = load_skin(path)
    assert skin.joint_names == ("neck", "chest", "pelvis")
    assert skin.parents == {"neck": "chest", "chest": "pelvis"}
    np.testing.assert_allclose(skin.bind["neck"], [0.0, 2.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(skin.vertices, vertices, atol=1e-6)


def test_repeated_and_missing_joint_names_are_made_unique(tmp_path):
    """Two nodes named ``bone`` (and a third already called ``bone_2``) and one without a name:
    every joint keeps a name of its own, the same every time."""
    vertices, faces, joints, weights = bar(along=1, rings=(0.0, 1.0, 2.0, 3.0), half=0.1)
    nodes = [
        gl.Node(name="bone", children=[1]),
        gl.Node(name="bone", translation=[0.0, 1.0, 0.0], children=[2]),
        gl.Node(name="bone_2", translation=[0.0, 1.0, 0.0], children=[3]),
        gl.Node(translation=[0.0, 1.0, 0.0]),
        gl.Node(name="mesh", mesh=0, skin=0),
    ]
    inverse_bind = np.stack([trs(translation=(0.0, -float(k), 0.0)) for k in range(4)])
    path = write_skin_glb(tmp_path / "names.glb", nodes, [0, 1, 2, 3], inverse_bind, vertices, faces, joints,
                          weights, roots=[0, 4])
    first, again = load_skin(path), load_skin(path)
    assert first.joint_names == again.joint_names == ("bone", "bone_3", "bone_2", "joint3")
    assert first.parents == {"bone_3": "bone", "bone_2": "bone_3", "joint3": "bone_2"}
    np.testing.assert_allclose(first.bind["joint3"], [0.0, 3.0, 0.0], atol=1e-6)


@pytest.mark.parametrize("where", ["armature", "posed mesh node"])
def test_a_mirror_keeps_the_faces_wound_outward(tmp_path, where):
    """Scale -1 on X (in the armature at bind, or in the mesh node of a posed file): the loaded
    mesh is mirrored and its faces are turned so that it still encloses a positive volume."""
    if where == "armature":
        path, stored = armature_file(tmp_path / "mirror.glb", {"scale": [-1.0, 1.0, 1.0]})
    else:
        path, stored = armature_file(tmp_path / "mirror.glb", {}, {"scale": [-1.0, 1.0, 1.0]},
                                     {"rotation": [HALF, 0.0, 0.0, HALF]})
    skin = load_skin(path)
    np.testing.assert_allclose(skin.vertices, stored * [-1.0, 1.0, 1.0], atol=1e-6)
    assert signed_volume(stored, bar(along=2, rings=(100.0, 150.0, 200.0))[1]) > 0
    assert signed_volume(skin.vertices, skin.faces) > 0


def z_up(motion: Motion) -> Motion:
    """The clip with its whole world turned +90 degrees about X (Y up becomes Z up), through a BVH file."""
    q = np.array([HALF, 0.0, 0.0, HALF])
    s = motion.skeleton
    ends = np.where(np.isfinite(s.end_sites), quat_rotate(q, np.nan_to_num(s.end_sites)), np.nan)
    skeleton = Skeleton(s.names, s.parents, quat_rotate(q, s.offsets), s.channels, ends)
    rotations = quat_mul(quat_mul(q, motion.local_rotations), q * np.array([-1, -1, -1, 1]))
    return load_bvh(io.BytesIO(format_bvh(Motion(skeleton, motion.frame_time, rotations,
                                                      quat_rotate(q, motion.local_positions)))))


@pytest.mark.parametrize("turn", ["y up", "z up"])
def test_our_own_glb_reads_back_at_the_clips_rest_pose_upright_in_metres(tmp_path, turn):
    """make_glb on the original skeleton, read back as a skin: the bind positions are the clip's rest
    positions turned upright (`UPRIGHT`) and in metres, the vertices the weights file's likewise."""
    motion = load_bvh(SAMPLE_DIR / "cmu_09_01_run_daz.bvh")
    if turn == "z up":
        motion = z_up(motion)
    result = run(motion, resolve_config("cartoon", None, {"output": {"skeleton": "original"}}))
    glb, weights_npz, _ = make_glb(motion, result)
    path = tmp_path / "ours.glb"
    path.write_bytes(glb)
    skin = load_skin(path)

    skeleton = result.motion.skeleton
    scale = unit_scale("auto", motion.skeleton.height())[0]
    up = standing_up(motion.skeleton, motion.world_positions()[:: max(motion.num_frames // 64, 1)])
    assert up == ((2, 1.0) if turn == "z up" else (1, 1.0))
    upright = quat_to_matrix(np.array(UPRIGHT[up]))
    rest = skeleton.rest_positions() @ upright.T * scale
    assert skin.joint_names == tuple(skeleton.names)
    for j, name in enumerate(skeleton.names):
        np.testing.assert_allclose(skin.bind[name], rest[j], atol=1e-5)
    stored = np.load(io.BytesIO(weights_npz))
    np.testing.assert_allclose(skin.vertices, stored["vertices"] @ upright.T * scale, atol=1e-5)
    np.testing.assert_array_equal(skin.faces, stored["faces"])
    parents = {name: skeleton.names[p] for name, p in zip(skeleton.names, skeleton.parents) if p >= 0}
    assert skin.parents == parents
    assert skin.bind["head"][1] > max(skin.bind["lFoot"][1], skin.bind["rFoot"][1]) + 0.7  # standing on +Y


@pytest.mark.parametrize("edit, words", [
    (lambda nodes: setattr(nodes[1], "children", [2, 0]), "loops"),
    (lambda nodes: setattr(nodes[2], "children", [2]), "its own child"),
    (lambda nodes: setattr(nodes[2], "children", [99]), "not a node"),
    (lambda nodes: setattr(nodes[0], "rotation", [0.0, 0.0, 0.0, 0.0]), "rotation"),
    (lambda nodes: setattr(nodes[0], "scale", [1.0, None, 1.0]), "readable"),  # pygltflib refuses it
    (lambda nodes: setattr(nodes[0], "matrix", [1.0] * 15), "matrix"),
    (lambda nodes: setattr(nodes[0], "translation", ["up", 0, 0]), "readable"),
    # Scales that overflow once composed down the tree: one message, no RuntimeWarning on the way.
    (lambda nodes: setattr(nodes[0], "scale", [1e200, 1e200, 1e200]), "node transforms must be finite"),
])
def test_a_broken_node_tree_is_an_input_error(tmp_path, edit, words):
    """Loops, bad children and transforms that are not numbers end in an InputError naming the fault."""
    vertices, faces, joints, weights = bar(along=2, rings=(100.0, 150.0, 200.0))
    nodes = [
        gl.Node(name="Armature", children=[1]),
        gl.Node(name="Hips", translation=[0.0, 0.0, 100.0], children=[2]),
        gl.Node(name="Spine", translation=[0.0, 0.0, 50.0], children=[3]),
        gl.Node(name="Head", translation=[0.0, 0.0, 50.0]),
        gl.Node(name="Body", mesh=0, skin=0),
    ]
    edit(nodes)
    path = write_skin_glb(tmp_path / "broken.glb", nodes, [1, 2, 3], None, vertices, faces, joints, weights,
                          roots=[0, 4])
    with pytest.raises(InputError, match=words):
        load_skin(path)
    with pytest.raises(InputError, match=words):
        load_gltf_skin(path)
