"""Skin file formats: NPZ, glTF/GLB skinned meshes and MakeHuman (.obj + .mhw) readers, the NPZ bytes writer.

The `Skin` type itself and influence pruning live in `mocap_exaggerate.rig.skinning`.
"""

from __future__ import annotations

import base64
import binascii
import json
import os
import struct
import urllib.parse
import zipfile
import zlib
from pathlib import Path

import numpy as np

from ..core.errors import InputError, printable
from ..core.rotations import quat_to_matrix, vector_norm
from ..rig.skinning import Skin, top_influences
from .files import LIMITS, read_limited, regular_file

__all__ = ["load_skin", "check_skin", "load_npz_skin", "load_gltf_skin", "load_makehuman_skin", "npz_bytes", "open_gltf"]


def load_npz_skin(path: str | os.PathLike) -> Skin:
    """A skin from ``.npz``: vertices, faces, joint_names, and either joints + weights
    ``(V, K)`` or dense weights ``(V, J)``; and ``rest_pose (J, 4)`` (x, y, z, w local rotations)
    where the mesh is bound to the joints posed by it, not in their rest pose (`Skin.pose`:
    what the weights file of a character bound in its own pose holds)."""
    label = str(path)
    try:
        regular_file(path, what=".npz skin", label=label)
        with zipfile.ZipFile(path) as archive:  # the members' sizes, as the archive declares them, first
            declared = sum(member.file_size for member in archive.infolist())
        if declared > LIMITS["character"]:
            raise InputError(f"unpacks to {declared / (1 << 30):.3g} GiB; a skin is read up to "
                             f"{LIMITS['character'] >> 30} GiB", source=label)
        with np.load(path, allow_pickle=False) as archive:
            data = {name: archive[name] for name in archive.files}  # read now: a bad CRC shows here
    except InputError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile, EOFError, zlib.error, MemoryError) as error:
        # (a member's header may declare more than its bytes: numpy's MemoryError before it reads them)
        raise InputError(f"not a readable .npz skin ({type(error).__name__}: {str(error)[:120]})", source=label) from None
    missing = {"vertices", "faces", "joint_names", "weights"} - set(data)
    if missing:
        raise InputError(f"skin .npz lacks {', '.join(sorted(missing))}", source=label)
    for name in ("vertices", "faces", "joints", "weights"):  # (complex vertices lost their imaginary part, warning)
        if name in data and data[name].dtype.kind not in "biuf":
            raise InputError(f"the skin's {name} must be real numbers, got {data[name].dtype}", source=label)
    names = tuple(str(n) for n in data["joint_names"])
    weights = np.asarray(data["weights"], dtype=np.float64)
    if "joints" in data:
        joints = data["joints"]
    else:
        if weights.ndim != 2 or weights.shape[1] != len(names):
            raise InputError(f"dense weights must be (V, {len(names)}), got {weights.shape}", source=label)
        rows, cols = np.nonzero(weights)
        joints, weights = top_influences(rows, cols, weights[rows, cols], len(weights), 4)
    pose = {}
    if "rest_pose" in data:
        turns = np.asarray(data["rest_pose"])
        if turns.dtype.kind != "f" or turns.ndim != 2 or turns.shape[1:] != (4,):
            raise InputError(f"rest_pose must be (J, 4) float quaternions (x, y, z, w), one a joint, got "
                             f"{turns.dtype} {turns.shape}", source=label)
        if len(turns) != len(names):
            raise InputError(f"rest_pose has {len(turns)} rows and joint_names names {len(names)} joints: one "
                             "quaternion a joint", source=label)
        if not np.all(np.isfinite(turns)):
            raise InputError("rest_pose holds a value that is not finite (NaN or infinite)", source=label)
        # (a part past 1 is not of a unit quaternion: said before a norm of 1e308s overflows into a warning)
        if len(turns) and (np.abs(turns).max() > 1.0 + 1e-4 or np.abs(np.linalg.norm(turns, axis=1) - 1.0).max() > 1e-4):
            raise InputError("rest_pose holds a quaternion that is not of unit length", source=label)
        turns = turns / np.linalg.norm(turns, axis=1, keepdims=True)
        pose = {names[k]: tuple(map(float, turns[k])) for k in range(len(names)) if abs(turns[k, 3]) < 1.0}
    try:
        return Skin(data["vertices"], data["faces"], names, joints, weights, pose=pose)
    except ValueError as error:
        raise InputError(str(error), source=label) from None


