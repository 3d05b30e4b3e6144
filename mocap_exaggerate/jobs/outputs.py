"""What a run turns into: the manifest, the skin bound to the output skeleton, the GLB bytes.

Everything here returns bytes or plain data; `mocap_exaggerate.jobs.job` decides
where they go and writes them.
"""

from __future__ import annotations

from dataclasses import asdict, replace
from typing import Any, NamedTuple

import numpy as np

from .. import __version__
from ..config import PipelineConfig
from ..core.errors import ConfigError
from ..core.kinematics import cache_blocks
from ..core.motion import Motion
from ..core.rotations import quat_identity, vector_norm
from ..io.bvh import written_positions
from ..pipeline import PipelineResult
from ..rig.skinning import Skin, top_influences

__all__ = ["manifest", "output_thickness", "base_skin", "at_bind_pose", "output_skin", "make_glb", "glb_files",
           "captured_glb", "CharacterFiles"]


def manifest(
    *,
    input_name: str,
    input_hash: str,
    config: PipelineConfig,
    preset: str | None,
    result: PipelineResult,
    outputs: dict[str, str],
    reader_warnings: list[str],
    frames_in: int,
    fps: float,
    timings: dict[str, float],
) -> dict[str, Any]:
    """The JSON manifest that records how an output was made.

    ``config`` is the declaration as the run's pipeline file holds it (`mocap_exaggerate.jobs.job.recorded_config`:
    the ``[glb]`` block as used, its files named relative to the output folder).
    Timings are the only part that varies between identical runs; they are
    kept apart under ``timings`` so a comparison can ignore them.
    """
    info: dict[str, Any] = {
        "tool": "mocap_exaggerate",
        "version": __version__,
        "input": {"file": input_name, "hash": input_hash, "frames": frames_in, "fps": fps},
        "preset": preset,
        "config": config.to_dict(),
        "stages": list(result.stages),
        "rest_frames": {"count": result.rest_frames, "dropped": result.rest_frames_dropped},
        "outputs": outputs,
        "result": {
            "frames": result.motion.num_frames,
            "joints": result.motion.skeleton.num_joints,
            "max_link_stretch": round(result.max_link_stretch, 6),
            "skeleton": config.output.skeleton,
            # What the BVH's position channels do to the OFFSETs, as written (output.bvh_positions).
            "bvh_position_channels": written_positions(result.motion.skeleton, config.output.bvh_positions),
        },
        "warnings": list(reader_warnings) + list(result.notes),
        "timings": timings,
    }
    if result.hierarchy is not None:
        names = result.hierarchy.skeleton.names
        info["result"]["subjoints"] = result.hierarchy.skeleton.num_joints
        info["result"]["groups"] = [[names[result.hierarchy.original[j]] for j in chain] for chain in result.hierarchy.groups]
    if result.substeps:
        info["result"]["spring_substeps"] = result.substeps
    if result.stretch is not None:
        info["result"]["stretch"] = [event.to_dict() for event in result.stretch.events]
    if result.constraints is not None:
        info["result"]["constraints"] = result.constraints
    if result.speed_report is not None:
        info["result"]["speed_limit"] = result.speed_report.to_dict()
    if result.correct_report is not None:
        info["result"]["correct"] = {
            k: (round(v, 6) if isinstance(v, float) else v) for k, v in asdict(result.correct_report).items()
        }
    return info


def output_thickness(result: PipelineResult) -> np.ndarray | None:
    """World scale ``(F, J_out)`` per output joint keeping a stretched link's volume; None where nothing stretches.

    A link's stretch ``s`` is the distance between its two original joints over
    their rest distance, measured on the output, so whatever lengthened or
    shortened it (exaggeration, correction, springs, the stretch pass) counts.
    Thickness is ``1 / sqrt(s)``, held within `THICKNESS` (volume kept: a link
    stretched 2x is 0.71x as thick, one squashed to half 1.41x). The sub-joints
    along a link (its start joint too) take its thickness; an original joint the
    geometric mean over its outgoing links; a joint with no link of its own (a
    hand, a head, fingers) keeps 1, so what it carries keeps its size. The
    chord, not the curve: with nothing exaggerated every link keeps its length
    exactly, and the result is None (no scale track is written), though the
    sub-links of a bent link are a little longer than their share of its chord.
    None too where the run's ``output.preserve_volume`` is off.
    """
    if not result.preserve_volume:
        return None
    skeleton = result.motion.skeleton
    hierarchy = result.hierarchy
    rubber = hierarchy is not None and skeleton is hierarchy.skeleton
    if rubber:
        parents = hierarchy.link_parent[hierarchy.original]
        originals = hierarchy.original
        rest = skeleton.rest_positions()[hierarchy.original]
    else:
        parents = np.asarray(skeleton.parents)
        originals = slice(None)
        rest = skeleton.rest_positions()
    count = len(parents)
    length = np.linalg.norm(rest - rest[np.maximum(parents, 0)], axis=1)
    child = np.flatnonzero((parents >= 0) & (length > 1e-9 * max(skeleton.height(), 1e-12)))
    frames = len(result.world_positions)
    thickness = np.empty((frames, skeleton.num_joints))
    # Every step is per frame: in blocks of frames, a long clip's temporaries stay small.
    for part in cache_blocks(frames, 8 * skeleton.num_joints):
        positions = result.world_positions[part][:, originals]
        log_stretch = np.zeros((part.stop - part.start, count))
        log_stretch[:, child] = np.log(np.maximum(
            vector_norm(positions[:, child] - positions[:, parents[child]]) / length[child], 1e-6))
        total = np.zeros((part.stop - part.start, count))
        np.add.at(total.T, parents[child], log_stretch[:, child].T)
        outgoing = total / np.maximum(np.bincount(parents[child], minlength=count), 1)
        if rubber:
            link = hierarchy.link_child
            along = np.where(hierarchy.is_original[None, :], outgoing[:, link], log_stretch[:, link])
        else:
            along = outgoing
        thickness[part] = np.clip(np.exp(-0.5 * along), *THICKNESS)
    thickness[np.abs(thickness - 1.0) <= 1e-6] = 1.0
    return None if np.all(thickness == 1.0) else thickness


