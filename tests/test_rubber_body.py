"""Issue 23, point 3: the default body is one rubber figure. Its tubes stay on their skeleton at
every frame of the exaggerated motion, with the stretch pass too, and get thinner where a link
stretches (volume kept), in the GLB as in the preview."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pygltflib
import pytest
from scipy.spatial import cKDTree

from mocap_exaggerate.config import PipelineConfig, load_preset
from mocap_exaggerate.core.skeleton import Skeleton
from mocap_exaggerate.io.bvh import read_bvh
from mocap_exaggerate.jobs.outputs import THICKNESS, base_skin, make_glb, output_skin, output_thickness
from mocap_exaggerate.pipeline import run
from mocap_exaggerate.rig.skinning import pose_skin
from mocap_exaggerate.stages.contacts import ContactConfig
from mocap_exaggerate.stages.correct import CorrectConfig
from mocap_exaggerate.stages.extrapolate import ExtrapolateConfig
from mocap_exaggerate.stages.springs import SpringConfig
from mocap_exaggerate.viz.posing import pose_bodies

from .helpers import ROOT, SAMPLE_CLIPS, mesh_pieces, shared

IDENTITY = PipelineConfig(extrapolate=ExtrapolateConfig(enabled=False, omega=1.0), correct=CorrectConfig(enabled=False),
                          springs=SpringConfig(enabled=False), contacts=ContactConfig(enabled=False))


def _chain(stretch: np.ndarray) -> SimpleNamespace:
    """A result whose three-joint chain (links of length 1 and 2 along x) is stretched by ``stretch`` (F, 2)."""
    names = ("a", "b", "c")
    skeleton = Skeleton(names, np.array([-1, 0, 1]), np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]),
                        tuple(("Xrotation", "Yrotation", "Zrotation") for _ in names), np.full((3, 3), np.nan))
    frames = len(stretch)
    positions = np.zeros((frames, 3, 3))
    positions[:, 1, 0] = 1.0 * stretch[:, 0]
    positions[:, 2, 0] = positions[:, 1, 0] + 2.0 * stretch[:, 1]
    return SimpleNamespace(motion=SimpleNamespace(skeleton=skeleton), world_positions=positions, hierarchy=None,
                           preserve_volume=True)


def test_thickness_keeps_each_bones_volume_worked_by_hand():
    # Frame 0 as captured; frame 1 the first link stretched 2x, the second squashed to half;
    # frame 2 the first stretched 16x (thinner than the floor).
    result = _chain(np.array([[1.0, 1.0], [2.0, 0.5], [16.0, 1.0]]))
    thickness = output_thickness(result)
    expected = np.array([[1.0, 1.0, 1.0], [1 / np.sqrt(2), np.sqrt(2), 1.0], [THICKNESS[0], 1.0, 1.0]])
    np.testing.assert_allclose(thickness, expected, rtol=1e-12)
    # A branch takes the geometric mean of its links' stretches.
    names = ("a", "b", "c")
    star = Skeleton(names, np.array([-1, 0, 0]), np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]),
                    tuple(("Xrotation", "Yrotation", "Zrotation") for _ in names), np.full((3, 3), np.nan))
    positions = np.array([[[0.0, 0, 0], [4, 0, 0], [0, 1, 0]]])
    thickness = output_thickness(SimpleNamespace(motion=SimpleNamespace(skeleton=star), world_positions=positions,
                                                 hierarchy=None, preserve_volume=True))
    np.testing.assert_allclose(thickness, [[1 / np.sqrt(2), 1.0, 1.0]], rtol=1e-12)


def test_nothing_stretched_writes_no_scale_track(sample_clip):
    motion, _ = read_bvh(sample_clip)
    result = run(motion, IDENTITY)
    assert output_thickness(result) is None
    glb, _, _ = make_glb(motion, result)
    paths = {c.target.path for c in pygltflib.GLTF2.load_from_bytes(glb).animations[0].channels}
    assert paths == {"translation", "rotation"}


def _scale_tracks(glb: bytes) -> int:
    return sum(c.target.path == "scale" for c in pygltflib.GLTF2.load_from_bytes(glb).animations[0].channels)


def test_preserve_volume_off_keeps_every_bone_its_thickness(tmp_path):
    clip = ROOT / "sample_data" / "cmu_09_01_run_daz.bvh"
    for flag, scaled in (("--preserve-volume", True), ("--no-preserve-volume", False)):
        out = tmp_path / flag
        done = subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", "exaggerate", str(clip), "-o", str(out),
                               "--preset", "looney", flag], capture_output=True, text=True, cwd=ROOT, timeout=300)
        assert done.returncode == 0, done.stderr
        (glb,) = out.glob("*.glb")
        assert (_scale_tracks(glb.read_bytes()) > 0) == scaled


def _gaps(motion, config) -> tuple[float, float]:
    """The farthest any joint or link middle of the output skeleton is from the posed body (every
    frame), and the same at rest, each point against the tube that carries it (in heights)."""
    result = run(motion, config)
    skin = output_skin(motion, result, base_skin(motion, result))
    skeleton = result.motion.skeleton
    index = np.array([skeleton.index(n) for n in skin.joint_names])
    carried = np.ones(skeleton.num_joints, bool)
    carried[result.original_index] = ~result.hierarchy.rigid
    parents = np.asarray(skeleton.parents)
    child = np.flatnonzero(carried & (parents >= 0))
    rest = skeleton.rest_positions()

    def points(p):
        return np.concatenate([p[..., np.flatnonzero(carried), :], 0.5 * (p[..., child, :] + p[..., parents[child], :])],
                              axis=-2)

    # At rest, against the piece that carries each point (weighted to its joint or its link's head).
    piece = mesh_pieces(skin)
    owners = np.concatenate([np.flatnonzero(carried), parents[child]])
    heads = np.concatenate([np.flatnonzero(carried), child])
    at_rest = points(rest)
    own = np.full(len(at_rest), np.inf)
    for p in np.unique(piece):
        weighted = np.isin(np.arange(skeleton.num_joints), index[skin.joints[piece == p][skin.weights[piece == p] > 0]])
        mine = weighted[owners] | weighted[heads]
        if mine.any():
            own[mine] = np.minimum(own[mine], cKDTree(skin.vertices[piece == p]).query(at_rest[mine])[0])
    thickness = output_thickness(result)
    worst = 0.0
    for frame in range(result.motion.num_frames):
        posed = pose_skin(skin, rest, result.world_rotations[frame], result.world_positions[frame], index,
                          None if thickness is None else thickness[frame])
        worst = max(worst, cKDTree(posed).query(points(result.world_positions[frame]))[0].max())
    height = motion.skeleton.height()
    return worst / height, own[np.isfinite(own)].max() / height


def _looney_stretched():
    looney = load_preset("looney")
    return replace(looney, auto_stretch=replace(looney.auto_stretch, enabled=True))


@pytest.mark.parametrize("setting", ["looney", "looney+auto-stretch"])
@pytest.mark.parametrize("path", SAMPLE_CLIPS + ["cmu_05_06_dance_cartwheel_start_iclone.bvh"],
                         ids=lambda p: getattr(p, "stem", str(p).removesuffix(".bvh")))
def test_the_body_never_parts_from_its_skeleton(path, setting):
    """At every frame, every joint and link of the rubber skeleton stays inside its tube: no point
    is farther from the posed body's surface than 1.5x its rest distance to its own tube (the
    issue's target; 0.86-1.13x on all 33 shared rigs in bench/skin.py, which also measures along
    the mesh's edges). A tube parted from its joint, or a joint rotated out of its tube, fails."""
    motion, _ = read_bvh(path if not isinstance(path, str) else shared(path))
    config = _looney_stretched() if setting.endswith("auto-stretch") else load_preset(setting)
    worst, rest = _gaps(motion, config)
    assert worst <= 1.5 * rest, (worst, rest)


