"""Animated previews (GIF, MP4), a view that covers everything drawn, and the preview command's
formats and --trajectory, as a user runs them."""

from __future__ import annotations

import io
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from mocap_exaggerate import load_preset
from mocap_exaggerate.core.errors import ConfigError
from mocap_exaggerate.io.bvh import read_bvh
from mocap_exaggerate.pipeline import run
from mocap_exaggerate.viz.animation import animation_frames, gif_durations, render_gif
from mocap_exaggerate.viz.framing import preview_window, view_limits
from mocap_exaggerate.viz.posing import pose_bodies
from mocap_exaggerate.viz.preview import write_preview
from mocap_exaggerate_cli.main import cli

from .helpers import SAMPLE_DIR, shared

RUN = SAMPLE_DIR / "cmu_09_01_run_daz.bvh"  # 120 fps, 149 frames, the first 4 a rest pose
JUMP = SAMPLE_DIR / "cmu_16_01_jump_amc2bvh.bvh"  # 30.0003 fps, 322 frames (10.7 s)


def exaggerate(path, preset="cartoon"):
    motion, _ = read_bvh(path)
    return motion, run(motion, load_preset(preset))


def command(*args, **kwargs):
    """``mocap-exaggerate ARGS`` in a new process (the installed module, as the console script runs it)."""
    return subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", *map(str, args)],
                          capture_output=True, text=True, timeout=300, **kwargs)


def gif_facts(data: bytes) -> tuple[int, int | None, list[int], list[bytes]]:
    """Frame count, loop count, each frame's milliseconds and pixels of a GIF."""
    with Image.open(io.BytesIO(data)) as image:
        assert image.format == "GIF"
        durations, pixels = [], []
        for k in range(image.n_frames):
            image.seek(k)
            durations.append(image.info["duration"])
            pixels.append(image.convert("RGB").tobytes())
        return image.n_frames, image.info.get("loop"), durations, pixels


def test_a_gif_of_the_run_loops_at_its_speed_and_is_the_same_bytes_every_time(tmp_path):
    target = tmp_path / "run.gif"
    done = command("preview", RUN, "-o", target)
    assert done.returncode == 0, done.stderr
    data = target.read_bytes()
    frames, loop, durations, pixels = gif_facts(data)
    # 145 frames of motion past the rest pose at 120 fps: every 6th, shown 50 ms each (20 fps).
    assert frames == len(range(4, 149, 6)) == 25 and loop == 0
    assert durations == [50] * 25 and sum(durations) == round(25 * 6 / 120 * 1000)
    assert len(set(pixels)) == frames  # every frame is a new picture: it moves
    motion, result = exaggerate(RUN)
    assert render_gif(motion, result) == data  # another process, the same bytes


def test_a_30_fps_clip_plays_every_second_frame_and_keeps_the_clips_time():
    motion, result = exaggerate(JUMP)
    shown, frame_seconds = animation_frames(motion, result, seconds=2.0)
    assert np.array_equal(shown, np.arange(0, 60, 2)) and frame_seconds == pytest.approx(2 / 30.0003)
    frames, loop, durations, _ = gif_facts(render_gif(motion, result, seconds=2.0))
    assert frames == 30 and loop == 0
    assert set(durations) == {60, 70} and sum(durations) == 2000  # 15 fps in centiseconds, no drift


def test_the_frame_times_of_a_gif_add_up_to_the_clips_time():
    assert gif_durations(3, 1 / 15) == [70, 60, 70]
    assert sum(gif_durations(150, 2 / 30.0003)) == 10_000
    assert gif_durations(4, 0.05) == [50] * 4


def test_an_animation_of_a_long_clip_stops_at_ten_seconds_unless_told():
    motion, result = exaggerate(JUMP)  # 10.7 s
    shown, _ = animation_frames(motion, result)
    assert shown[0] == 0 and shown[-1] < round(10 / motion.frame_time) <= shown[-1] + 2
    shown, _ = animation_frames(motion, result, seconds=20)
    assert shown[-1] >= motion.num_frames - 2
    shown, _ = animation_frames(motion, result, start=4.0, seconds=1.0)
    assert np.array_equal(shown, np.arange(120, 150, 2))
    with pytest.raises(ConfigError, match="past the end"):
        animation_frames(motion, result, start=11.0)