#: The thinnest and thickest a joint's bone gets by `output_thickness` (stretched 4x, squashed to a quarter).
THICKNESS = (0.5, 2.0)


def base_skin(motion: Motion, result: PipelineResult, skin: Skin | None = None,
              joint_map: dict[str, str] | None = None) -> Skin:
    """The skin on the clip's own joints (in its rest pose, or posed like the character: `Skin.pose`,
    taken up by `at_bind_pose`): ``skin`` bound to the clip
    (`mocap_exaggerate.rig.binding.bind_skin`, with ``joint_map`` for the pairs it misses; as it is
    when it already is), or the default body."""
    skeleton = motion.skeleton
    hierarchy = result.hierarchy
    if skin is None:
        from ..rig.body import default_skin

        return default_skin(skeleton, hierarchy.rigid if hierarchy is not None else None)
    from ..rig.binding import bind_skin

    return bind_skin(skin, skeleton, joint_map)[0]


def at_bind_pose(motion: Motion, result: PipelineResult | None, skin: Skin
                 ) -> tuple[Motion, PipelineResult | None, Skin]:
    """The captured clip, the run and ``skin`` (bound to the clip, `base_skin`) with the pose the skin
    is bound in as the skeletons' rest pose: as they are when it is bound in the rest pose itself.

    A character bound to a clip whose rest pose is far from its own is bound with the clip's
    limbs posed like its own (`Skin.pose`, `mocap_exaggerate.rig.binding.bind_skin`). The clip
    and the run are then the same motion on skeletons resting in that pose
    (`Motion.with_rest`): every frame's positions as they were, the GLB's rest pose the
    character's, and linear blend skinning from there as from any rest pose. The sub-joints
    rest along their links as before (a cut link's sub-joints turn with its first joint).
    """
    if not skin.pose:
        return motion, result, skin
    pose = skin.pose_rows(motion.skeleton.names)
    posed = motion.with_rest(pose)
    if result is not None:
        output_pose = np.tile(quat_identity(), (result.motion.skeleton.num_joints, 1))
        output_pose[result.original_index] = pose
        output = result.motion.with_rest(output_pose)
        hierarchy = result.hierarchy
        if hierarchy is not None and result.motion.skeleton is hierarchy.skeleton:
            hierarchy = replace(hierarchy, skeleton=output.skeleton)  # (the re-weighting reads its rest)
        result = replace(result, motion=output, hierarchy=hierarchy)
    return posed, result, replace(skin, pose={})


def output_skin(motion: Motion, result: PipelineResult, skin: Skin, influences: int = 4) -> Skin:
    """``skin`` (on the clip's joints) bound to the output skeleton, with at most ``influences`` per vertex.

    On the rubber skeleton the weights are redistributed onto the sub-joints
    (`mocap_exaggerate.rig.skinning.reweight`); on the original one the strongest
    influences are kept.
    """
    from ..rig.skinning import reweight

    if influences not in (4, 8):
        raise ConfigError(f"influences must be 4 or 8, got {influences!r}")
    hierarchy = result.hierarchy
    if hierarchy is not None and result.motion.skeleton is hierarchy.skeleton:
        return reweight(skin, motion.skeleton, hierarchy, max_influences=influences)
    # On the output skeleton's own joint list, as the GLB's skin lists them: a character bound to the clip
    # names only the joints it uses, and the .npz's indices then addressed another list than the GLB's.
    names = result.motion.skeleton.names
    if tuple(skin.joint_names) != tuple(names):
        where = {name: k for k, name in enumerate(names)}
        index = np.array([where[name] for name in skin.joint_names], dtype=np.int64)
        skin = Skin(skin.vertices, skin.faces, tuple(names), np.where(skin.weights > 0, index[skin.joints], 0),
                    skin.weights, skin.bind, per_link=skin.per_link)
    if skin.joints.shape[1] > influences:
        rows = np.repeat(np.arange(skin.num_vertices), skin.joints.shape[1])
        joints, weights = top_influences(rows, skin.joints.ravel(), skin.weights.ravel(), skin.num_vertices, influences)
        return Skin(skin.vertices, skin.faces, skin.joint_names, joints, weights, skin.bind, per_link=skin.per_link)
    return skin


