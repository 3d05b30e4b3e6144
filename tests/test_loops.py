"""Looping clips (`mocap_exaggerate.analysis.loops`): a game's cycle is run as the loop repeated, so the
exaggerated cycle still loops, whichever frame it starts on."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from mocap_exaggerate.analysis.loops import find_loop
from mocap_exaggerate.config import load_preset
from mocap_exaggerate.core.errors import ConfigError
from mocap_exaggerate.core.motion import Motion
from mocap_exaggerate.io.bvh import load_bvh
from mocap_exaggerate.pipeline import run

from .helpers import SAMPLE_DIR, SHARED_BVH

ROBOT = SHARED_BVH.parent / "gltf" / "robot_expressive_quaternius.glb"
FOX = SHARED_BVH.parent / "gltf" / "fox_khronos.glb"


def _with_loop(preset: str, mode: str):
    config = load_preset(preset)
    return replace(config, input=replace(config.input, loop=mode))


def _frames(motion: Motion, index) -> Motion:
    hint = None if motion.euler_hint is None else motion.euler_hint[index]
    return Motion(motion.skeleton, motion.frame_time, motion.local_rotations[index], motion.local_positions[index],
                  hint)


def _there_and_back() -> Motion:
    """A closed loop made of a real clip: the Daz run's frames 10-69 (past its T-pose), and back at twice the
    speed (no two frames of the cycle alike, so its calmest frame is one)."""
    motion = load_bvh(SAMPLE_DIR / "cmu_09_01_run_daz.bvh")
    return _frames(motion, np.r_[np.arange(10, 70), np.arange(68, 9, -2)])


def _started_at(loop: Motion, k: int) -> Motion:
    """The same closed loop started on its frame ``k`` (and closed there)."""
    period = loop.num_frames - 1
    return _frames(loop, np.r_[np.arange(k, period), np.arange(k), [k]])


def _cycle_error(motion: Motion, config, k: int) -> float:
    """How far (in body heights) the output of the loop started at frame ``k`` is from the output of the loop
    itself, moved on by ``k`` frames: 0 for an output that is the same cycle wherever it starts."""
    period = motion.num_frames - 1
    ours = run(motion, config).motion.world_positions()[:period]
    moved = run(_started_at(motion, k), config).motion.world_positions()[:period]
    return float(np.abs(np.roll(ours, -k, axis=0) - moved).max() / motion.skeleton.height())


@pytest.mark.parametrize("preset", ["cartoon", "looney"])
def test_a_loop_gives_the_same_cycle_whichever_frame_it_starts_on(preset):
    loop = _there_and_back()
    assert find_loop(loop, *reversed(loop.forward_kinematics())) is not None
    assert _cycle_error(loop, _with_loop(preset, "auto"), 31) < 1e-6
    # Taken as a clip, its ends are ends: the same cycle started elsewhere is another motion.
    assert _cycle_error(loop, _with_loop(preset, "off"), 31) > 0.05


def test_a_closed_loop_closes_exactly_and_its_seam_is_a_step_like_the_others():
    loop = _there_and_back()
    result = run(loop, _with_loop("looney", "auto"))
    assert result.notes[0].startswith("a loop of 89 frames (its last frame repeating its first)")
    out = result.motion
    np.testing.assert_array_equal(out.local_rotations[-1], out.local_rotations[0])
    np.testing.assert_array_equal(out.local_positions[-1], out.local_positions[0])
    world = out.world_positions()
    steps = np.linalg.norm(np.diff(world, axis=0), axis=-1).max(axis=1)
    assert steps[-1] <= steps[:-1].max()  # into the frame that is the first again: no pop
    # The manifest's frame numbers are the clip's own.
    assert result.motion.num_frames == loop.num_frames == len(result.world_positions)
    for runs in result.constraints["contacts"].values():
        assert all(0 <= a <= b < loop.num_frames for a, b in runs)


def test_a_capture_is_not_a_loop_and_runs_as_before():
    motion = load_bvh(SAMPLE_DIR / "cmu_16_01_jump_amc2bvh.bvh")
    auto = run(motion, _with_loop("cartoon", "auto"))
    off = run(motion, _with_loop("cartoon", "off"))
    assert not any("loop" in note for note in auto.notes)
    np.testing.assert_array_equal(auto.motion.local_rotations, off.motion.local_rotations)
    np.testing.assert_array_equal(auto.motion.local_positions, off.motion.local_positions)


def test_frame_keyed_requests_keep_a_loop_a_clip_and_loop_on_refuses_them():
    loop = _there_and_back()
    config = _with_loop("cartoon", "auto")
    from mocap_exaggerate.stages.contacts import parse_target

    targeted = replace(config, target=(parse_target("rHand@40"),))
    result = run(loop, targeted)
    assert any("it has targets, keyed to its frames: not run as a loop" in warning for warning in result.warnings)
    with pytest.raises(ConfigError, match="input.loop = on: a clip with targets"):
        run(loop, replace(targeted, input=replace(targeted.input, loop="on")))


def test_a_clip_starting_in_a_rest_pose_is_not_a_loop():
    motion = load_bvh(SAMPLE_DIR / "cmu_09_01_run_daz.bvh")  # a T-pose first: back to it at the end
    ends = _frames(motion, np.r_[np.arange(motion.num_frames), [0]])
    result = run(ends, _with_loop("cartoon", "auto"))
    assert "starts in a rest pose: not run as a loop" in result.notes[0]


@pytest.mark.skipif(not ROBOT.exists(), reason=f"the shared glTF robot is not at {ROBOT}")
def test_the_robots_run_cycle_loops_in_the_written_files(tmp_path):
    """The Quaternius robot's Running (its last key its first) at cartoon: it had jumped 0.33 heights where it
    loops; the written BVH's and GLB's last frames are now their first again."""
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", "exaggerate", str(ROBOT), "--clip",
                           "Running", "-o", str(out), "-v"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert "a loop of 23 frames" in done.stdout + done.stderr
    from mocap_exaggerate.io.gltf_motion import read_gltf_motion

    height = read_gltf_motion(ROBOT, clip="Running")[0].skeleton.height()
    bvh = load_bvh(out / "robot_expressive_quaternius_Running.bvh").world_positions()
    glb = read_gltf_motion(out / "robot_expressive_quaternius_Running.glb")[0].world_positions()
    for world in (bvh, glb):  # (a BVH's Euler angles may differ by whole turns and still be the same pose)
        assert len(world) == 24
        assert np.abs(world[-1] - world[0]).max() < 1e-5 * height
        # ... and the step into the last frame (the first again) is one like the others, not a jump
        steps = np.linalg.norm(np.diff(world, axis=0), axis=-1).max(axis=1)
        assert steps[-1] <= steps[:-1].max()
    off = run(read_gltf_motion(ROBOT, clip="Running")[0], _with_loop("cartoon", "off")).motion.world_positions()
    assert np.abs(off[-1] - off[0]).max() > 0.2 * height  # what it was


@pytest.mark.skipif(not FOX.exists(), reason=f"the shared glTF fox is not at {FOX}")
def test_loop_on_takes_an_open_cycle_whose_last_frame_leads_into_its_first():
    """The fox's Run does not repeat its first key (auto leaves it a clip); ``on`` makes its last frame lead into
    its first by a step like its others."""
    from mocap_exaggerate.io.gltf_motion import read_gltf_motion

    fox = read_gltf_motion(FOX, clip="Run")[0]
    assert not any("loop" in note for note in run(fox, _with_loop("cartoon", "auto")).notes)
    on = _with_loop("cartoon", "on")
    assert "its last frame leading into its first" in run(fox, on).notes[0]
    # The same open cycle started on its frame 11 gives the same cycle, moved on by 11 frames.
    frames = fox.num_frames
    started = _frames(fox, np.r_[np.arange(11, frames), np.arange(11)])
    ours, moved = (run(clip, on).motion.world_positions() for clip in (fox, started))
    height = fox.skeleton.height()
    assert np.abs(np.roll(ours, -11, axis=0) - moved).max() < 1e-6 * height
    off = _with_loop("cartoon", "off")
    ours, moved = (run(clip, off).motion.world_positions() for clip in (fox, started))
    assert np.abs(np.roll(ours, -11, axis=0) - moved).max() > 0.05 * height


@pytest.mark.skipif(not ROBOT.exists(), reason=f"the shared glTF robot is not at {ROBOT}")
def test_a_loops_notes_and_reports_number_the_clips_own_frames():
    """The robot's Punch (a 21-key cycle) with --auto-stretch at looney: the strike in each of the cycles run
    is said once, in the clip's frames, as the manifest has it; the largest stretch is the clip's own."""
    from mocap_exaggerate.io.gltf_motion import read_gltf_motion

    punch = read_gltf_motion(ROBOT, clip="Punch")[0]
    config = _with_loop("looney", "auto")
    config = replace(config, auto_stretch=replace(config.auto_stretch, enabled=True))
    result = run(punch, config)
    said = [note for note in result.notes if note.startswith("auto-stretch: ")]
    events = result.stretch.events
    assert len(said) == len(events) >= 1
    for note, event in zip(said, events):
        assert f"frames {event.frames[0]}-{event.frames[1]} " in note
        assert 0 <= event.frames[0] <= event.frames[1] < punch.num_frames
    for key in result.constraints["stretch_keys"]:
        assert 0 <= key["frame"] < punch.num_frames
    assert result.stretch.trails
    for trail in result.stretch.trails:
        assert all(0 <= f < punch.num_frames for f in trail["frames"])
        assert len(trail["original"]) == len(trail["exaggerated"]) == len(trail["frames"])
    first, last = result.speed_report.seconds
    assert 0 <= first <= last <= punch.duration + 1e-9
    assert f"most from {first:.2f} to {last:.2f} s" in " ".join(result.notes)
    assert len(result.world_positions) == punch.num_frames


def test_frames_in_notes_move_onto_the_clip_or_go():
    from mocap_exaggerate.pipeline import _moved_message

    keep = slice(100, 130)
    assert _moved_message("auto-stretch: right_arm frames 105-112 to 2 limb lengths", keep, 30, 0.1) == \
        "auto-stretch: right_arm frames 5-12 to 2 limb lengths"
    assert _moved_message("stretch left_leg frames 90-104: squashed", keep, 30, 0.1) == "stretch left_leg frames 0-4: squashed"
    assert _moved_message("stretch left_leg at frame 140: the limb reaches 93%", keep, 30, 0.1) is None
    assert _moved_message("the strongest candidate, right_arm at frame 112 (11.20 s): reach 0.9", keep, 30, 0.1) == \
        "the strongest candidate, right_arm at frame 12 (1.20 s): reach 0.9"
    assert _moved_message("springs: link stiffness 5 is more than 8 substeps", keep, 30, 0.1) == \
        "springs: link stiffness 5 is more than 8 substeps"


def test_a_long_cycle_has_five_seconds_either_side_and_a_short_one_at_most_64_cycles():
    motion = load_bvh(SAMPLE_DIR / "cmu_16_01_jump_amc2bvh.bvh")
    rotations, positions = motion.forward_kinematics()
    loop = find_loop(motion, positions, rotations, "on")
    halo = int(np.ceil(5.0 * motion.fps))
    assert motion.num_frames > halo and loop.halo == halo and loop.length == motion.num_frames + 2 * halo
    assert find_loop(motion, positions, rotations, "on", reach=8.0).halo == int(np.ceil(8.0 * motion.fps))
    result = run(motion, _with_loop("cartoon", "on"))
    assert result.motion.num_frames == motion.num_frames
    three = _frames(motion, np.array([0, 1, 2])).replace(frame_time=1e-4)  # 3 frames at 10,000 fps
    rotations, positions = three.forward_kinematics()
    assert find_loop(three, positions, rotations, "on").length <= 2 * (64 + 1) * 3


def test_loop_on_refuses_a_rest_pose_and_the_halo_is_in_the_configs_frame_rate():
    motion = load_bvh(SAMPLE_DIR / "cmu_09_01_run_daz.bvh")  # its T-pose first
    with pytest.raises(ConfigError, match="input.loop = on: the clip starts in a rest pose"):
        run(motion, _with_loop("cartoon", "on"))
    loop = _there_and_back()  # 120 fps, run at 240: 5 s is 1,200 frames, 14 whole cycles of 89 and a part
    config = _with_loop("cartoon", "auto")
    result = run(loop, replace(config, input=replace(config.input, fps=240.0)))
    before = float(result.notes[0].split("run as the loop repeated, ")[1].split(" s before it")[0])
    assert 5.0 <= before < 5.0 + 2 * 89 / 240  # (whole cycles, from the calmest frame)


@pytest.mark.skipif(not ROBOT.exists(), reason=f"the shared glTF robot is not at {ROBOT}")
def test_info_says_which_clips_are_cycles():
    from mocap_exaggerate.jobs.job import describe

    assert describe(ROBOT, clip="Running")["loop"] == {"period": 23, "closed": True}
    assert describe(ROBOT, clip="Death")["loop"] is None  # it ends lying down
    assert describe(SAMPLE_DIR / "cmu_16_01_jump_amc2bvh.bvh")["loop"] is None