def load_makehuman_skin(obj_path: str | os.PathLike, weights_path: str | os.PathLike | None = None) -> Skin:
    """The MakeHuman base mesh's ``body`` group with its ``.mhw`` weights (bones named as in its BVH)."""
    obj_path = Path(obj_path)
    if weights_path is None:
        found = sorted(obj_path.parent.glob("*.mhw"))
        if not found:
            raise InputError("no .mhw weights file beside the .obj", source=str(obj_path))
        if len(found) > 1:  # (the first by name was taken without a word: an edited copy beside it went unseen)
            shown = ", ".join(printable(p.name[:80]) for p in found[:4]) + (", ..." if len(found) > 4 else "")
            raise InputError(f"{len(found)} .mhw weights files beside the .obj ({shown}): keep only the one to use "
                             "beside it", source=str(obj_path))
        weights_path = found[0]
    vertices, faces = _read_obj_group(obj_path, "body")
    try:
        table = json.loads(read_limited(Path(weights_path), limit=LIMITS["text"], what="MakeHuman weights file")
                           .decode("utf-8"))["weights"]
    except (OSError, ValueError, KeyError, TypeError, RecursionError) as error:
        raise InputError(f"not a MakeHuman weights file ({type(error).__name__})", source=str(weights_path)) from None
    used = np.unique(faces)
    remap = np.full(len(vertices), -1)
    remap[used] = np.arange(len(used))
    names = tuple(sorted(table))
    rows, cols, values = [], [], []
    for column, name in enumerate(names):
        pairs = np.asarray(table[name], dtype=np.float64).reshape(-1, 2)
        index = pairs[:, 0].astype(np.int64)
        keep = (index < len(vertices)) & (remap[np.clip(index, 0, len(vertices) - 1)] >= 0)
        rows.append(remap[index[keep]])
        cols.append(np.full(int(keep.sum()), column))
        values.append(pairs[keep, 1])
    joints, weights = top_influences(np.concatenate(rows), np.concatenate(cols), np.concatenate(values), len(used), 8)
    bind, parents = {}, {}
    skeleton_files = sorted(obj_path.parent.glob("*.mhskel"))
    if skeleton_files:
        # Bone heads in the mesh's own (A-)pose: each joint is the mean of its vertex group.
        try:
            rig = json.loads(read_limited(skeleton_files[0], limit=LIMITS["text"], what="MakeHuman skeleton file")
                             .decode("utf-8"))
        except (OSError, ValueError, RecursionError) as error:
            raise InputError(f"not a MakeHuman skeleton file ({type(error).__name__})",
                             source=str(skeleton_files[0])) from None
        for name, bone in rig.get("bones", {}).items():
            group = rig.get("joints", {}).get(bone.get("head"), [])
            if group:
                bind[name] = vertices[np.asarray(group, dtype=np.int64)].mean(axis=0)
            if bone.get("parent"):
                parents[name] = str(bone["parent"])
    return Skin(vertices[used], remap[faces], names, joints, weights, bind, parents)


def _read_obj_group(path: Path, group: str) -> tuple[np.ndarray, np.ndarray]:
    """All vertices and the triangulated faces of one group of an OBJ file."""
    try:
        text = read_limited(path, limit=LIMITS["character"], what="OBJ file").decode("utf-8", errors="replace")
    except OSError as error:
        raise InputError(f"cannot read ({error.strerror})", source=str(path)) from None
    vertices, faces = [], []
    current = None
    for _number, line in enumerate(text.splitlines(), start=1):
        if line.startswith("v "):
            vertices.append(line.split()[1:4])
        elif line.startswith("g "):
            current = line[2:].strip()
        elif line.startswith("f ") and current == group:
            corners = [int(part.split("/")[0]) - 1 for part in line.split()[1:]]
            faces.extend([corners[0], corners[i], corners[i + 1]] for i in range(1, len(corners) - 1))
    if not faces:
        raise InputError(f"no faces in group {group!r}", source=str(path))
    return np.array(vertices, dtype=np.float64), np.array(faces, dtype=np.int64)


