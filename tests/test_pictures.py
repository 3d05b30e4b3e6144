"""The pictures of previews and reports: which frames, which joint, which window, lined up with the output."""

from __future__ import annotations

import dataclasses

import numpy as np

from mocap_exaggerate import load_preset
from mocap_exaggerate.io.bvh import read_bvh
from mocap_exaggerate.pipeline import run
from mocap_exaggerate.viz.framing import fastest_end, telling_frames, telling_window
from mocap_exaggerate.viz.stills import render_preview, render_trajectory

from .helpers import SAMPLE_DIR

RUN = SAMPLE_DIR / "cmu_09_01_run_daz.bvh"  # 4 leading rest-pose frames


def exaggerate(path, tpose="auto", preset="looney"):
    motion, _ = read_bvh(path)
    config = load_preset(preset)
    config = dataclasses.replace(config, input=dataclasses.replace(config.input, tpose=tpose))
    return motion, run(motion, config), config


def test_the_fastest_end_of_a_run_is_a_foot_and_of_a_sit_a_hand():
    motion, _ = read_bvh(RUN)
    assert motion.skeleton.names[fastest_end(motion)] in ("lFoot", "rFoot")
    motion, _ = read_bvh(SAMPLE_DIR / "mocapbank_sit_down_stand_up.bvh")
    assert "Wrist" in motion.skeleton.names[fastest_end(motion)] or "Hand" in motion.skeleton.names[fastest_end(motion)]


def test_telling_frames_are_the_most_exaggerated_apart_and_past_the_rest_pose():
    motion, result, _ = exaggerate(RUN)
    frames = telling_frames(motion, result, 4)
    assert frames == sorted(frames) and len(frames) == 4
    assert min(frames) >= result.rest_frames and max(frames) < result.motion.num_frames
    assert min(np.diff(frames)) >= result.motion.num_frames // 8
    captured = motion.world_positions()
    moved = (result.world_positions[:, result.original_index] - result.world_positions[:, :1]) - \
            (captured - captured[:, :1])
    away = np.linalg.norm(moved, axis=-1).max(axis=1)
    assert int(np.argmax(away)) in frames  # the most exaggerated moment is drawn


def test_pictures_line_up_when_the_rest_pose_is_dropped():
    motion, result, config = exaggerate(RUN, tpose="drop")
    assert result.rest_frames == 4 and result.motion.num_frames == motion.num_frames - 4
    frames = telling_frames(motion, result, 4)
    assert max(frames) < result.motion.num_frames
    png = render_preview(motion, result, frames=5)  # evenly spaced up to the output's last frame
    assert png.startswith(b"\x89PNG")
    joint = fastest_end(motion, result.rest_frames)
    start, end = telling_window(motion, result, joint)
    assert 0 <= start < end <= result.motion.num_frames
    assert render_trajectory(motion, result, joint, config, frames=(start, end)).startswith(b"\x89PNG")


def test_the_window_of_a_long_clip_is_three_seconds_around_the_largest_move():
    motion, result, _ = exaggerate(SAMPLE_DIR / "mocapbank_sit_down_stand_up.bvh")
    joint = fastest_end(motion, result.rest_frames)
    start, end = telling_window(motion, result, joint, seconds=3.0)
    assert end - start == round(3.0 / motion.frame_time)
    away = np.linalg.norm(result.world_positions[:, result.original_index[joint]] - motion.world_positions()[:, joint],
                          axis=-1)
    assert start <= int(np.argmax(away[result.rest_frames:])) + result.rest_frames < end
    short = telling_window(motion, result, joint, seconds=1000.0)
    assert short == (result.rest_frames, result.motion.num_frames)  # a short clip is drawn whole


def test_pictures_are_the_same_bytes_every_time():
    motion, result, config = exaggerate(RUN)
    assert render_trajectory(motion, result, None, config) == render_trajectory(motion, result, None, config)
    assert render_preview(motion, result, at=[10, 50]) == render_preview(motion, result, at=[10, 50])


def test_previews_of_one_clip_at_different_settings_show_the_body_at_one_scale():
    # Issue 27: nine previews of a sweep came out 499-801 pixels tall, each body at its own scale.
    import io

    from PIL import Image

    from mocap_exaggerate.viz.animation import animation_frames, render_frames

    sit = SAMPLE_DIR / "mocapbank_sit_down_stand_up.bvh"
    stills, moving = [], []
    for preset in ("subtle", "looney"):
        motion, result, _ = exaggerate(sit, preset=preset)
        picture = np.asarray(Image.open(io.BytesIO(render_preview(motion, result, at=[60, 200, 330]))).convert("RGB"))
        stills.append(picture)
        moving.append(next(iter(render_frames(motion, result, animation_frames(motion, result)[0]))))
    # The stills fit in the room left around the captured body: the same size, the captured row the same pixels.
    assert stills[0].shape == stills[1].shape
    top = stills[0].shape[0] // 2
    np.testing.assert_array_equal(stills[0][:top], stills[1][:top])
    assert (stills[0][top:] != stills[1][top:]).any()  # and the exaggerated ones differ
    # Looney swings past that room in the animation: a wider picture, the captured body the same size in it.
    assert moving[0].shape[0] == moving[1].shape[0] and moving[0].shape[1] < moving[1].shape[1]
    areas = [int(((m[:, : m.shape[1] // 2] < 200).all(axis=-1)).sum()) for m in moving]
    assert areas[0] > 1000 and abs(areas[0] - areas[1]) <= 0.01 * areas[0], areas
