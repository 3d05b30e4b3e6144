"""FBX out (issue 26, part 2): ``--fbx`` hands our GLB to Blender, which writes it as FBX; Blender
imports that FBX again and poses every joint where the BVH puts it.

Blender runs in its own Python (``MOCAP_BPY_PYTHON``, as `tests.test_blender`); the round trip's
tests skip, saying why, without one. The refusal without Blender needs none.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mocap_exaggerate import convert
from mocap_exaggerate.config import PipelineConfig, load_preset
from mocap_exaggerate.io.bvh import read_bvh

from .helpers import SAMPLE_DIR, shared
from .test_blender import BPY, needs_blender

SCRIPT = Path(__file__).parent / "blender" / "read_fbx.py"


def _with_fbx(config: PipelineConfig) -> PipelineConfig:
    return PipelineConfig.from_dict({**config.to_dict(), "glb": {**config.to_dict()["glb"], "fbx": True}})


def _seen(path: Path, fps: float, frames: list[int]) -> dict:
    done = subprocess.run([BPY, str(SCRIPT), str(path), repr(fps), *map(str, frames)], capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(next(line for line in done.stdout.splitlines() if line.startswith("JSON:"))[5:])


@needs_blender
@pytest.mark.parametrize("clip", ["daz", "zup"])
def test_blender_reads_our_fbx_with_every_joint_where_the_bvh_puts_it(clip, tmp_path, monkeypatch):
    monkeypatch.setenv("MOCAP_BPY_PYTHON", BPY)
    path = SAMPLE_DIR / "cmu_09_01_run_daz.bvh" if clip == "daz" else shared("makehuman_zombie_walk_keyframed.bvh")
    record = convert(path, tmp_path, _with_fbx(load_preset("looney")))
    fbx = record.outputs["fbx"]
    assert fbx.suffix == ".fbx" and fbx.read_bytes()[:18] == b"Kaydara FBX Binary"
    motion, _ = read_bvh(record.outputs["bvh"])
    _, world = motion.forward_kinematics()
    frames = [0, motion.num_frames // 2, motion.num_frames - 1]
    seen = _seen(fbx, motion.fps, frames)
    names = list(motion.skeleton.names)
    assert seen["bones"] == len(names) and seen["leaf_bones"] == 0  # no leaf bones added
    assert seen["frame_range"][1] - seen["frame_range"][0] == pytest.approx(motion.num_frames - 1, abs=0.01)
    from mocap_exaggerate.io.gltf import unit_scale

    scale = unit_scale("auto", read_bvh(path)[0].skeleton.height())[0]  # the GLB's metres
    # glTF's (and our FBX's) Y up: a Z-up clip's joints are turned as the GLB turns them.
    up = motion.skeleton.up_axis()
    turn = np.eye(3) if up == 1 else np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])
    height = motion.skeleton.height() * scale
    for frame in frames:
        theirs = np.array([seen["heads"][str(frame)][n] for n in names])
        ours = world[frame] @ turn.T * scale
        assert np.abs(theirs - ours).max() < 1e-4 * height, frame


def test_without_blender_fbx_is_refused_in_one_line_and_nothing_is_written(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "MOCAP_BPY_PYTHON"}
    env["PATH"] = str(Path(sys.executable).parent)  # no blender on it
    code = ("import sys; sys.modules['bpy'] = None\nimport runpy\nsys.argv = ['mocap-exaggerate', *sys.argv[1:]]\n"
            "runpy.run_module('mocap_exaggerate_cli.main', run_name='__main__')")
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-c", code, "exaggerate", str(SAMPLE_DIR / "cmu_09_01_run_daz.bvh"),
                           "-o", str(out), "--fbx"], capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "FBX output needs Blender" in lines[0], done.stderr
    assert not out.exists()


@needs_blender
def test_the_same_run_writes_the_same_fbx_bytes(tmp_path, monkeypatch):
    # Blender numbers the FBX's objects through Python's hashing and stamps the time: both pinned.
    monkeypatch.setenv("MOCAP_BPY_PYTHON", BPY)
    first, second = (convert(SAMPLE_DIR / "cmu_16_01_jump_amc2bvh.bvh", tmp_path / name,
                             _with_fbx(load_preset("cartoon"))).outputs["fbx"] for name in ("a", "b"))
    assert first.read_bytes() == second.read_bytes()