#: Most nodes a glTF/GLB file may have (joints, meshes and the rest): a character has a few hundred; the
#: skeleton is held to the BVH reader's 2,000 joints.
MAX_NODES = 5000


def _node_count(path: str | os.PathLike) -> int:
    """How many nodes the file's JSON lists, read before pygltflib reads it (0 where the JSON cannot be read:
    pygltflib then says what is wrong)."""
    try:
        with open(path, "rb") as stream:
            head = stream.read(20)
            if head[:4] == b"glTF":  # GLB: a 12-byte header, then the JSON chunk's length and type
                length = struct.unpack_from("<I", head, 12)[0]
                text = stream.read(min(length, LIMITS["character"]))
            else:
                text = head + stream.read(LIMITS["character"])
        nodes = json.loads(text).get("nodes") or []
        return len(nodes) if isinstance(nodes, list) else 0
    except (OSError, ValueError, RecursionError, AttributeError, struct.error):
        return 0


def open_gltf(path: str | os.PathLike):
    """A glTF/GLB file and a function reading its accessor ``index`` as a ``(count, width)`` array.

    Every number of an accessor is checked before a view is made over the buffer: a hostile
    file must not make it read outside (a negative stride once crashed the process).
    """
    import pygltflib as gl

    label = str(path)
    try:
        if regular_file(path, what="glTF file", label=label).st_size > LIMITS["character"]:
            raise InputError(f"is over {LIMITS['character'] >> 30} GiB; a character is read up to that", source=label)
    except OSError as error:
        raise InputError(f"cannot read ({error.strerror or error})", source=label) from None
    nodes = _node_count(path)
    if nodes > MAX_NODES:  # (pygltflib makes an object of each: 50,000 nodes took 21 s before any check)
        raise InputError(f"the file has {nodes:,} nodes; at most {MAX_NODES:,} are read", source=label)
    try:
        gltf = gl.GLTF2().load(str(path))
    except Exception as error:  # pygltflib raises many kinds on bad files
        raise InputError(f"not a readable glTF/GLB file ({type(error).__name__}: {error})", source=label) from None
    blob = gltf.binary_blob() if str(path).lower().endswith(".glb") else None

    def read(index: int) -> np.ndarray:
        if not (type(index) is int and 0 <= index < len(gltf.accessors)):
            raise InputError(f"accessor {str(index)[:20]!r} is not in the file", source=label)
        accessor = gltf.accessors[index]
        if accessor.bufferView is None or not 0 <= accessor.bufferView < len(gltf.bufferViews):
            raise InputError(f"accessor {index} has no buffer view", source=label)
        view = gltf.bufferViews[accessor.bufferView]
        data = blob if blob is not None else _buffer_data(gltf.buffers[view.buffer].uri, Path(path).parent, label)
        if data is None:
            raise InputError("the GLB has no binary chunk", source=label)
        width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}[accessor.type]  # KeyError: the caller's
        dtype = {gl.FLOAT: np.float32, gl.UNSIGNED_BYTE: np.uint8, gl.UNSIGNED_SHORT: np.uint16,
                 gl.UNSIGNED_INT: np.uint32}[accessor.componentType]
        item = np.dtype(dtype).itemsize * width
        stride = view.byteStride or item
        count = accessor.count
        view_start, offset = view.byteOffset or 0, accessor.byteOffset or 0
        view_length = view.byteLength or 0
        if not (isinstance(count, int) and count >= 1 and stride >= item and view_start >= 0 and offset >= 0
                and offset + stride * (count - 1) + item <= view_length
                and view_start + view_length <= len(data)):
            raise InputError(f"accessor {index} does not fit inside its buffer view", source=label)
        raw = np.frombuffer(data, dtype=np.uint8, count=stride * (count - 1) + item, offset=view_start + offset)
        rows = np.lib.stride_tricks.as_strided(raw, shape=(count, item), strides=(stride, 1))
        values = np.ascontiguousarray(rows).view(dtype).reshape(accessor.count, width)
        if accessor.normalized and dtype != np.float32:
            values = values / np.iinfo(dtype).max
        return values

    return gltf, read


