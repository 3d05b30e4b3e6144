"""Motion from an animated, skinned glTF/GLB: a game character's clip as the pipeline's input.

The skeleton is the skin's joints (the first skinned mesh's skin), with every node between them
and their common ancestor, parents before children. One animation (``clip``: by name, else the
first) is sampled at a fixed rate: each animated node's translation, rotation and scale at every
frame (linear keys interpolated, rotations by slerp; step keys held; cubic-spline keys by their
values, linearly), every other node at its own transform; node by node down the tree to world
transforms.

The pipeline works as BVH does, with identity orientations at rest: the rest pose is the skin's
bind pose (where its inverse bind matrices put the joints, which is where the mesh was made), each
joint's OFFSET is its bind position from its parent's in the scene's world axes, and each frame's
world rotation is the node's world rotation over its bind rotation, so the mesh moves as the
glTF's own skinning moves it. Node scales (an armature scaled by 0.01) place the joints; a joint
scaled over time beyond that is read as where it puts its children (BVH has no scale). The scene
is +Y up and in metres, as glTF says.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.errors import InputError
from ..core.kinematics import local_from_world
from ..core.motion import Motion
from ..core.rotations import quat_from_matrix, quat_normalize, quat_slerp
from ..core.skeleton import Skeleton
from .bvh import MAX_DEPTH, MAX_JOINT_FRAMES, MAX_JOINTS
from .bvh import MAX_FRAMES as BVH_MAX_FRAMES
from .skin import _node_local, _skinned_piece, _unique_names, _world_matrices, open_gltf

__all__ = ["GLTF_SUFFIXES", "is_gltf", "GltfReport", "gltf_animations", "read_gltf_motion", "DEFAULT_GLTF_FPS"]

GLTF_SUFFIXES = (".glb", ".gltf")
#: The rate a clip is sampled at when neither the user nor its keys say (keys at irregular times).
DEFAULT_GLTF_FPS = 30.0
#: The keys' own rate is taken when it lies in this range (keys every 1/24 s: 24 fps).
_KEY_RATES = (10.0, 240.0)
#: Most frames one clip may be sampled into: the BVH reader's cap (`mocap_exaggerate.io.bvh.MAX_FRAMES`).
MAX_FRAMES = BVH_MAX_FRAMES


def is_gltf(source) -> bool:
    """True for a path ending in ``.glb`` or ``.gltf`` (any case)."""
    return isinstance(source, (str, os.PathLike)) and str(source).lower().endswith(GLTF_SUFFIXES)


@dataclass
class GltfReport:
    """What the reader noticed: the file, the clip taken and the rate it was sampled at."""

    source: str
    clip: str = ""
    clips: list[str] = field(default_factory=list)
    fps: float = DEFAULT_GLTF_FPS
    root_offset: str = "replace"
    warnings: list[str] = field(default_factory=list)


def gltf_animations(path: str | os.PathLike) -> list[dict]:
    """Each animation of the file: its name, duration (s), number of channels and of keys."""
    try:
        return _animations(path)
    except InputError:
        raise
    except (ValueError, TypeError, KeyError, IndexError, AttributeError) as error:
        raise InputError(f"not a readable glTF animation ({type(error).__name__}: {str(error)[:120]})",
                         source=str(path)) from None


def _animations(path) -> list[dict]:
    gltf, read = open_gltf(path)
    out = []
    for number, animation in enumerate(gltf.animations or []):
        times = [read(sampler.input)[:, 0] for sampler in animation.samplers or []]
        duration = float(max((t.max() for t in times), default=0.0))
        out.append({"name": animation.name or f"animation{number}", "duration_s": round(duration, 6),
                    "channels": len(animation.channels or []), "keys": int(max((len(t) for t in times), default=0))})
    return out


def read_gltf_motion(path: str | os.PathLike, *, fps: float | None = None, clip: str = "",
                     name: str | None = None) -> tuple[Motion, GltfReport]:
    """The skeleton of the file's skin moving as one of its animations does, sampled at ``fps``.

    clip : the animation's name ("" takes the first); fps : None samples at the keys' own
    rate where at least four in five of their steps are one step of 1/240-1/10 s, else at
    `DEFAULT_GLTF_FPS`. A file that is not what glTF says is one `InputError` line.
    """
    label = name or str(path)
    if not Path(path).is_file():
        raise InputError("no such file" if not Path(path).exists() else "is not a file", source=label)
    try:
        return _read(path, fps, clip, label)
    except InputError:
        raise
    except PermissionError:
        raise InputError("permission denied", source=label) from None
    except (ValueError, TypeError, KeyError, IndexError, OverflowError, AttributeError, RecursionError,
            np.linalg.LinAlgError) as error:  # a field of the wrong kind, an accessor past its buffer...
        raise InputError(f"not a readable glTF animation ({type(error).__name__}: {str(error)[:120]})",
                         source=label) from None


def _read(path, fps: float | None, clip: str, label: str) -> tuple[Motion, GltfReport]:
    gltf, read = open_gltf(path)
    nodes = gltf.nodes or []
    owner = next((n for n in nodes if n.mesh is not None and n.skin is not None), None)
    if owner is None or not gltf.skins:
        raise InputError("no skinned mesh in the file: nothing says which nodes are the skeleton", source=label)
    skin = gltf.skins[owner.skin]
    joints = list(skin.joints or [])
    if not joints or not all(type(j) is int and 0 <= j < len(nodes) for j in joints):
        raise InputError("the skin's joints must be node numbers", source=label)
    animations = gltf.animations or []
    names = [a.name or f"animation{k}" for k, a in enumerate(animations)]
    if not animations:
        raise InputError("the file has no animation: nothing moves", source=label)
    if clip:
        if clip not in names:
            raise InputError(f"no animation called {clip[:60]!r}; the file has {', '.join(names)[:300]}", source=label)
        chosen = names.index(clip)
    else:
        chosen = 0
    animation = animations[chosen]

    rest_world, parent = _world_matrices(nodes, label)
    if len(joints) > MAX_JOINTS:  # (the BVH reader's cap)
        raise InputError(f"the skin has {len(joints)} joints; at most {MAX_JOINTS} are read", source=label)
    order = _tree(joints, parent, label)  # every node of the skeleton, parents before children
    if len(order) > MAX_JOINTS:
        raise InputError(f"the skeleton has {len(order)} nodes; at most {MAX_JOINTS} joints are read", source=label)
    index = {node: k for k, node in enumerate(order)}
    parents = np.array([index.get(int(parent[node]), -1) if k else -1 for k, node in enumerate(order)])
    depth = np.zeros(len(order), dtype=np.int64)
    for k in range(1, len(order)):  # (parents before children)
        depth[k] = depth[parents[k]] + 1 if parents[k] >= 0 else 0
    if depth.max() >= MAX_DEPTH:
        raise InputError(f"the skeleton is {int(depth.max()) + 1} joints deep; at most {MAX_DEPTH} are read", source=label)

    # Keys: each channel's sampler, by node and path.
    tracks: dict[tuple[int, str], tuple[np.ndarray, np.ndarray, str]] = {}
    ends = []
    for channel in animation.channels or []:
        target = channel.target
        if target is None or target.node not in index or target.path not in ("translation", "rotation", "scale"):
            continue  # morph weights, nodes outside the skeleton: nothing the skeleton shows
        if not (type(channel.sampler) is int and 0 <= channel.sampler < len(animation.samplers)):
            raise InputError(f"animation {names[chosen]!r}: a channel names no sampler", source=label)
        sampler = animation.samplers[channel.sampler]
        times = read(sampler.input)[:, 0].astype(np.float64)
        values = read(sampler.output).astype(np.float64)
        mode = sampler.interpolation or "LINEAR"
        if mode == "CUBICSPLINE":  # in-tangent, value, out-tangent per key: the values
            values = values[1::3]
        if len(values) != len(times) or not np.all(np.isfinite(times)) or not np.all(np.isfinite(values)) \
                or np.any(np.diff(times) < 0):
            raise InputError(f"animation {names[chosen]!r}: node {target.node}'s {target.path} keys are not "
                             f"finite numbers at rising times, one value a key", source=label)
        if target.path == "rotation" and (values.shape[1:] != (4,) or np.any(np.einsum("kc,kc->k", values, values) == 0)):
            raise InputError(f"animation {names[chosen]!r}: node {target.node}'s rotation keys must be quaternions "
                             f"of four numbers, not all zero", source=label)
        tracks[(target.node, target.path)] = (times, values, mode)
        ends.append(times)
    if not tracks:
        raise InputError(f"animation {names[chosen]!r} moves none of the skeleton's joints", source=label)
    start = min(t[0] for t in ends)
    stop = max(t[-1] for t in ends)
    rate = float(fps) if fps else _key_rate(ends)
    count = int(np.floor((stop - start) * rate + 1e-3)) + 1  # key times are float32: 79.999998 frames is 80
    if count > MAX_FRAMES:
        raise InputError(f"animation {names[chosen]!r} at {rate:g} fps is {count} frames; at most {MAX_FRAMES}",
                         source=label)
    if count * len(order) > MAX_JOINT_FRAMES:
        raise InputError(f"animation {names[chosen]!r} at {rate:g} fps is {count} frames of {len(order)} joints; at "
                         f"most {MAX_JOINT_FRAMES:,} joints times frames are read", source=label)
    times = start + np.arange(count) / rate

    # World transforms of every node of the skeleton at every frame, down the tree.
    above = parent[order[0]]
    base = rest_world[above] if above >= 0 else np.eye(4)  # the skeleton's root's parent, as it rests
    world = np.empty((count, len(order), 4, 4))
    for k, node in enumerate(order):
        local = _sampled_local(nodes[node], node, tracks, times, label)
        world[:, k] = (base if parents[k] < 0 else world[:, parents[k]]) @ local
    if not np.all(np.isfinite(world)):
        raise InputError("the animated node transforms are not finite numbers", source=label)

    # The rest pose: the skin's bind pose where it gives one (its inverse bind matrices), else the rest nodes.
    # Where the skin loader puts the joints at bind (`mocap_exaggerate.io.skin.load_gltf_skin`), so the
    # motion and the character agree: the nodes as they stand when they stand at bind (the mesh
    # node's own transform is ignored, as glTF says), else the mesh node's world over the IBMs.
    bind = rest_world[order].copy()
    column = {node: k for k, node in enumerate(joints)}
    stood = _skinned_piece(gltf, read, nodes.index(owner), column, rest_world, label)[4]
    for node, k in column.items():
        bind[index[node]] = stood[k]
    # Nodes between the joints that the skin leaves out stand where their rest tree puts them under the bind.
    for k, node in enumerate(order):
        if node not in column and parents[k] >= 0:
            bind[k] = bind[parents[k]] @ _node_local(nodes[node], node, label)
    positions = world[..., :3, 3]
    turn = _rotation_of(world[..., :3, :3])
    rest_turn = _rotation_of(bind[:, :3, :3])
    rotations = quat_from_matrix(turn @ np.swapaxes(rest_turn, -1, -2)[None])
    rest = bind[:, :3, 3]
    offsets = rest - rest[np.maximum(parents, 0)]
    offsets[0] = rest[0]
    local_rot, local_pos = local_from_world(parents, quat_normalize(rotations), positions)
    moving = np.ptp(local_pos, axis=0).max(axis=1) > 1e-6 * max(float(np.ptp(rest, axis=0).max()), 1e-12)
    moving[0] = True
    channels = tuple((("Xposition", "Yposition", "Zposition") if moving[k] else ())
                     + ("Zrotation", "Xrotation", "Yrotation") for k in range(len(order)))
    node_names = [nodes[node].name or f"joint{node}" for node in order]
    skeleton = Skeleton(_unique_names(node_names), parents, offsets, channels, np.full((len(order), 3), np.nan), up=1)
    local_pos = np.where(moving[None, :, None], local_pos, offsets[None])
    motion = Motion(skeleton, 1.0 / rate, local_rot, local_pos)
    report = GltfReport(label, names[chosen], names, rate)
    if len(animations) > 1 and not clip:
        report.warnings.append(f"the file has {len(animations)} animations; took the first, {names[chosen]!r} "
                               f"(--clip NAME takes another: {', '.join(names)[:200]})")
    return motion, report


def _tree(joints: list[int], parent: np.ndarray, label: str) -> list[int]:
    """The skin's joints and every node between them and their common ancestor, parents first."""
    chains = []
    for node in joints:
        chain = [node]
        while parent[chain[-1]] >= 0:
            chain.append(int(parent[chain[-1]]))
        chains.append(chain[::-1])  # from the top of the scene down to the joint
    common = 0
    while all(len(c) > common and c[common] == chains[0][common] for c in chains):
        common += 1
    if common == 0:
        raise InputError("the skin's joints are in separate trees: no node holds them all", source=label)
    # The lowest common ancestor is the root, unless it is a joint's own parent that no joint is (an
    # armature node): then the topmost joint below it is the root when there is only one.
    members = {node for chain in chains for node in chain[common - 1:]}
    top = chains[0][common - 1]
    if top not in joints:
        below = [c[common] for c in chains if len(c) > common]
        if len(set(below)) == 1:
            members.discard(top)
            top = below[0]
    children: dict[int, list[int]] = {}
    for node in members:
        if node != top:
            children.setdefault(int(parent[node]), []).append(node)
    order, stack = [], [top]
    while stack:
        node = stack.pop()
        order.append(node)
        stack.extend(sorted(children.get(node, []), reverse=True))
    return order