def test_the_window_starts_past_the_rest_pose():
    motion, result = exaggerate(RUN)
    assert preview_window(motion, result) == (4, 149)
    assert preview_window(motion, result, start=0.5, seconds=0.25) == (64, 94)


def test_view_limits_cover_the_points_at_one_scale_with_a_margin():
    points = np.array([[[0.0, 0.0], [0.0, 2.0]], [[10.0, 0.0], [11.0, 3.0]]])
    half, low, high = view_limits(points, np.array([0.0, 10.0]), margin=0.1)
    assert (half, low, high) == pytest.approx((1.3, -0.3, 3.3))  # a tenth of the larger extent (3) each side
    half, _, _ = view_limits(points[:1], np.array([0.0]), margin=0.0, min_aspect=0.5)
    assert half == pytest.approx(0.5)  # a stick is shown at least half as wide as tall
    half, low, high = view_limits(np.array([[[-6.0, 0.0], [6.0, 1.0]]]), np.array([0.0]), margin=0.0, max_aspect=3.0)
    assert (half, low, high) == pytest.approx((6.0, -1.5, 2.5))  # and at most 3 times as wide
    with pytest.raises(ValueError, match=r"points must be \(F, N, 2\)"):
        view_limits(points[..., :1], np.array([0.0, 10.0]))


def covers(points: np.ndarray, centre: np.ndarray, limits: tuple[float, float, float]) -> bool:
    half, low, high = limits
    across = points[..., 0] - centre[:, None]
    return bool(np.all(np.abs(across) <= half) and np.all(points[..., 1] >= low) and np.all(points[..., 1] <= high))


def test_the_view_of_a_looney_run_covers_every_vertex_of_both_bodies():
    motion, result = exaggerate(RUN, "looney")
    bodies = pose_bodies(motion, result, np.arange(result.motion.num_frames))
    right, up, _ = bodies.axes
    points = bodies.screen_points()
    assert points.shape[1] == len(bodies.captured[0]) + len(bodies.exaggerated[0]) + 1
    centre = bodies.root[:, right]  # as the still frames centre each column
    height = motion.skeleton.height()
    # The fixed view the previews had (0.75 heights each side of the root) cut the looney stride off.
    assert np.abs(points[..., 0] - centre[:, None]).max() > 0.75 * height
    limits = view_limits(points, centre)
    assert covers(points, centre, limits)
    half, low, high = limits
    inside = min(half - np.abs(points[..., 0] - centre[:, None]).max(), points[..., 1].min() - low,
                 high - points[..., 1].max())
    assert inside > 0.03 * height  # with a margin, not touching the edge


def test_the_view_of_a_looney_cartwheel_is_not_cut_off_at_the_top():
    motion, result = exaggerate(shared("cmu_05_06_dance_cartwheel_start_iclone.bvh"), "looney")
    bodies = pose_bodies(motion, result, np.arange(result.motion.num_frames))
    right, up, _ = bodies.axes
    points, centre = bodies.screen_points(), bodies.root[:, right]
    lowest = min(motion.world_positions()[..., up].min(), result.world_positions[..., up].min())
    assert points[..., 1].max() > lowest + 1.45 * motion.skeleton.height()  # above the old fixed view
    assert covers(points, centre, view_limits(points, centre))


def test_trajectory_of_a_joint_is_a_png_and_an_unknown_joint_is_refused(tmp_path):
    target = tmp_path / "foot.png"
    done = command("preview", RUN, "-o", target, "--trajectory", "lFoot", "--preset", "looney")
    assert done.returncode == 0, done.stderr
    assert target.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and target.stat().st_size > 10_000
    missing = tmp_path / "nose.png"
    refused = command("preview", RUN, "-o", missing, "--trajectory", "LeftFoot")
    assert refused.returncode == 2 and not missing.exists()
    assert len(refused.stderr.strip().splitlines()) == 1 and "no joint named 'LeftFoot'" in refused.stderr
    assert "lFoot" in refused.stderr  # the close names


