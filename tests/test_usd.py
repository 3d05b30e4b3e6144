"""UsdSkel output (issue 26, part 1): ``--usd`` writes the GLB's character as a skinned, animated
UsdSkel that Pixar's own libraries validate and pose where our BVH and GLB put it.

Checked with ``usd-core`` itself: ``pxr.UsdValidation`` (every registered validator, no error),
``pxr.UsdSkel`` evaluating the skeleton (every joint's world position against the BVH's forward
kinematics and the GLB's nodes) and the skinning (every vertex against the GLB's own skinning), the
joint names USD cannot take as paths, and the command line's refusals.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from mocap_exaggerate import convert
from mocap_exaggerate.config import PipelineConfig, load_preset
from mocap_exaggerate.core.skeleton import Skeleton
from mocap_exaggerate.io.bvh import read_bvh

from .helpers import SAMPLE_DIR, glb_joint_positions, shared, skinned_vertices

pxr = pytest.importorskip("pxr", reason="usd-core is not installed (pip install 'mocap-exaggerate[usd]')")
from pxr import Usd, UsdGeom, UsdSkel, UsdValidation, Vt  # noqa: E402

from mocap_exaggerate.io.usd import format_usd, joint_paths  # noqa: E402

RUN = SAMPLE_DIR / "cmu_09_01_run_daz.bvh"


def _validate(path) -> list[str]:
    registry = UsdValidation.ValidationRegistry()
    context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    stage = Usd.Stage.Open(str(path))
    return [f"{e.GetName()}: {e.GetMessage()}" for e in context.Validate(stage)
            if e.GetType() == UsdValidation.ValidationErrorType.Error]


def _posed(path, frames):
    """World joint positions (F, J, 3) by joint name order, and skinned points (F, V, 3), as USD poses them."""
    stage = Usd.Stage.Open(str(path))
    root = UsdSkel.Root(stage.GetDefaultPrim())
    cache = UsdSkel.Cache()
    cache.Populate(root, Usd.PrimDefaultPredicate)
    bindings = cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate)
    assert len(bindings) == 1
    skel = bindings[0].GetSkeleton()
    query = cache.GetSkelQuery(skel)
    (target,) = bindings[0].GetSkinningTargets()
    mesh_points = np.array(stage.GetPrimAtPath(target.GetPrim().GetPath()).GetAttribute("points").Get())
    joints, points = [], []
    for frame in frames:
        time = Usd.TimeCode(frame)
        world = np.array(query.ComputeJointWorldTransforms(UsdGeom.XformCache(time)))
        joints.append(world[:, 3, :3])
        skinning = query.ComputeSkinningTransforms(time)
        moved = Vt.Vec3fArray.FromNumpy(mesh_points.astype(np.float32))
        assert target.ComputeSkinnedPoints(skinning, moved, time)
        points.append(np.array(moved, dtype=np.float64))
    names = list(skel.GetJointNamesAttr().Get())
    return names, np.array(joints), np.array(points)


@pytest.fixture(scope="module")
def run_outputs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("usd")
    record = convert(RUN, folder, _with_usd(load_preset("looney"), "usda"), preset="looney")
    return folder, record


def _with_usd(config: PipelineConfig, suffix: str) -> PipelineConfig:
    return PipelineConfig.from_dict({**config.to_dict(), "glb": {**config.to_dict()["glb"], "usd": suffix}})


def test_the_usd_file_passes_every_usd_validator(run_outputs):
    folder, record = run_outputs
    assert record.outputs["usd"].suffix == ".usda"
    assert _validate(record.outputs["usd"]) == []


def test_usd_poses_every_joint_where_the_bvh_and_the_glb_put_them(run_outputs):
    folder, record = run_outputs
    motion, _ = read_bvh(record.outputs["bvh"])
    _, world = motion.forward_kinematics()
    glb = record.outputs["glb"].read_bytes()
    frames = [0, motion.num_frames // 2, motion.num_frames - 1]
    names, joints, _ = _posed(record.outputs["usd"], frames)
    assert names == list(motion.skeleton.names)
    height = motion.skeleton.height() * 0.01  # the Daz run is in centimetres: metres in the GLB and the USD
    for k, frame in enumerate(frames):
        assert np.abs(joints[k] - world[frame] * 0.01).max() <= 1e-4 * height
        nodes = glb_joint_positions(glb, frame)
        assert np.abs(joints[k] - np.array([nodes[n] for n in names])).max() <= 1e-4 * height


def test_usd_skins_every_vertex_where_the_glb_does(run_outputs):
    from mocap_exaggerate.pipeline import run

    folder, record = run_outputs
    captured, _ = read_bvh(RUN)
    result = run(captured, load_preset("looney"))
    glb = record.outputs["glb"].read_bytes()
    frames = [0, 40, 100]
    _, _, points = _posed(record.outputs["usd"], frames)
    height = captured.skeleton.height() * 0.01
    for k, frame in enumerate(frames):
        expected, _ = skinned_vertices(glb, frame, result, 0.01)
        assert points[k].shape == expected.shape
        assert np.abs(points[k] - expected).max() <= 1e-4 * height


def test_a_z_up_clip_stands_on_usds_y_up_as_in_the_glb(tmp_path):
    clip = shared("cmu_131_01_walk_start_stop_max.bvh")
    record = convert(clip, tmp_path, _with_usd(load_preset("cartoon"), "usdc"))
    assert _validate(record.outputs["usd"]) == []
    stage = Usd.Stage.Open(str(record.outputs["usd"]))
    assert UsdGeom.GetStageUpAxis(stage) == "Y" and UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    glb = record.outputs["glb"].read_bytes()
    names, joints, _ = _posed(record.outputs["usd"], [0, 50])
    for k, frame in enumerate([0, 50]):
        nodes = glb_joint_positions(glb, frame)
        expected = np.array([nodes[n] for n in names])
        assert np.abs(joints[k] - expected).max() <= 1e-4 * np.ptp(expected[:, 1])


def test_names_usd_cannot_take_are_made_valid_in_paths_and_kept_as_names(tmp_path):
    names = ("mixamorig:Hips", "left leg", "left:leg", "1st", "mixamorig:Spine")
    parents = np.array([-1, 0, 0, 1, 0])
    assert joint_paths(names, parents) == ["mixamorig_Hips", "mixamorig_Hips/left_leg", "mixamorig_Hips/left_leg_2",
                                           "mixamorig_Hips/left_leg/_st", "mixamorig_Hips/mixamorig_Spine"]
    offsets = np.array([[0, 1, 0], [0.2, -0.1, 0], [-0.2, -0.1, 0], [0, -0.5, 0], [0, 0.3, 0]], dtype=float)
    channels = tuple(("Zrotation", "Xrotation", "Yrotation") for _ in names)
    skeleton = Skeleton(names, parents, offsets, channels, np.full((5, 3), np.nan))
    from mocap_exaggerate.core.motion import Motion
    from mocap_exaggerate.rig.body import default_skin

    rotations = np.zeros((3, 5, 4))
    rotations[..., 3] = 1.0
    motion = Motion(skeleton.with_full_channels(), 0.1, rotations, np.broadcast_to(offsets, (3, 5, 3)).copy())
    path = tmp_path / "names.usda"
    path.write_bytes(format_usd(motion, default_skin(skeleton), suffix="usda"))
    stage = Usd.Stage.Open(str(path))
    skel = UsdSkel.Skeleton(stage.GetPrimAtPath("/mocap_exaggerate/Skeleton"))
    topology = UsdSkel.Topology(skel.GetJointsAttr().Get())
    valid, why = topology.Validate()
    assert valid, why
    assert list(topology.GetParentIndices()) == list(parents)  # not five roots
    assert list(skel.GetJointNamesAttr().Get()) == list(names)
    assert _validate(path) == []


def _cli(*args, cwd, before: str = ""):
    """The command line in a real process (``python -m``), with ``before`` run first in it."""
    if not before:
        return subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", *args], cwd=cwd,
                              capture_output=True, text=True, timeout=120)
    code = f"{before}\nimport runpy, sys\nsys.argv = ['mocap-exaggerate', *sys.argv[1:]]\n" \
           "runpy.run_module('mocap_exaggerate_cli.main', run_name='__main__')"
    return subprocess.run([sys.executable, "-c", code, *args], cwd=cwd, capture_output=True, text=True, timeout=120)


def test_without_usd_core_the_option_is_refused_in_one_line_and_nothing_is_written(tmp_path):
    out = tmp_path / "out"
    done = _cli("exaggerate", str(RUN), "-o", str(out), "--usd", "usda", cwd=tmp_path,
                before="import sys; sys.modules['pxr'] = None  # as if usd-core were not installed")
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "pip install 'mocap-exaggerate[usd]'" in lines[0], done.stderr
    assert not out.exists()


@pytest.mark.parametrize("args, says", [
    (("--usd", "fbx"), "'fbx' is not one of"),
    (("--usd", "usda", "--no-glb"), "drop --no-glb"),
])
def test_bad_usd_options_are_one_line(tmp_path, args, says):
    out = tmp_path / "out"
    done = _cli("exaggerate", str(RUN), "-o", str(out), *args, cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert says in done.stderr and "Traceback" not in done.stderr
    assert not out.exists()


def test_the_same_run_writes_the_same_usd_bytes_and_its_pipeline_file_rebuilds_them(tmp_path):
    first, second = tmp_path / "a", tmp_path / "b"
    done = _cli("exaggerate", str(RUN), "-o", str(first), "--usd", "usdc", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert ".usdc" in done.stderr  # the summary line names it
    again = _cli("exaggerate", str(RUN), "-o", str(second), "--config", str(first / f"{RUN.stem}.pipeline.toml"),
                 cwd=tmp_path)
    assert again.returncode == 0, again.stderr
    assert (first / f"{RUN.stem}.usdc").read_bytes() == (second / f"{RUN.stem}.usdc").read_bytes()
