"""Any rig the right way up: the up axis, the root OFFSET convention, and a GLB that stands on glTF's +Y."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from mocap_exaggerate.config import load_preset, resolve_config
from mocap_exaggerate.core.motion import Motion
from mocap_exaggerate.core.rotations import quat_mul, quat_rotate
from mocap_exaggerate.core.skeleton import Skeleton
from mocap_exaggerate.io.bvh import format_bvh, read_bvh
from mocap_exaggerate.jobs.outputs import make_glb
from mocap_exaggerate.pipeline import run

from .helpers import SAMPLE_DIR, glb_joint_positions, shared, shared_clip_params

RUN = SAMPLE_DIR / "cmu_09_01_run_daz.bvh"
#: +90 degrees about X: Y up becomes Z up and the +Z front becomes -Y (Blender's and 3ds Max's way).
TO_Z_UP = np.array([np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)])


def turned(motion: Motion, q: np.ndarray) -> Motion:
    """The same clip with the whole world turned by ``q``: every offset turned, every joint's
    rotation conjugated, so that each joint's world position is the old one turned."""
    s = motion.skeleton
    ends = np.where(np.isfinite(s.end_sites), quat_rotate(q, np.nan_to_num(s.end_sites)), np.nan)
    skeleton = Skeleton(s.names, s.parents, quat_rotate(q, s.offsets), s.channels, ends)
    inverse = q * np.array([-1, -1, -1, 1])
    rotations = quat_mul(quat_mul(q, motion.local_rotations), inverse)
    return Motion(skeleton, motion.frame_time, rotations, quat_rotate(q, motion.local_positions))


def test_a_z_up_clip_stands_in_the_glb_where_its_y_up_original_stands(tmp_path):
    """The run turned to Z up (through a BVH file): read as Z up, exaggerated, and its GLB's joints
    are where the Y-up original's GLB puts them, frame for frame (glTF is +Y up, +Z front)."""
    motion, _ = read_bvh(RUN)
    z_up, _ = read_bvh(format_bvh(turned(motion, TO_Z_UP)))
    assert z_up.skeleton.up_axis() == 2 and motion.skeleton.up_axis() == 1
    np.testing.assert_allclose(z_up.world_positions()[7], quat_rotate(TO_Z_UP, motion.world_positions()[7]), atol=1e-4)
    for config in (resolve_config("cartoon", None, {"extrapolate": {"omega": 1.0}, "springs": {"enabled": False}}),
                   load_preset("cartoon")):
        glbs = [make_glb(m, run(m, config))[0] for m in (motion, z_up)]
        for frame in (0, 60, 148):
            ours, theirs = (glb_joint_positions(glb, frame) for glb in glbs)
            assert ours.keys() == theirs.keys()
            gap = max(np.linalg.norm(ours[n] - theirs[n]) for n in ours)
            assert gap < 2e-3, (frame, gap)  # metres, on a 1.5 m body
            assert ours["head"][1] > min(ours["lFoot"][1], ours["rFoot"][1]) + 0.7  # standing on +Y


def test_up_given_wins_and_is_recorded():
    """--up says the axis when the rest pose cannot: it is the skeleton's up, kept through the pipeline."""
    motion, _ = read_bvh(RUN, up="z")
    assert motion.skeleton.up_axis() == 2
    result = run(motion, load_preset("subtle"))
    assert result.motion.skeleton.up_axis() == 2
    with pytest.raises(Exception, match="up must be one of"):
        read_bvh(RUN, up="w")


def test_reallusion_root_channels_add_to_the_offset(tmp_path):
    """iClone: the root OFFSET is the hips' height and its channels move it. Read as replacing it
    (bvhio, Blender) the body stands a metre under the floor; auto reads them as adding, so the
    feet are on it. The written BVH is in the standard convention (the root's channels are its
    position, the hips' height up); asked for, it keeps the file's own numbers and convention."""
    path = shared("cmu_06_15_basketball_dribble_shoot_iclone.bvh")
    added, report = read_bvh(path)
    replaced, replace_report = read_bvh(path, root_offset="replace")
    assert report.root_offset == "add" and replace_report.root_offset == "replace"
    height = added.skeleton.height()
    lowest = np.percentile(added.world_positions()[..., 1].min(axis=1), 5)
    assert -0.02 * height < lowest < 0.1 * height
    dropped = added.world_positions() - replaced.world_positions()
    np.testing.assert_allclose(dropped, np.broadcast_to(added.skeleton.offsets[0], dropped.shape), atol=1e-6)
    source = path.read_text()

    def first_row(text):
        return [float(v) for v in text.split("Frame Time:")[1].splitlines()[1].split()[:3]]

    # By default the root's channels are its position, the OFFSET replaced: every reader's convention.
    text = format_bvh(added).decode()
    assert first_row(text) == pytest.approx(np.array(first_row(source)) + added.skeleton.offsets[0], abs=1e-5)
    again, again_report = read_bvh(text.encode())
    assert again_report.root_offset == "replace"
    np.testing.assert_allclose(again.world_positions(), added.world_positions(), atol=1e-4)
    # Asked for, the root's channel values go back out as they came in (the file's own convention).
    text = format_bvh(added, positions="input").decode()
    assert first_row(text) == pytest.approx(first_row(source), abs=1e-6)
    again, again_report = read_bvh(text.encode())
    assert again_report.root_offset == "add"
    np.testing.assert_allclose(again.world_positions(), added.world_positions(), atol=1e-4)


