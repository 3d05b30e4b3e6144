"""A real client: Blender (the bpy module) imports the rubber BVH we write.

Blender needs its own Python (3.11, numpy < 2), so it runs in a separate process:
``MOCAP_BPY_PYTHON`` names that interpreter (.ci/run sets one up in .bpy-venv).
The tests skip, saying so, when there is none.
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from mocap_exaggerate.config import load_preset
from mocap_exaggerate.io.bvh import format_bvh, read_bvh
from mocap_exaggerate.pipeline import run

from .helpers import ROOT, SAMPLE_DIR

SCRIPT = Path(__file__).parent / "blender" / "read_bvh.py"


def blender_python() -> str | None:
    candidates = [os.environ.get("MOCAP_BPY_PYTHON"), str(ROOT / ".bpy-venv" / "bin" / "python")]
    for candidate in candidates:
        if candidate and Path(candidate).exists():
            check = subprocess.run([candidate, "-c", "import bpy"], capture_output=True, timeout=120)
            if check.returncode == 0:
                return candidate
    return None


BPY = blender_python()
needs_blender = pytest.mark.skipif(
    BPY is None, reason="no Python with Blender's bpy (set MOCAP_BPY_PYTHON, or run .ci/run which makes .bpy-venv)"
)


@needs_blender
@pytest.mark.parametrize("clip", ["cmu_09_01_run_daz.bvh", "mocapbank_sit_down_stand_up.bvh"])
def test_blender_imports_the_rubber_bvh_where_we_computed_it(clip, tmp_path):
    motion, _ = read_bvh(SAMPLE_DIR / clip)
    result = run(motion, load_preset("cartoon"))
    path = tmp_path / clip
    path.write_bytes(format_bvh(result.motion))
    frames = [0, motion.num_frames // 2, motion.num_frames - 1]
    done = subprocess.run([BPY, str(SCRIPT), str(path), *map(str, frames)], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    line = next(line for line in done.stdout.splitlines() if line.startswith("JSON:"))
    seen = json.loads(line[5:])
    assert seen["bones"] == result.motion.skeleton.num_joints
    assert seen["frame_range"][1] - seen["frame_range"][0] + 1 == motion.num_frames
    names = result.motion.skeleton.names
    tolerance = 1e-4 * motion.skeleton.height()  # Blender computes in float32
    for frame in frames:
        theirs = np.array([seen["positions"][str(frame)][name] for name in names])
        assert np.max(np.abs(theirs - result.world_positions[frame])) < tolerance, frame


GLB_SCRIPT = Path(__file__).parent / "blender" / "read_glb.py"


@needs_blender
@pytest.mark.parametrize("clip", ["cmu_09_01_run_daz.bvh", "cmu_16_01_jump_amc2bvh.bvh"])
def test_blender_imports_the_glb_and_deforms_the_mesh_as_we_do(clip, tmp_path):
    from scipy.spatial import cKDTree

    from mocap_exaggerate.io.gltf import unit_scale
    from mocap_exaggerate.jobs.outputs import make_glb

    from .helpers import skinned_vertices

    motion, _ = read_bvh(SAMPLE_DIR / clip)
    result = run(motion, load_preset("cartoon"))
    glb, _, _ = make_glb(motion, result)
    path = tmp_path / "rubber.glb"
    path.write_bytes(glb)
    frames = [5, motion.num_frames // 2]
    done = subprocess.run([BPY, str(GLB_SCRIPT), str(path), str(motion.fps), *map(str, frames)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    seen = json.loads(next(line for line in done.stdout.splitlines() if line.startswith("JSON:"))[5:])
    assert seen["bones"] == result.motion.skeleton.num_joints
    assert seen["frame_range"][1] - seen["frame_range"][0] == pytest.approx(motion.num_frames - 1, abs=0.01)
    meters = unit_scale("auto", motion.skeleton.height())[0]
    for frame in frames:
        ours, _ = skinned_vertices(glb, frame, result, meters)
        theirs = np.array(seen["meshes"][str(frame)])
        distance, _ = cKDTree(ours).query(theirs)
        assert distance.max() < 1e-4  # metres: Blender deforms the mesh exactly as our skinning says
        # and it really moves: the mesh at the two frames differs.
    first, second = (np.array(seen["meshes"][str(f)]) for f in frames)
    assert np.abs(first - second).max() > 0.05


@needs_blender
def test_blender_stands_a_z_up_clip_upright_on_the_floor(tmp_path):
    """A Z-up clip (MakeHuman's zombie walk, `info`: height along Z): Blender imports its GLB standing
    on glTF's +Y, head well above the feet, the body's lowest point on the floor."""
    from mocap_exaggerate.io.gltf import unit_scale
    from mocap_exaggerate.jobs.job import convert

    from .helpers import shared

    clip = shared("makehuman_zombie_walk_keyframed.bvh")
    record = convert(clip, tmp_path)
    motion, _ = read_bvh(clip)
    assert motion.skeleton.up_axis() == 2
    frames = [0, 10, 20, 30]
    done = subprocess.run([BPY, str(GLB_SCRIPT), str(record.outputs["glb"]), str(motion.fps), *map(str, frames)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    seen = json.loads(next(line for line in done.stdout.splitlines() if line.startswith("JSON:"))[5:])
    height = motion.skeleton.height() * unit_scale("auto", motion.skeleton.height())[0]
    for frame in map(str, frames):
        heads, mesh = seen["heads"][frame], np.array(seen["meshes"][frame])
        assert heads["Head"][1] > max(heads["Foot_L"][1], heads["Foot_R"][1]) + 0.6 * height, frame
        assert abs(mesh[:, 1].min()) < 0.02 * height, (frame, mesh[:, 1].min(), height)
        assert mesh[:, 1].max() > 0.85 * height, frame


@needs_blender
@pytest.mark.parametrize("clip", ["cmu_09_01_run_daz.bvh", "makehuman_default_tpose.bvh"])
def test_blender_deforms_the_makehuman_body_bound_to_a_clip_along_its_skeleton(clip, tmp_path):
    """The MakeHuman body (A-pose, Y up, decimetres) with --skin on a CMU clip and on its own one:
    Blender imports the GLB and, at every checked frame, every vertex of the deformed body lies
    within a body's girth of the skeleton Blender poses, and the body is as tall as the skeleton."""
    from scipy.spatial import cKDTree

    from mocap_exaggerate.jobs.job import convert

    from .helpers import SHARED_BVH

    skin_dir = SHARED_BVH.parent / "skin"
    if not (skin_dir / "makehuman_base.obj").exists():
        pytest.skip(f"the MakeHuman body is not at {skin_dir}")
    path = SAMPLE_DIR / clip if (SAMPLE_DIR / clip).exists() else skin_dir / clip
    record = convert(path, tmp_path, skin=skin_dir / "makehuman_base.obj")
    motion, _ = read_bvh(path)
    frames = sorted({0, motion.num_frames // 3, (2 * motion.num_frames) // 3})
    done = subprocess.run([BPY, str(GLB_SCRIPT), str(record.outputs["glb"]), str(motion.fps), *map(str, frames)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    seen = json.loads(next(line for line in done.stdout.splitlines() if line.startswith("JSON:"))[5:])
    assert seen["vertices"] > 10_000  # the MakeHuman body, not the capsule body
    for frame in map(str, frames):
        mesh = np.array(seen["meshes"][frame])
        heads = np.array(list(seen["heads"][frame].values()))
        height = np.ptp(heads[:, 1])  # glTF's Y up: the skeleton as Blender poses it
        distance, _ = cKDTree(heads).query(mesh)
        assert distance.max() < 0.15 * height, (frame, distance.max() / height)
        assert np.ptp(mesh[:, 1]) == pytest.approx(height, rel=0.25), frame
