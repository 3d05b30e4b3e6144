"""Skinned, animated UsdSkel output (``.usd``, ``.usdc``, ``.usda``), written with Pixar's ``usd-core``.

The same character and motion as the GLB (`mocap_exaggerate.io.gltf.glb_pieces`), in the same
metres and the same +Y up with a +Z front, so the two files agree vertex for vertex:

- a ``SkelRoot`` (the stage's default prim) holding
- a ``Skeleton``: every joint, parents before children, as a path of valid USD names
  (``Hips/Spine/Chest``), with ``jointNames`` keeping each name as the clip gives it
  (``mixamorig:Hips``, ``left arm``); ``restTransforms`` (each joint's rest offset, no turn; the
  root turned upright as in the GLB) and ``bindTransforms`` (the rest pose in world space);
- a ``SkelAnimation`` with a translation, rotation and scale for every joint at every frame
  (time code = frame, ``timeCodesPerSecond`` = the clip's rate); scales are the GLB's volume
  preservation (uniform, 1 where a joint keeps its thickness);
- the body (the default rubber body or the user's character) as a ``Mesh`` with the
  ``SkelBindingAPI``: ``primvars:skel:jointIndices`` and ``jointWeights`` (4 or 8 a vertex),
  an identity ``geomBindTransform`` (the mesh is stored in the bind pose), bound to the skeleton,
  whose ``skel:animationSource`` is the animation.

Why paths of valid names: a UsdSkel joint is an ``SdfPath``; ``mixamorig:Hips/mixamorig:Spine``
is not a path, and a skeleton whose joints are not paths of their parents' makes every joint a
root without a word. Names are made valid with ``Tf.MakeValidIdentifier`` and told apart among
siblings by a number; the original names stay in ``jointNames``.

``usd-core`` is an optional extra (``pip install 'mocap-exaggerate[usd]'``); `require_usd` says so
in one line where it is missing.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from ..core.errors import ConfigError
from ..core.motion import Motion
from ..core.rotations import quat_mul, quat_rotate, quat_unroll, vector_norm
from ..rig.skinning import Skin
from .gltf import UPRIGHT, vertex_normals

__all__ = ["USD_FORMATS", "require_usd", "joint_paths", "format_usd"]

#: The formats written, by suffix: ``usd`` and ``usdc`` are USD's binary crate files, ``usda`` text.
USD_FORMATS = ("usd", "usda", "usdc")  # as mocap_exaggerate.config.USD_FORMATS (io does not import config)

#: What to install when ``usd-core`` is missing.
USD_EXTRA = "pip install 'mocap-exaggerate[usd]' (Pixar's usd-core)"


def require_usd() -> None:
    """Raise a one-line `ConfigError` unless ``usd-core`` (the ``pxr`` package) can be imported."""
    try:
        import pxr.UsdSkel  # noqa: F401
    except ImportError:
        raise ConfigError(f"USD output needs the usd extra: {USD_EXTRA}") from None


def joint_paths(names: tuple[str, ...] | list[str], parents: np.ndarray) -> list[str]:
    """Each joint's UsdSkel path: its ancestors' valid names and its own, joined by ``/``.

    A name that is not a valid USD identifier is made one (``mixamorig:Hips`` -> ``mixamorig_Hips``,
    ``1st`` -> ``_st``); two siblings whose names become the same get ``_2``, ``_3``... on the later
    ones, so every path is unique and every joint's parent is the path before its last part.

    >>> joint_paths(["mixamorig:Hips", "left leg", "left:leg", "9"], np.array([-1, 0, 0, 1]))
    ['mixamorig_Hips', 'mixamorig_Hips/left_leg', 'mixamorig_Hips/left_leg_2', 'mixamorig_Hips/left_leg/_']
    """
    from pxr import Tf

    paths: list[str] = []
    taken: set[str] = set()
    for j, name in enumerate(names):
        base = Tf.MakeValidIdentifier(str(name)) or "_"
        prefix = paths[parents[j]] + "/" if parents[j] >= 0 else ""
        path, number = prefix + base, 1
        while path in taken:
            number += 1
            path = f"{prefix}{base}_{number}"
        taken.add(path)
        paths.append(path)
    return paths


def _usd_matrices(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """(J, 4, 4) USD matrices (row vectors: a point is ``p @ M``) of column-convention rotations
    ``(J, 3, 3)`` and translations ``(J, 3)``."""
    out = np.zeros(rotation.shape[:-2] + (4, 4))
    out[..., :3, :3] = np.swapaxes(rotation, -1, -2)
    out[..., 3, :3] = translation
    out[..., 3, 3] = 1.0
    return out


def format_usd(motion: Motion, skin: Skin, *, suffix: str = "usd", meters_per_unit: float = 1.0,
               name: str = "mocap_exaggerate", thickness: np.ndarray | None = None,
               up: tuple[int, float] = (1, 1.0)) -> bytes:
    """The UsdSkel file's bytes: ``suffix`` ``usd``/``usdc`` (binary) or ``usda`` (text).

    Takes what `mocap_exaggerate.io.gltf.glb_pieces` takes, and poses the same: every joint where
    the BVH puts it, every vertex where the GLB puts it (in metres, +Y up).
    """
    require_usd()
    from pxr import Gf, Sdf, Tf, Usd, UsdGeom, UsdSkel, Vt

    if suffix not in USD_FORMATS:
        raise ConfigError(f"USD format must be one of {', '.join(USD_FORMATS)}, got {suffix!r:.40}")
    skeleton = motion.skeleton
    index = {n: j for j, n in enumerate(skeleton.names)}
    missing = [n for n in skin.joint_names if n not in index]
    if missing:
        raise ConfigError(f"skin joints not in the output skeleton: {', '.join(missing[:5])}")
    try:
        upright = np.array(UPRIGHT[(int(up[0]), float(up[1]))])
    except KeyError:
        raise ConfigError(f"up must be an axis 0, 1 or 2 and a sign 1 or -1, got {up!r}") from None
    turn = quat_rotate(upright, np.eye(3)).T  # column i is where axis i goes
    scale = float(meters_per_unit)
    count = skeleton.num_joints
    parents = np.asarray(skeleton.parents)

    with tempfile.TemporaryDirectory(prefix="mocap_usd_") as folder:
        # A crate file needs a real path to be written; the bytes are read back for the caller's
        # all-or-nothing output set.
        path = Path(folder) / f"out.{suffix}"
        stage = Usd.Stage.CreateNew(str(path))
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
        UsdGeom.SetStageMetersPerUnit(stage, 1.0)
        fps = 1.0 / motion.frame_time
        stage.SetTimeCodesPerSecond(fps)
        stage.SetFramesPerSecond(fps)
        stage.SetStartTimeCode(0)
        stage.SetEndTimeCode(max(motion.num_frames - 1, 0))
        root_name = Tf.MakeValidIdentifier(name) or "character"
        root = UsdSkel.Root.Define(stage, Sdf.Path(f"/{root_name}"))
        stage.SetDefaultPrim(root.GetPrim())

        joints = Vt.TokenArray(joint_paths(skeleton.names, parents))
        skel = UsdSkel.Skeleton.Define(stage, root.GetPath().AppendChild("Skeleton"))
        skel.CreateJointsAttr(joints)
        skel.CreateJointNamesAttr(Vt.TokenArray([str(n) for n in skeleton.names]))
        offsets = skeleton.offsets * scale
        rest_rotation = np.repeat(np.eye(3)[None], count, axis=0)
        rest_rotation[0] = turn
        offsets[0] = turn @ offsets[0]
        skel.CreateRestTransformsAttr(Vt.Matrix4dArray.FromNumpy(_usd_matrices(rest_rotation, offsets)))
        bind = (skeleton.rest_positions() * scale) @ turn.T
        bind_rotation = np.repeat(turn[None], count, axis=0)
        skel.CreateBindTransformsAttr(Vt.Matrix4dArray.FromNumpy(_usd_matrices(bind_rotation, bind)))

        animation = UsdSkel.Animation.Define(stage, skel.GetPath().AppendChild("Animation"))
        animation.CreateJointsAttr(joints)
        binding = UsdSkel.BindingAPI.Apply(skel.GetPrim())
        binding.CreateAnimationSourceRel().SetTargets([animation.GetPath()])
        _write_tracks(animation, motion, upright, turn, scale, thickness)

        body = UsdGeom.Mesh.Define(stage, root.GetPath().AppendChild("Body"))
        points = skin.vertices @ turn.T * scale
        body.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(points.astype(np.float32)))
        body.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy((vertex_normals(skin.vertices, skin.faces) @ turn.T)
                                                       .astype(np.float32)))
        body.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
        body.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(skin.faces), 3, dtype=np.int32)))
        body.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(skin.faces.reshape(-1).astype(np.int32)))
        body.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        low, high = points.min(axis=0), points.max(axis=0)
        body.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, low)), Gf.Vec3f(*map(float, high))]))
        remap = np.array([index[n] for n in skin.joint_names], dtype=np.int64)
        width = skin.weights.shape[1]
        weights = np.where(skin.weights > 0, skin.weights, 0.0)
        weights /= np.maximum(weights.sum(axis=1, keepdims=True), 1e-300)
        indices = np.where(weights > 0, remap[skin.joints], 0).astype(np.int32)
        skinning = UsdSkel.BindingAPI.Apply(body.GetPrim())
        skinning.CreateJointIndicesPrimvar(False, width).Set(Vt.IntArray.FromNumpy(indices.reshape(-1)))
        skinning.CreateJointWeightsPrimvar(False, width).Set(Vt.FloatArray.FromNumpy(
            weights.reshape(-1).astype(np.float32)))
        skinning.CreateGeomBindTransformAttr(Gf.Matrix4d(1.0))
        skinning.CreateSkeletonRel().SetTargets([skel.GetPath()])
        stage.GetRootLayer().Save()
        del stage
        return path.read_bytes()


def _write_tracks(animation, motion: Motion, upright: np.ndarray, turn: np.ndarray, scale: float,
                  thickness: np.ndarray | None) -> None:
    """The animation's time samples: the GLB's tracks (`mocap_exaggerate.io.gltf.glb_pieces`), frame by frame."""
    from pxr import Usd, Vt

    skeleton = motion.skeleton
    rotation = np.array(motion.local_rotations, dtype=np.float64)
    translation = motion.local_positions * scale
    rotation[:, 0] = quat_mul(upright, rotation[:, 0])
    translation[:, 0] = translation[:, 0] @ turn.T
    rotation = quat_unroll(rotation, axis=0)
    rotation = (rotation / vector_norm(rotation, keepdims=True)).astype(np.float32)
    node_scale = np.ones(rotation.shape[:2], dtype=np.float16)
    if thickness is not None:
        thickness = np.asarray(thickness, dtype=np.float64)
        parent_world = np.ones_like(thickness)
        parent_world[:, 1:] = thickness[:, skeleton.parents[1:]]
        # UsdSkel's scales are half floats (3 digits): each child's translation is divided by its
        # parent's world scale as USD will compose it from the rounded scales, so the joints land
        # where the BVH puts them to float precision and only the thickness is rounded.
        node_scale = (thickness / parent_world).astype(np.float16)
        world = node_scale.astype(np.float64)
        for j in range(1, skeleton.num_joints):  # parents come before children
            world[:, j] *= world[:, skeleton.parents[j]]
        translation[:, 1:] /= world[:, skeleton.parents[1:], None]
    translation = translation.astype(np.float32)
    scales = np.repeat(node_scale[..., None], 3, axis=-1)
    translations = animation.CreateTranslationsAttr()
    rotations = animation.CreateRotationsAttr()
    scaled = animation.CreateScalesAttr()
    for frame in range(motion.num_frames):  # USD takes one time sample at a time
        time = Usd.TimeCode(frame)
        translations.Set(Vt.Vec3fArray.FromNumpy(translation[frame]), time)
        rotations.Set(Vt.QuatfArray.FromNumpy(rotation[frame]), time)
        scaled.Set(Vt.Vec3hArray.FromNumpy(scales[frame]), time)