def _key_rate(times: list[np.ndarray]) -> float:
    """The keys' own rate where they are evenly spaced and plausible, else `DEFAULT_GLTF_FPS`."""
    steps = np.concatenate([np.diff(t) for t in times if len(t) > 1] or [np.zeros(0)])
    steps = steps[steps > 1e-9]
    if not len(steps):
        return DEFAULT_GLTF_FPS
    step = float(np.median(steps))
    rate = 1.0 / step
    even = np.isclose(steps, step, rtol=0.05, atol=1e-4)
    if _KEY_RATES[0] <= rate <= _KEY_RATES[1] and np.mean(even) >= 0.8:  # a held pose's gap aside
        return round(rate * 1000) / 1000
    return DEFAULT_GLTF_FPS


def _sampled_local(node, number: int, tracks: dict, times: np.ndarray, label: str) -> np.ndarray:
    """(F, 4, 4): the node's local matrix at each time, its animated parts sampled, the rest as it stands."""
    from ..core.rotations import quat_to_matrix

    rest = _node_local(node, number, label)
    count = len(times)
    if not any((number, path) in tracks for path in ("translation", "rotation", "scale")):
        return np.broadcast_to(rest, (count, 4, 4))
    if node.matrix is not None:
        raise InputError(f"node {number} is animated but given as a matrix (glTF forbids it)", source=label)
    translation = np.broadcast_to(np.array(node.translation or [0.0, 0.0, 0.0], float), (count, 3))
    rotation = np.broadcast_to(np.array(node.rotation or [0.0, 0.0, 0.0, 1.0], float), (count, 4))
    scale = np.broadcast_to(np.array(node.scale or [1.0, 1.0, 1.0], float), (count, 3))
    if (number, "translation") in tracks:
        translation = _sample(*tracks[(number, "translation")], times)
    if (number, "rotation") in tracks:
        rotation = _sample(*tracks[(number, "rotation")], times, rotation=True)
    if (number, "scale") in tracks:
        scale = _sample(*tracks[(number, "scale")], times)
    local = np.zeros((count, 4, 4))
    local[:, :3, :3] = quat_to_matrix(quat_normalize(rotation)) * scale[:, None, :]
    local[:, :3, 3] = translation
    local[:, 3, 3] = 1.0
    return local