def make_glb(motion: Motion, result: PipelineResult, skin: Skin | None = None, units: str = "auto",
             influences: int = 4, joint_map: dict[str, str] | None = None) -> tuple[bytes, bytes, str]:
    """The skinned GLB of a run, its skin as ``.npz`` bytes, and how the units were decided."""
    files = glb_files(motion, result, skin, units, influences, joint_map)
    return b"".join(files.glb), files.weights, files.units


class CharacterFiles(NamedTuple):
    """What `glb_files` makes: the GLB as pieces, the re-weighted skin as ``.npz`` bytes, how the
    units were decided, and the UsdSkel file's bytes (None unless asked for)."""

    glb: list[bytes]
    weights: bytes
    units: str
    usd: bytes | None = None


def glb_files(motion: Motion, result: PipelineResult, skin: Skin | None = None, units: str = "auto",
              influences: int = 4, joint_map: dict[str, str] | None = None, usd: str = "") -> CharacterFiles:
    """As `make_glb`, with the GLB as a list of pieces (no copy of a long clip's animation into one blob).

    motion : the captured clip the run started from
    skin : a character (bound to the clip here when it is not yet, `mocap_exaggerate.rig.binding`;
        ``joint_map`` for the pairs the binding misses), or None for the default body grown
        from the skeleton
    usd : also the same character as a UsdSkel file of this suffix (``usd``, ``usdc``, ``usda``;
        `mocap_exaggerate.io.usd.format_usd`), posed exactly as the GLB
    Joints are scaled by `output_thickness` (kept volume) unless the run's ``output.preserve_volume`` is off.
    """
    from ..io.gltf import glb_pieces, unit_scale
    from ..io.skin import npz_bytes

    scale, how = unit_scale(units, motion.skeleton.height())
    based = base_skin(motion, result, skin, joint_map)
    posed_skin = based
    motion, result, based = at_bind_pose(motion, result, based)
    bound = output_skin(motion, result, based, influences)
    from ..analysis.limbs import standing_up

    step = max(motion.num_frames // 64, 1)  # a sample of the clip tells which way is up
    up = standing_up(motion.skeleton, motion.slice(slice(None, None, step)).world_positions())
    thickness = output_thickness(result)
    glb = glb_pieces(result.motion, bound, meters_per_unit=scale, thickness=thickness, up=up)
    posed = {}
    if posed_skin.pose:  # the mesh is in the GLB's rest, the BVH's posed so: how, for the .npz read back as a skin
        posed["rest_pose"] = posed_skin.pose_rows(bound.joint_names)
    weights = npz_bytes(joint_names=np.array(bound.joint_names), joints=bound.joints, weights=bound.weights,
                        vertices=bound.vertices, faces=bound.faces, **posed)
    scene = None
    if usd:
        from ..io.usd import format_usd

        scene = format_usd(result.motion, bound, suffix=usd, meters_per_unit=scale, thickness=thickness, up=up)
    return CharacterFiles(glb, weights, how, scene)


def captured_glb(motion: Motion, result: PipelineResult, skin: Skin | None = None, units: str = "auto") -> bytes:
    """A GLB of the captured clip with the run's body (``skin`` bound to the clip, else the default body),
    frame for frame with the run's output (its rest frames dropped where the run dropped them), in the
    units and standing as the run's GLB (`glb_files`): the reference a page plays beside the exaggerated one."""
    from ..analysis.limbs import standing_up
    from ..io.gltf import glb_pieces, unit_scale

    scale, _ = unit_scale(units, motion.skeleton.height())
    step = max(motion.num_frames // 64, 1)
    up = standing_up(motion.skeleton, motion.slice(slice(None, None, step)).world_positions())
    shown, _, body = at_bind_pose(motion, None, base_skin(motion, result, skin))
    shown = shown.slice(slice(result.rest_frames, None)) if result.rest_frames_dropped else shown
    return b"".join(glb_pieces(shown, body, meters_per_unit=scale, up=up, name="captured"))
