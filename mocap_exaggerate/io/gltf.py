"""Skinned glTF 2.0 binary (GLB) output, written with pygltflib.

One node per joint (rest translation = the BVH offset, identity rotation,
exactly the BVH's rest pose), one skin whose inverse bind matrices undo the
rest pose, the mesh with POSITION, NORMAL, JOINTS_0 and WEIGHTS_0 (and a
second set for 8 influences), and one
animation with a translation and a rotation sampler per joint (6-DOF, as the
BVH). Units are metres; BVH units are given or guessed from the skeleton's
height.
"""

from __future__ import annotations

import dataclasses
import json
import struct

import numpy as np
import pygltflib as gl

from ..core.errors import ConfigError
from ..core.motion import Motion
from ..core.rotations import quat_mul, quat_rotate, unit_track
from ..rig.skinning import Skin
from .units import UNITS, guessed_units_warning, unit_scale

__all__ = ["UNITS", "UPRIGHT", "unit_scale", "guessed_units_warning", "format_glb", "glb_pieces", "vertex_normals"]

def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit normals ``(V, 3)``: the faces' normals around each vertex, weighted by the corner angle there.

    The same as ``trimesh.Trimesh.vertex_normals``, without trimesh's import
    (0.33 s of every command). A vertex on no face (or only on faces of no
    area) gets +Z, so the validator still sees unit normals.
    """
    corners = vertices[faces]  # (T, 3, 3)
    face = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    face /= np.maximum(np.linalg.norm(face, axis=1, keepdims=True), 1e-300)
    summed = np.zeros((len(vertices), 3))
    for k in range(3):
        u = corners[:, (k + 1) % 3] - corners[:, k]
        w = corners[:, (k + 2) % 3] - corners[:, k]
        angle = np.arctan2(np.linalg.norm(np.cross(u, w), axis=1), np.einsum("ij,ij->i", u, w))
        for axis in range(3):
            summed[:, axis] += np.bincount(faces[:, k], weights=face[:, axis] * angle, minlength=len(vertices))
    norm = np.linalg.norm(summed, axis=1, keepdims=True)
    fallback = np.zeros_like(summed)
    fallback[:, 2] = 1.0
    return np.where(norm > 1e-300, summed / np.where(norm > 0, norm, 1.0), fallback)


def _pad4(data: bytes) -> bytes:
    return data + b"\x00" * (-len(data) % 4)


class _Buffer:
    """Accumulates binary data (as pieces, never copied into one blob) and the bufferViews/accessors into it."""

    def __init__(self, gltf: gl.GLTF2) -> None:
        self.gltf = gltf
        self.pieces: list[bytes] = []
        self.length = 0

    def add(self, array: np.ndarray, kind: str, component: int, *, target: int | None = None,
            bounds: bool = False, normalized: bool = False) -> int:
        data = np.ascontiguousarray(array)
        offset = self.length
        self.pieces.append(_pad4(data.tobytes()))
        self.length += len(self.pieces[-1])
        self.gltf.bufferViews.append(gl.BufferView(buffer=0, byteOffset=offset, byteLength=data.nbytes, target=target))
        accessor = gl.Accessor(
            bufferView=len(self.gltf.bufferViews) - 1,
            componentType=component,
            count=len(data),
            type=kind,
            normalized=normalized or None,
        )
        if bounds:
            flat = data.reshape(len(data), -1)
            accessor.min = [float(v) for v in flat.min(axis=0)]
            accessor.max = [float(v) for v in flat.max(axis=0)]
        self.gltf.accessors.append(accessor)
        return len(self.gltf.accessors) - 1


def _weights_for_gltf(weights: np.ndarray) -> np.ndarray:
    """float32 weights whose rows sum to 1 after the cast (the validator checks it)."""
    w = weights.astype(np.float32)
    total = w.sum(axis=1, keepdims=True)
    w = np.divide(w, total, out=w.copy(), where=total > 0).astype(np.float32)
    strongest = np.argmax(w, axis=1)
    rest = w.sum(axis=1) - w[np.arange(len(w)), strongest]
    w[np.arange(len(w)), strongest] = (np.float32(1.0) - rest).astype(np.float32)
    return w


def gltf_json(gltf: gl.GLTF2) -> str:
    """``gltf.gltf_to_json(separators=(",", ":"), indent=None)``, the same text, five times faster.

    pygltflib deep-copies every value of the document on its way to a dict;
    on an animated skeleton (a few thousand nodes, accessors, samplers and
    channels) that is 0.1 s of the GLB's 0.25 s, all of it holding the GIL.
    Here the dataclasses are walked once, sharing the values (they are only
    read), and pygltflib's own rule drops the empty keys.
    """
    return json.dumps(gl.delete_empty_keys(_plain(gltf)), cls=gl.JsonEncoder, default=gl.json_serial,
                      allow_nan=False, skipkeys=True, separators=(",", ":"))


_FIELDS: dict[type, tuple[str, ...]] = {}
_LEAVES = (int, float, str, bool, type(None))


def _plain(value):
    """A pygltflib object as the dicts and lists pygltflib's ``gltf_asdict`` makes of it."""
    kind = type(value)
    if kind in _LEAVES:
        return value
    if kind is gl.Attributes:  # its keys are open-ended: pygltflib takes its __dict__ as it is
        return dict(value.__dict__)
    if kind in (list, tuple):
        return kind(_plain(item) for item in value)
    if kind is dict:
        return {_plain(key): _plain(item) for key, item in value.items()}
    names = _FIELDS.get(kind)
    if names is None:
        if not dataclasses.is_dataclass(kind):
            return value
        names = _FIELDS[kind] = tuple(field.name for field in dataclasses.fields(kind))
    return {name: _plain(getattr(value, name)) for name in names}