def load_gltf_skin(path: str | os.PathLike) -> Skin:
    """A glTF/GLB file's character as it stands in the file's scene, in world space: every mesh that
    rides on the skeleton of its first skinned mesh.

    The skeleton is the first skinned mesh's skin. Its mesh, every other mesh skinned to joints of
    the same skeleton, and every mesh whose node hangs below one of its joints (a game character
    made of rigid pieces parented to its bones, as the Quaternius robot is; such a piece moves
    with its nearest joint, weight 1), all their triangle primitives, make one skin.

    Node transforms count (an armature turned Z-up to Y-up, scaled by 0.01, a
    mesh node moved): a viewer draws the bind pose at ``world(joint) @ IBM @ v``,
    so when every joint gives the same ``world(joint) @ IBM`` (the nodes stand at
    bind) that one matrix places the mesh and ``bind`` holds the joint nodes'
    world positions. Otherwise the nodes are posed away from bind, and the
    mesh node's world matrix carries both the mesh and the inverse bind
    matrices' bind positions. Joints are named by their nodes (``joint{node}``
    unnamed, ``_2``, ``_3``... after a repeated name); ``parents`` is each joint's
    nearest ancestor node that is a joint too.
    """
    label = str(path)
    gltf, read = open_gltf(path)

    owner_index = next((i for i, n in enumerate(gltf.nodes) if n.mesh is not None and n.skin is not None), None)
    if owner_index is None:
        raise InputError("no skinned mesh in the file", source=label)
    owner = gltf.nodes[owner_index]
    skin_def = gltf.skins[owner.skin]
    joint_nodes = list(skin_def.joints or [])
    if not joint_nodes or not all(type(j) is int and 0 <= j < len(gltf.nodes) for j in joint_nodes):
        raise InputError("the skin's joints must be node numbers", source=label)
    names = _unique_names([gltf.nodes[j].name or f"joint{j}" for j in joint_nodes])
    world, parent = _world_matrices(gltf.nodes, label)
    column = {node: k for k, node in enumerate(joint_nodes)}

    vertices, joints, weights, faces, bind_world = _skinned_piece(gltf, read, owner_index, column, world, label)
    pieces = [(vertices, joints, weights, faces)]  # bind_world: where the owner's joints stand at bind
    for number, node in enumerate(gltf.nodes):
        if number == owner_index or node.mesh is None:
            continue
        if node.skin is not None:  # another piece skinned to the same skeleton (a hand, a head)
            other = gltf.skins[node.skin] if 0 <= node.skin < len(gltf.skins) else None
            if other is None or not set(other.joints or []) <= set(column):
                continue
            pieces.append(_skinned_piece(gltf, read, number, column, world, label)[:4])
            continue
        carrier = number  # a rigid piece: on the nearest joint at or above its node
        while carrier >= 0 and carrier not in column:
            carrier = int(parent[carrier])
        if carrier < 0:
            continue
        # Where the piece stands when its joint stands at bind: the joint's bind over its node's rest.
        placed = bind_world[column[carrier]] @ np.linalg.inv(world[carrier]) @ world[number]
        for points, triangles in _primitives(gltf, read, node.mesh):
            moved = points @ placed[:3, :3].T + placed[:3, 3]
            if np.linalg.det(placed[:3, :3]) < 0:
                triangles = triangles[:, ::-1]
            one = np.zeros((len(points), joints.shape[1]), dtype=np.int64)
            one[:, 0] = column[carrier]
            weight = np.zeros((len(points), joints.shape[1]))
            weight[:, 0] = 1.0
            pieces.append((moved, one, weight, triangles))
    vertices, joints, weights, faces = _joined(pieces)
    bind = {name: matrix[:3, 3].copy() for name, matrix in zip(names, bind_world)}

    joint_name = {}
    for node, name in zip(joint_nodes, names):
        joint_name.setdefault(node, name)
    parents = {}
    for node, name in zip(joint_nodes, names):
        above = parent[node]
        while above >= 0 and above not in joint_name:
            above = parent[above]
        if above >= 0:
            parents[name] = joint_name[above]

    rows = np.repeat(np.arange(len(vertices)), joints.shape[1])
    top_j, top_w = top_influences(rows, joints.ravel(), weights.ravel(), len(vertices), 8)
    return Skin(vertices, np.ascontiguousarray(faces), names, top_j, top_w, bind, parents)