def test_formats_it_cannot_write_are_refused_before_any_work(tmp_path):
    done = command("preview", RUN, "-o", tmp_path / "run.jpg")
    assert done.returncode == 2 and not (tmp_path / "run.jpg").exists()
    assert len(done.stderr.strip().splitlines()) == 1
    assert "cannot write .jpg" in done.stderr and all(s in done.stderr for s in (".png", ".gif", ".mp4"))
    runner = CliRunner()
    for name, words in [("run.jpeg", "cannot write .jpeg"), ("run.webp", "cannot write .webp"), ("run", "no suffix"),
                        ("run.GIF.txt", "cannot write .txt")]:
        result = runner.invoke(cli, ["preview", str(RUN), "-o", str(tmp_path / name)])
        assert result.exit_code == 2 and words in result.stderr, result.stderr
        assert not (tmp_path / name).exists()
    result = runner.invoke(cli, ["preview", str(RUN), "-o", str(tmp_path / "foot.gif"), "--trajectory", "lFoot"])
    assert result.exit_code == 2 and "name the file .png" in result.stderr and not (tmp_path / "foot.gif").exists()


def test_mp4_without_ffmpeg_is_a_one_line_refusal(tmp_path, monkeypatch):
    empty = tmp_path / "bin"
    empty.mkdir()
    done = command("preview", RUN, "-o", tmp_path / "run.mp4", env={**os.environ, "PATH": str(empty)})
    assert done.returncode == 2 and not (tmp_path / "run.mp4").exists()
    assert len(done.stderr.strip().splitlines()) == 1 and "ffmpeg" in done.stderr and ".gif" in done.stderr
    monkeypatch.setenv("PATH", str(empty))
    with pytest.raises(ConfigError, match="needs ffmpeg"):
        write_preview(tmp_path / "not-even-read.bvh", tmp_path / "run.mp4")  # refused before the clip is read


def test_a_failing_ffmpeg_is_reported_with_its_own_words_and_nothing_is_written(tmp_path, monkeypatch):
    fake = tmp_path / "bin" / "ffmpeg"
    fake.parent.mkdir()
    fake.write_text("#!/bin/sh\necho \"Unknown encoder 'libx264'\" >&2\nexit 1\n")
    fake.chmod(0o755)
    monkeypatch.setenv("PATH", str(fake.parent))
    with pytest.raises(OSError, match="Unknown encoder 'libx264'"):
        write_preview(RUN, tmp_path / "run.mp4", seconds=0.2)
    assert not (tmp_path / "run.mp4").exists()


@pytest.mark.skipif(shutil.which("ffmpeg") is None,
                    reason="ffmpeg is not on PATH: the MP4 branch runs where it is (the refusal is tested above)")
def test_an_mp4_holds_the_frames_of_the_animation(tmp_path):
    target = write_preview(RUN, tmp_path / "run.mp4", seconds=0.5)
    data = target.read_bytes()
    assert data[4:8] == b"ftyp"
    decoded = subprocess.run([shutil.which("ffmpeg"), "-hide_banner", "-i", str(target), "-map", "0:v", "-f", "null", "-"],
                             stderr=subprocess.PIPE, text=True, timeout=60)
    counted = [line for line in decoded.stderr.replace("\r", "\n").splitlines() if line.startswith("frame=")]
    assert decoded.returncode == 0 and int(counted[-1].split("=")[1].split()[0]) == len(range(4, 64, 6))


@pytest.mark.parametrize("window, said", [(("--start", "inf"), "past the end"), (("--start", "1.3"), "past the end"),
                                          (("--seconds", "nan"), "seconds must be")])
def test_a_window_outside_the_motion_is_one_line_and_nothing_written(window, said, tmp_path):
    """As users run it: an infinite start once overflowed into a traceback."""
    target = tmp_path / "run.gif"
    done = command("preview", RUN, "-o", target, *window)
    assert done.returncode == 2 and said in done.stderr and len(done.stderr.strip().splitlines()) == 1
    assert "Traceback" not in done.stderr and not target.exists()


def test_an_infinite_length_shows_the_rest_of_the_motion():
    motion, result = exaggerate(RUN)
    assert preview_window(motion, result, start=0.5, seconds=float("inf")) == preview_window(motion, result, start=0.5)