def test_a_stretched_limb_is_thinner_in_the_preview_as_in_the_glb():
    """The preview poses the body with the GLB's scales: at the frame of the largest stretch, the
    tube around the most stretched sub-link is thinner than its rest radius by 1/sqrt(stretch)."""
    motion, _ = read_bvh(ROOT / "sample_data" / "cmu_09_01_run_daz.bvh")
    result = run(motion, _looney_stretched())
    thickness = output_thickness(result)
    skin = output_skin(motion, result, base_skin(motion, result))
    skeleton = result.motion.skeleton
    index = np.array([skeleton.index(n) for n in skin.joint_names])
    # The sub-joint holding some vertices alone whose link is stretched most.
    held = np.zeros((skin.num_vertices, skeleton.num_joints))
    np.add.at(held, (np.repeat(np.arange(skin.num_vertices), 4), index[skin.joints].ravel()), skin.weights.ravel())
    holders = np.flatnonzero((held > 0.999).any(axis=0))
    frame, pick = np.unravel_index(np.argmin(thickness[:, holders]), (len(thickness), len(holders)))
    joint = holders[pick]
    assert thickness[frame, joint] < 0.9
    alone = np.flatnonzero(held[:, joint] > 0.999)
    rest = skeleton.rest_positions()
    posed = pose_skin(skin, rest, result.world_rotations[frame], result.world_positions[frame], index, thickness[frame])
    plain = pose_skin(skin, rest, result.world_rotations[frame], result.world_positions[frame], index)
    centre = result.world_positions[frame, joint]
    ratio = np.linalg.norm(posed[alone] - centre, axis=1) / np.linalg.norm(plain[alone] - centre, axis=1)
    np.testing.assert_allclose(ratio, thickness[frame, joint], rtol=1e-9)
    # With output.preserve_volume off the run says so, and the preview poses the plain body.
    kept = run(motion, replace(_looney_stretched(), output=replace(_looney_stretched().output, preserve_volume=False)))
    assert output_thickness(kept) is None
    # (the preview blends matrices, `pose_skin` turns offsets: the same sum to the last bits)
    np.testing.assert_allclose(pose_bodies(motion, kept, [frame]).exaggerated[0],
                               pose_skin(skin, rest, kept.world_rotations[frame], kept.world_positions[frame], index),
                               rtol=0, atol=1e-9 * motion.skeleton.height())