def _joined(pieces: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]):
    """Pieces ``(vertices, joints, weights, faces)`` as one mesh: influences padded to the widest,
    each piece's faces numbered after the vertices before it."""
    width = max(p[1].shape[1] for p in pieces)
    first = np.cumsum([0] + [len(p[0]) for p in pieces[:-1]])
    return (np.concatenate([p[0] for p in pieces]),
            np.concatenate([np.pad(p[1], ((0, 0), (0, width - p[1].shape[1]))) for p in pieces]),
            np.concatenate([np.pad(p[2], ((0, 0), (0, width - p[2].shape[1]))) for p in pieces]),
            np.concatenate([p[3] + at for p, at in zip(pieces, first)]))


def _primitives(gltf, read, mesh: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each triangle primitive of a mesh: its positions (V, 3) and faces (T, 3) (points and lines are not a body)."""
    out = []
    for primitive in gltf.meshes[mesh].primitives or []:
        if primitive.mode not in (None, 4):
            continue
        points = read(primitive.attributes.POSITION).astype(np.float64)
        faces = (read(primitive.indices).reshape(-1, 3) if primitive.indices is not None
                 else np.arange(len(points) - len(points) % 3).reshape(-1, 3)).astype(np.int64)
        out.append((points, faces))
    return out


def _skinned_piece(gltf, read, number: int, column: dict[int, int], world: np.ndarray, label: str):
    """A skinned mesh node's triangle primitives in the bind pose, in world space, its joints as
    ``column`` numbers them: ``(vertices, joints, weights, faces, bind_world)``, ``bind_world``
    (J, 4, 4) where its skin's joints stand at bind (identity rows for joints it does not use)."""
    node = gltf.nodes[number]
    skin_def = gltf.skins[node.skin]
    own = list(skin_def.joints or [])
    if not own or not all(type(j) is int and 0 <= j < len(gltf.nodes) for j in own):
        raise InputError("the skin's joints must be node numbers", source=label)
    parts = []
    for primitive in gltf.meshes[node.mesh].primitives or []:
        if primitive.mode not in (None, 4):
            continue  # points and lines are not a body
        attributes = primitive.attributes
        if attributes.JOINTS_0 is None or attributes.WEIGHTS_0 is None:
            raise InputError("the mesh has no JOINTS_0/WEIGHTS_0", source=label)
        points = read(attributes.POSITION).astype(np.float64)
        joints = [read(attributes.JOINTS_0)]
        weights = [read(attributes.WEIGHTS_0)]
        if getattr(attributes, "JOINTS_1", None) is not None and getattr(attributes, "WEIGHTS_1", None) is not None:
            joints.append(read(attributes.JOINTS_1))
            weights.append(read(attributes.WEIGHTS_1))
        faces = (read(primitive.indices).reshape(-1, 3) if primitive.indices is not None
                 else np.arange(len(points) - len(points) % 3).reshape(-1, 3))
        parts.append((points, np.concatenate(joints, axis=1).astype(np.int64),
                      np.concatenate(weights, axis=1).astype(np.float64), faces.astype(np.int64)))
    if not parts:
        raise InputError("the skinned mesh has no triangles", source=label)
    vertices, joints, weights, faces = _joined(parts)

    inverse = np.tile(np.eye(4), (len(own), 1, 1))
    if skin_def.inverseBindMatrices is not None:
        stored = read(skin_def.inverseBindMatrices)
        if stored.shape[1] != 16 or len(stored) < len(own):
            raise InputError(f"the skin has {len(own)} joints but {len(stored)} inverse bind matrices",
                             source=label)
        # glTF matrices are column-major: each row read is the transpose.
        inverse = stored[: len(own)].reshape(-1, 4, 4).transpose(0, 2, 1).astype(np.float64)
        if not np.all(np.isfinite(inverse)):
            raise InputError("inverse bind matrices must be finite numbers", source=label)
    placed = world[own] @ inverse  # (J, 4, 4): where each joint draws the mesh at bind
    corners = np.ones((8, 4))
    corners[:, :3] = np.where((np.arange(8)[:, None] >> np.arange(3)) & 1, vertices.max(axis=0), vertices.min(axis=0))
    # The bounding box's corners bound how far apart any two matrices take any vertex.
    reached = np.einsum("jab,cb->jca", placed[:, :3], corners)  # (J, 8, 3)
    middle = reached.mean(axis=0)
    size = float(np.linalg.norm(middle.max(axis=0) - middle.min(axis=0)))
    if np.max(vector_norm(reached - middle)) <= 1e-4 * max(size, 1e-12):
        transform = placed.mean(axis=0)
        stood = world[own]
    else:
        transform = world[number]
        try:
            stood = transform @ np.linalg.inv(inverse)
        except np.linalg.LinAlgError:
            raise InputError("an inverse bind matrix cannot be inverted", source=label) from None
    vertices = vertices @ transform[:3, :3].T + transform[:3, 3]
    if np.linalg.det(transform[:3, :3]) < 0:
        faces = faces[:, ::-1]  # a mirror turns the winding inside out: turn it back
    if np.any(joints >= len(own)) or np.any(joints < 0):
        raise IndexError(f"a vertex names joint {int(joints.max())} of a skin of {len(own)}")
    bind_world = np.tile(np.eye(4), (len(column), 1, 1))
    mapped = np.array([column[j] for j in own], dtype=np.int64)
    bind_world[mapped] = stood
    return vertices, mapped[joints], weights, faces, bind_world


def _unique_names(names: list[str]) -> tuple[str, ...]:
    """``names`` with each repeat suffixed ``_2``, ``_3``... (skipping names already present), first one kept."""
    taken = set(names)
    seen: set[str] = set()
    unique = []
    for name in names:
        if name in seen:
            number = 2
            while f"{name}_{number}" in taken:
                number += 1
            name = f"{name}_{number}"
            taken.add(name)
        seen.add(name)
        unique.append(name)
    return tuple(unique)


def _node_local(node, number: int, label: str) -> np.ndarray:
    """A glTF node's local 4x4 matrix: its ``matrix`` (column-major), else translation @ rotation @ scale."""

    def numbers(value, size: int, what: str) -> np.ndarray:
        try:
            array = np.array(value, dtype=np.float64)
        except (TypeError, ValueError):
            array = np.zeros(0)
        if array.shape != (size,) or not np.all(np.isfinite(array)):
            raise InputError(f"node {number}'s {what} must be {size} finite numbers", source=label)
        return array

    if node.matrix is not None:
        return numbers(node.matrix, 16, "matrix").reshape(4, 4).T
    local = np.eye(4)
    if node.rotation is not None:
        quaternion = numbers(node.rotation, 4, "rotation")
        length = np.linalg.norm(quaternion)
        if length < 1e-12:
            raise InputError(f"node {number}'s rotation is not a quaternion (all zeros)", source=label)
        local[:3, :3] = quat_to_matrix(quaternion / length)  # x, y, z, w as glTF stores it
    if node.scale is not None:
        local[:3, :3] = local[:3, :3] * numbers(node.scale, 3, "scale")
    if node.translation is not None:
        local[:3, 3] = numbers(node.translation, 3, "translation")
    return local


def _world_matrices(nodes: list, label: str) -> tuple[np.ndarray, np.ndarray]:
    """Every node's world matrix ``(N, 4, 4)`` and its parent (``-1`` at a root), from ``children``.

    Each node is placed through its own ancestors, so one outside every scene
    still gets one; a node listed twice as a child keeps its first parent; a
    loop in the tree is an InputError.
    """
    count = len(nodes)
    parent = np.full(count, -1, dtype=np.int64)
    for number, node in enumerate(nodes):
        for child in node.children or []:
            if not (type(child) is int and 0 <= child < count):
                raise InputError(f"node {number} has a child {str(child)[:20]!r} that is not a node", source=label)
            if child == number:
                raise InputError(f"node {number} is its own child", source=label)
            if parent[child] < 0:
                parent[child] = number
    local = [_node_local(node, number, label) for number, node in enumerate(nodes)]
    world = np.zeros((count, 4, 4))
    done = np.zeros(count, dtype=bool)
    for start in range(count):
        chain, node = [], start
        while node >= 0 and not done[node]:
            chain.append(node)
            if len(chain) > count:
                raise InputError(f"the node tree loops (through node {start})", source=label)
            node = parent[node]
        above = world[node] if node >= 0 else np.eye(4)
        for number in reversed(chain):
            with np.errstate(over="ignore", invalid="ignore"):  # huge scales are refused just below
                above = world[number] = above @ local[number]
            done[number] = True
    if not np.all(np.abs(world) <= 1e9):
        raise InputError("node transforms must be finite numbers (at most 1e9 in size, composed down the tree)",
                         source=label)
    return world, parent


def _buffer_data(uri: str | None, folder: Path, label: str) -> bytes:
    """A .gltf buffer's bytes: a data URI, or a file in the glTF's own folder (never elsewhere)."""
    if not uri:
        raise InputError("a buffer has no uri", source=label)
    if uri.startswith("data:"):
        header, _, payload = uri.partition(",")
        if not header.endswith(";base64"):
            raise InputError("buffer data URIs must be base64", source=label)
        return base64.b64decode(payload, validate=True)
    relative = Path(urllib.parse.unquote(uri))
    target = (folder / relative).resolve()
    if relative.is_absolute() or "://" in uri or not target.is_relative_to(folder.resolve()):
        raise InputError(f"buffer uri {uri[:60]!r} points outside the glTF's folder", source=label)
    try:  # a regular file, as every file read is, and no larger than a character may be (a FIFO blocked for ever)
        return read_limited(target, limit=LIMITS["character"], what="glTF buffer", label=f"{label}: buffer {uri[:60]!r}")
    except OSError as error:
        raise InputError(f"buffer {uri[:60]!r}: {error.strerror or error}", source=label) from None


def check_skin(skin: Skin, source: str) -> Skin:
    """``skin`` if its arrays make sense (InputError naming the first fault otherwise).

    Vertices finite and in range; at least one face, every corner a vertex;
    every joint index names a joint; weights finite, not negative, and every
    vertex weighted.
    """
    vertices, faces, joints, weights = skin.vertices, skin.faces, skin.joints, skin.weights
    if not len(vertices):
        raise InputError("the skin has no vertices", source=source)
    if not np.all(np.abs(vertices) <= 1e9):
        raise InputError("vertex positions must be finite numbers (at most 1e9 in size)", source=source)
    if not len(faces):
        raise InputError("the skin has no faces", source=source)
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise InputError(f"face corners must be vertex numbers 0 to {len(vertices) - 1}, found "
                         f"{faces.min() if faces.min() < 0 else faces.max()}", source=source)
    if joints.size and (joints.min() < 0 or joints.max() >= len(skin.joint_names)):
        raise InputError(f"joint indices must be 0 to {len(skin.joint_names) - 1} (one per joint name), found "
                         f"{joints.min() if joints.min() < 0 else joints.max()}", source=source)
    if not np.all(np.isfinite(weights)) or np.any(weights < 0):
        raise InputError("weights must be finite and not negative", source=source)
    if any(not np.all(np.abs(np.asarray(p, dtype=np.float64)) <= 1e9) for p in skin.bind.values()):
        raise InputError("bind positions (inverse bind matrices) must be finite numbers", source=source)
    unweighted = np.flatnonzero(weights.sum(axis=1) <= 0)
    if len(unweighted):
        raise InputError(f"{len(unweighted)} vertices (the first: {unweighted[0]}) have no weight", source=source)
    return skin


#: The last skin read in this process, by `_file_key`: a batch reads its one character for the
#: CLI's check, the parameters' digest and every clip of a worker; it is parsed once. One only,
#: so a process never holds more than the skin it is using.
_LAST: dict[tuple, Skin] = {}


def _file_key(path: str | os.PathLike) -> tuple | None:
    """What a skin read from ``path`` depends on: the file's bytes (and for a MakeHuman ``.obj``
    those of the ``.mhw``/``.mhskel`` files beside it), as SHA-256 digests; None when it cannot be
    read (the reader then says why). Hashing is about 1/50 of parsing, and unlike a modification
    time it cannot miss a file rewritten within the clock's tick."""
    from .files import digest_of_file

    try:
        real = Path(os.path.realpath(path))
        files = [real]
        if real.suffix.lower() == ".obj":
            files += sorted(p for p in real.parent.iterdir() if p.suffix.lower() in (".mhw", ".mhskel"))
        return tuple((str(file), digest_of_file(file)) for file in files)
    except OSError:
        return None


def known_digest(path: str | os.PathLike) -> str | None:
    """The ``sha256:<hex>`` of the skin file `load_skin` last read at ``path`` in this process
    (so a job that names its skin does not hash it twice), None when it read no such file."""
    real = os.path.realpath(path)
    return next((digest for key in _LAST for name, digest in key[:1] if name == real), None)


def load_skin(path: str | os.PathLike) -> Skin:
    """A skin from ``.npz``, a glTF/GLB skinned mesh, or a MakeHuman ``.obj`` (with its ``.mhw`` beside it).

    Whatever is wrong with the file ends in one InputError naming it; the
    skin that comes back has passed `check_skin`. The same unchanged file read again in the
    same process is the same `Skin` (its arrays are read-only, so no user of it can change
    it for the next).
    """
    key = _file_key(path)
    if key is not None and key in _LAST:
        return _LAST[key]
    skin = _read_skin(path)
    if key is not None:
        for array in (skin.vertices, skin.faces, skin.joints, skin.weights):
            array.flags.writeable = False
        _LAST.clear()
        _LAST[key] = skin
    return skin


def _read_skin(path: str | os.PathLike) -> Skin:
    label = str(path)
    suffix = Path(path).suffix.lower()
    loaders = {".npz": load_npz_skin, ".glb": load_gltf_skin, ".gltf": load_gltf_skin, ".obj": load_makehuman_skin}
    if suffix not in loaders:
        raise InputError("skins are read from .npz, .glb/.gltf or a MakeHuman .obj (+ .mhw)", source=label)
    if not Path(path).exists():
        raise InputError("no such skin file", source=label)
    regular_file(path, what="skin file", label=label)  # a folder, a FIFO, a device: said, not read
    try:
        skin = loaders[suffix](path)
    except InputError:
        raise
    except PermissionError:
        raise InputError("permission denied", source=label) from None
    except (ValueError, TypeError, KeyError, IndexError, OverflowError, EOFError, AttributeError,
            zipfile.BadZipFile, struct.error, binascii.Error, RecursionError) as error:
        # Truncated archives, bad CRCs, arrays of the wrong type, accessors past their buffer...
        raise InputError(f"not a readable {suffix[1:]} skin ({type(error).__name__}: {str(error)[:120]})",
                         source=label) from None
    return check_skin(skin, label)


def npz_bytes(**arrays: np.ndarray) -> bytes:
    """An ``.npz`` archive as bytes with fixed timestamps (``np.savez`` stamps the current time)."""
    import io
    import zipfile

    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for name, array in arrays.items():
            member = io.BytesIO()
            np.lib.format.write_array(member, np.asarray(array), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            archive.writestr(info, member.getvalue())
    return buffer.getvalue()