def format_glb(motion: Motion, skin: Skin, *, meters_per_unit: float = 1.0, name: str = "mocap_exaggerate",
               thickness: np.ndarray | None = None) -> bytes:
    """The whole GLB as bytes (see `glb_pieces`)."""
    return b"".join(glb_pieces(motion, skin, meters_per_unit=meters_per_unit, name=name, thickness=thickness))


#: glTF's up is +Y and its front +Z. The turn (x, y, z, w) that stands a clip whose body stands
#: along (axis, sign) on +Y, about the other horizontal axis, so a Z-up clip's -Y front (Blender's,
#: 3ds Max's, MakeHuman's) becomes +Z, as Blender's own glTF exporter turns it.
_HALF = float(np.sqrt(0.5))
UPRIGHT = {
    (1, 1.0): (0.0, 0.0, 0.0, 1.0),
    (2, 1.0): (-_HALF, 0.0, 0.0, _HALF),
    (2, -1.0): (_HALF, 0.0, 0.0, _HALF),
    (0, 1.0): (0.0, 0.0, _HALF, _HALF),
    (0, -1.0): (0.0, 0.0, -_HALF, _HALF),
    (1, -1.0): (0.0, 0.0, 1.0, 0.0),
}


def glb_pieces(motion: Motion, skin: Skin, *, meters_per_unit: float = 1.0, name: str = "mocap_exaggerate",
               thickness: np.ndarray | None = None, up: tuple[int, float] = (1, 1.0)) -> list[bytes]:
    """The GLB as consecutive pieces of bytes, to be written one after the other.

    motion : the output Motion (its skeleton is the one the skin is bound to)
    skin : bound to ``motion.skeleton``'s joints by name, in its rest pose
    thickness : (F, J) float64 or None, the world scale wanted for each joint
        (volume preservation: 1/sqrt(stretch)). Written as uniform node
        scales with each child's translation divided by its parent's world
        scale, so every joint stays exactly where the BVH puts it and children
        are never sheared; the mesh around a thinner joint shrinks about it.
    up : the axis the clip's body stands along and its sign (`limbs.standing_up`).
        glTF is +Y up: another up is turned onto +Y (`UPRIGHT`) in the root
        joint, its rest and its tracks, and in the mesh, so the file stands on
        +Y with no extra node, and every joint below the root is unchanged.
    """
    skeleton = motion.skeleton
    index = {n: j for j, n in enumerate(skeleton.names)}
    missing = [n for n in skin.joint_names if n not in index]
    if missing:
        raise ConfigError(f"skin joints not in the output skeleton: {', '.join(missing[:5])}")
    scale = float(meters_per_unit)
    gltf = gl.GLTF2(asset=gl.Asset(generator="mocap_exaggerate", version="2.0"))
    gltf.scene = 0
    buffer = _Buffer(gltf)

    try:
        upright = np.array(UPRIGHT[(int(up[0]), float(up[1]))])
    except KeyError:
        raise ConfigError(f"up must be an axis 0, 1 or 2 and a sign 1 or -1, got {up!r}") from None
    turned = not np.array_equal(upright, UPRIGHT[(1, 1.0)])
    turn = quat_rotate(upright, np.eye(3)).T  # the matrix: column i is where axis i goes

    # Joint nodes, rest pose: translation = offset, no rotation (the root: turned upright).
    children = [[] for _ in range(skeleton.num_joints)]
    for j in range(1, skeleton.num_joints):
        children[skeleton.parents[j]].append(j)
    for j in range(skeleton.num_joints):
        offset = turn @ skeleton.offsets[j] if j == 0 else skeleton.offsets[j]
        node = gl.Node(name=skeleton.names[j], translation=[float(v) * scale for v in offset])
        if j == 0 and turned:
            node.rotation = [float(v) for v in upright]
        if children[j]:
            node.children = children[j]
        gltf.nodes.append(node)
    mesh_node = skeleton.num_joints
    gltf.nodes.append(gl.Node(name=f"{name}_body", mesh=0, skin=0))
    gltf.scenes.append(gl.Scene(nodes=[0, mesh_node]))

    rest = skeleton.rest_positions() * scale
    inverse_bind = np.zeros((skeleton.num_joints, 4, 4), dtype=np.float32)
    inverse_bind[:] = np.eye(4, dtype=np.float32)
    inverse_bind[:, :3, :3] = turn.T  # every joint's rest frame is the root's turn; its inverse
    inverse_bind[:, :3, 3] = -rest
    # glTF matrices are column-major: store the transpose row by row.
    ibm = buffer.add(inverse_bind.transpose(0, 2, 1).reshape(-1, 16), "MAT4", gl.FLOAT)
    gltf.skins.append(gl.Skin(joints=list(range(skeleton.num_joints)), inverseBindMatrices=ibm, skeleton=0))

    positions = (skin.vertices @ turn.T * scale).astype(np.float32)
    normals = (vertex_normals(skin.vertices, skin.faces) @ turn.T).astype(np.float32)
    remap = np.array([index[n] for n in skin.joint_names], dtype=np.int64)
    sets = 2 if skin.weights.shape[1] > 4 else 1  # 8 influences need a second JOINTS/WEIGHTS pair
    columns = 4 * sets
    raw = np.zeros((skin.num_vertices, columns))
    ids = np.zeros((skin.num_vertices, columns), dtype=np.int64)
    raw[:, : skin.weights.shape[1]] = skin.weights[:, :columns]
    ids[:, : skin.joints.shape[1]] = skin.joints[:, :columns]
    weights = _weights_for_gltf(raw)
    joints = np.where(weights > 0, remap[ids], 0)
    joint_type, joint_dtype = (gl.UNSIGNED_BYTE, np.uint8) if skeleton.num_joints <= 255 else (gl.UNSIGNED_SHORT, np.uint16)
    attributes = gl.Attributes(
        POSITION=buffer.add(positions, "VEC3", gl.FLOAT, target=gl.ARRAY_BUFFER, bounds=True),
        NORMAL=buffer.add(normals, "VEC3", gl.FLOAT, target=gl.ARRAY_BUFFER),
    )
    for number in range(sets):
        part = slice(4 * number, 4 * number + 4)
        setattr(attributes, f"JOINTS_{number}",
                buffer.add(joints[:, part].astype(joint_dtype), "VEC4", joint_type, target=gl.ARRAY_BUFFER))
        setattr(attributes, f"WEIGHTS_{number}",
                buffer.add(np.ascontiguousarray(weights[:, part]), "VEC4", gl.FLOAT, target=gl.ARRAY_BUFFER))
    vertex_index = gl.UNSIGNED_INT if len(positions) > 65535 else gl.UNSIGNED_SHORT
    index_dtype = np.uint32 if vertex_index == gl.UNSIGNED_INT else np.uint16
    indices = buffer.add(skin.faces.astype(index_dtype).reshape(-1), "SCALAR", vertex_index,
                         target=gl.ELEMENT_ARRAY_BUFFER)
    gltf.meshes.append(gl.Mesh(name=f"{name}_body", primitives=[gl.Primitive(attributes=attributes, indices=indices)]))

    # Animation: one translation and one rotation sampler per joint.
    times = (np.arange(motion.num_frames) * motion.frame_time).astype(np.float32)
    time_accessor = buffer.add(times, "SCALAR", gl.FLOAT, bounds=True)
    if thickness is not None:
        thickness = np.asarray(thickness, dtype=np.float64)
    samplers, channels = [], []
    rotations = np.ascontiguousarray(motion.local_rotations, dtype=np.float64)  # (each joint's track read where it lies)
    for j in range(skeleton.num_joints):
        # Joint by joint: float32 tracks made one at a time keep long clips' memory flat.
        translation = motion.local_positions[:, j] * scale
        if j == 0 and turned:
            rotation = unit_track(quat_mul(upright, rotations[:, j])).astype(np.float32)
            translation = translation @ turn.T
        else:
            rotation = unit_track(rotations, j).astype(np.float32)
        node_scale = None
        if thickness is not None:  # joint by joint too: no (F, J) arrays beside the thickness
            parent_world = thickness[:, skeleton.parents[j]] if j > 0 else np.ones(motion.num_frames)
            translation = translation / parent_world[:, None]
            node_scale = thickness[:, j] / parent_world
        tracks = [("translation", translation.astype(np.float32), "VEC3"), ("rotation", rotation, "VEC4")]
        if node_scale is not None and np.any(np.abs(node_scale - 1.0) > 1e-6):
            tracks.append(("scale", np.repeat(node_scale[:, None], 3, axis=1).astype(np.float32), "VEC3"))
        for path, values, kind in tracks:
            output = buffer.add(values, kind, gl.FLOAT)
            samplers.append(gl.AnimationSampler(input=time_accessor, output=output, interpolation="LINEAR"))
            channels.append(gl.AnimationChannel(sampler=len(samplers) - 1,
                                                target=gl.AnimationChannelTarget(node=j, path=path)))
    gltf.animations.append(gl.Animation(name=name, samplers=samplers, channels=channels))
    gltf.buffers.append(gl.Buffer(byteLength=buffer.length))
    # The GLB container by hand (12-byte header, JSON chunk, BIN chunk): pygltflib's
    # writer copies the binary blob three times, which on a long clip is 60 MB more.
    json_blob = gltf_json(gltf).encode("utf-8")
    json_blob += b" " * (-len(json_blob) % 4)
    total = 12 + 8 + len(json_blob) + 8 + buffer.length
    return [struct.pack("<4sII", b"glTF", 2, total), struct.pack("<I4s", len(json_blob), b"JSON"), json_blob,
            struct.pack("<I4s", buffer.length, b"BIN\x00"), *buffer.pieces]