def test_makehuman_position_channels_on_every_joint_add_to_the_offsets():
    """MakeHuman writes six channels on every joint, zeros for the position: replaced, every bone
    shrinks to nothing; auto reads them as adding, and the T-pose is as tall as its skeleton."""
    path = shared("../skin/makehuman_default_tpose.bvh")
    added, report = read_bvh(path)
    replaced, _ = read_bvh(path, root_offset="replace")
    assert report.root_offset == "add"
    height = added.skeleton.height()
    assert np.ptp(added.world_positions()[0, :, 2]) == pytest.approx(height, rel=0.05)
    assert np.ptp(replaced.world_positions()[0], axis=0).max() < 0.2 * height


@pytest.mark.parametrize("given", ["replace", "add"])
def test_root_offset_on_the_command_line(given, tmp_path):
    """--root-offset as users run it: recorded in the pipeline file, the manifest's parameters change."""
    path = shared("cmu_06_15_basketball_dribble_shoot_iclone.bvh")
    done = subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", "-q", "exaggerate", str(path),
                           "-o", str(tmp_path), "--root-offset", given, "--no-glb"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert f'root_offset = "{given}"' in (tmp_path / f"{path.stem}.pipeline.toml").read_text()
    written, report = read_bvh(tmp_path / f"{path.stem}.bvh")  # written in the standard convention
    assert report.root_offset == "replace"
    lowest = np.percentile(written.world_positions()[..., 1].min(axis=1), 5)
    assert (lowest > -0.05 * written.skeleton.height()) == (given == "add")
    bad = subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", "exaggerate", str(path),
                          "-o", str(tmp_path / "x"), "--root-offset", "sideways"], capture_output=True, text=True)
    assert bad.returncode == 2 and "Traceback" not in bad.stderr and not (tmp_path / "x").exists()


# ---------------------------------------------------------------------------- weights on any rig


@pytest.mark.parametrize("path", shared_clip_params())
def test_root_weight_zero_keeps_every_rig_within_the_presets_stretch(path):
    """``--weight root=0`` means the root on every rig; no link explodes (the presets' worst link
    stretch over the shared clips is 1.46x at cartoon: held to 1.5)."""
    motion, _ = read_bvh(path, fps=120.0 if "amc2bvh" in path.name else None)  # its header says 30
    result = run(motion, resolve_config("cartoon", None, {"extrapolate": {"weights": [["root", 0.0]]}}))
    assert result.max_link_stretch < 1.5


def test_a_weight_on_a_root_with_a_welded_pelvis_moves_both():
    """iClone's CC_Base_Pelvis sits on CC_Base_Hip (a link of 0.07 mm). A weight given to the hip
    alone once opened that link into 9 cm (138,445x); welded joints now share their weight."""
    from mocap_exaggerate.stages.extrapolate import resolve_weights, welded

    motion, _ = read_bvh(shared("cmu_06_15_basketball_dribble_shoot_iclone.bvh"))
    skeleton = motion.skeleton
    hip, pelvis = skeleton.index("CC_Base_Hip"), skeleton.index("CC_Base_Pelvis")
    assert welded(skeleton)[pelvis] == hip
    weights = resolve_weights(skeleton, (("CC_Base_Hip", 0.0),))
    assert weights[hip] == weights[pelvis] == 0.0 and weights.sum() == skeleton.num_joints - 2
    result = run(motion, resolve_config("cartoon", None, {"extrapolate": {"weights": [["CC_Base_Hip", 0.0]]}}))
    assert result.max_link_stretch < 1.5
    out = result.world_positions[:, result.original_index]
    assert np.linalg.norm(out[:, pelvis] - out[:, hip], axis=1).max() < 0.001 * skeleton.height()
    # `root` and `pelvis` name the root, unless a joint has that name (MakeHuman's root joint is `root`).
    assert np.array_equal(resolve_weights(skeleton, (("pelvis", 0.0),)), weights)