def _sample(keys: np.ndarray, values: np.ndarray, mode: str, times: np.ndarray, *, rotation: bool = False):
    """Values ``(F, width)`` at ``times``: held before the first key and after the last."""
    if len(keys) == 1:
        return np.repeat(values[:1], len(times), axis=0)
    after = np.clip(np.searchsorted(keys, times, side="right"), 1, len(keys) - 1)
    before = after - 1
    span = keys[after] - keys[before]
    u = np.clip(np.divide(times - keys[before], span, out=np.zeros_like(times), where=span > 0), 0.0, 1.0)
    if mode == "STEP":  # a key stored a float32 hair late still holds from its own frame
        held = np.clip(np.searchsorted(keys, times + 1e-5, side="right") - 1, 0, len(keys) - 1)
        return values[held]
    if rotation:
        a = quat_normalize(values[before])
        b = quat_normalize(values[after])
        return quat_slerp(a, b, u)
    return values[before] * (1.0 - u)[:, None] + values[after] * u[:, None]


def _rotation_of(matrix: np.ndarray) -> np.ndarray:
    """The rotation part of matrices ``(..., 3, 3)`` that may carry scale (polar decomposition)."""
    left, _, right = np.linalg.svd(matrix)
    turn = left @ right
    flip = np.linalg.det(turn) < 0
    if np.any(flip):
        left = left.copy()
        left[flip, :, 2] *= -1.0
        turn = left @ right
    return turn
