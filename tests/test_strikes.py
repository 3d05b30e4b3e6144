"""Issue 25, part 1: strikes found by what they are (a limb unfolding to near full reach, away from the
body, not a step), held to the strikes labelled by hand in every shared clip (``tests/data/strikes.json``;
``bench/strikes.py`` prints the table)."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mocap_exaggerate import load_bvh
from mocap_exaggerate.analysis.limbs import find_limbs, limb_length, standing_up
from mocap_exaggerate.stages.stretch import AutoStretchConfig, find_strikes, nothing_found, weigh_strikes

from .helpers import ROOT, SAMPLE_DIR, SHARED_BVH, SHARED_REASON

LABELS = json.loads((Path(__file__).parent / "data" / "strikes.json").read_text())["clips"]


def _standing(frames: int = 120):
    """The sample sit-down clip's first pose (standing) held for ``frames`` frames, its limbs and axes."""
    motion = load_bvh(SAMPLE_DIR / "mocapbank_sit_down_stand_up.bvh")
    pose = np.repeat(motion.world_positions()[:1], frames, axis=0)
    limbs = find_limbs(motion.skeleton)
    axis, sign = standing_up(motion.skeleton, pose)
    up = np.zeros(3)
    up[axis] = sign
    across = pose[0, limbs["left_arm"].base] - pose[0, limbs["right_arm"].base]
    across -= (across @ up) * up
    forward = np.cross(up, across / np.linalg.norm(across))
    return motion, pose, limbs, up, forward


def _unfold(pose, skeleton, limb, direction, frames: range, bent: float = 0.45):
    """Move ``limb`` (in place) from ``bent`` of its reach to straight along ``direction`` over ``frames``,
    then hold it there: the elbow or knee off the line by what its bones leave."""
    full = limb_length(skeleton, limb)
    base, middle, end = limb.joints[0], limb.joints[1], limb.joints[-1]
    upper = np.linalg.norm(pose[0, middle] - pose[0, base])
    side = np.cross(direction, [0.0, 1.0, 0.0] if abs(direction[1]) < 0.9 else [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    share = np.clip((np.arange(len(pose)) - frames.start) / (frames.stop - frames.start), 0.0, 1.0)
    reach = (bent + (1.0 - bent) * (3 * share**2 - 2 * share**3)) * full * 0.999
    origin = pose[:, base]
    pose[:, end] = origin + reach[:, None] * direction
    along = reach * upper / full
    pose[:, middle] = origin + along[:, None] * direction + np.sqrt(np.maximum(upper**2 - along**2, 0))[:, None] * side


@pytest.mark.parametrize("seconds", [0.1, 0.5])
def test_a_punch_is_found_whatever_its_speed(seconds):
    motion, pose, limbs, up, forward = _standing()
    frames = int(round(seconds / motion.frame_time))
    _unfold(pose, motion.skeleton, limbs["right_arm"], forward, range(30, 30 + frames))
    (strike,) = find_strikes(pose, motion.skeleton, limbs, motion.frame_time, AutoStretchConfig(enabled=True))
    assert strike.limb == "right_arm" and abs(int(strike.end) - (30 + frames)) <= 2


def test_an_arm_pushed_down_at_the_side_is_weighed_and_left():
    motion, pose, limbs, up, forward = _standing()
    down = -up * 0.95 + forward * 0.3
    _unfold(pose, motion.skeleton, limbs["right_arm"], down / np.linalg.norm(down), range(30, 45))
    weighed = weigh_strikes(pose, motion.skeleton, limbs, motion.frame_time, AutoStretchConfig(enabled=True))
    assert not any(c.taken for c in weighed)
    (pushed,) = [c for c in weighed if c.limb == "right_arm"]
    assert "hanging" in pushed.why and "down line" in nothing_found(weighed, motion.frame_time)


def test_both_arms_flung_out_are_a_pose_and_both_reaching_up_are_two_strikes():
    motion, pose, limbs, up, forward = _standing()
    across = np.cross(forward, up)
    for limb, sign in (("left_arm", -1.0), ("right_arm", 1.0)):
        _unfold(pose, motion.skeleton, limbs[limb], sign * across, range(30, 45))
    config = AutoStretchConfig(enabled=True)
    assert find_strikes(pose, motion.skeleton, limbs, motion.frame_time, config) == []
    motion, pose, limbs, up, forward = _standing()
    for limb in ("left_arm", "right_arm"):
        _unfold(pose, motion.skeleton, limbs[limb], up, range(30, 45))
    assert sorted(s.limb for s in find_strikes(pose, motion.skeleton, limbs, motion.frame_time, config)) == [
        "left_arm", "right_arm"]


def test_nothing_found_says_so_even_without_candidates():
    motion, pose, limbs, _, _ = _standing(20)
    weighed = weigh_strikes(pose, motion.skeleton, limbs, motion.frame_time, AutoStretchConfig(enabled=True))
    assert "no strike found" in nothing_found([], motion.frame_time)
    assert all(not c.taken for c in weighed)


def _bench():
    spec = importlib.util.spec_from_file_location("strikes_bench", ROOT / "bench" / "strikes.py")
    sys.path.insert(0, str(ROOT / "bench"))
    try:
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(ROOT / "bench"))
    return module


def test_the_labels_cover_every_shared_clip():
    if not SHARED_BVH.is_dir():
        pytest.skip(SHARED_REASON)
    clips = {p.name for p in SHARED_BVH.glob("*.bvh")} | {p.name for p in (SHARED_BVH / "wide").glob("*.bvh")}
    assert clips == set(LABELS)
    for name, label in LABELS.items():
        for limb, frame, what in label["strikes"] + label["maybe"]:
            assert limb in ("left_arm", "right_arm", "left_leg", "right_leg") and frame >= 0 and what, name


def test_strikes_are_found_with_ninety_percent_precision_and_recall_over_the_labels():
    if not SHARED_BVH.is_dir():
        pytest.skip(SHARED_REASON)
    bench = _bench()
    config = AutoStretchConfig(enabled=True)
    hits = missed = extra = 0
    for name, label in LABELS.items():
        path = SHARED_BVH / name if (SHARED_BVH / name).exists() else SHARED_BVH / "wide" / name
        motion = load_bvh(path, fps=bench.FPS.get(name))
        limbs = find_limbs(motion.skeleton)
        weighed = weigh_strikes(motion.world_positions(), motion.skeleton, limbs, motion.frame_time, config)
        found = find_strikes(None, motion.skeleton, limbs, motion.frame_time, config, weighed)
        holds = {(c.limb, c.arrive): c.last for c in weighed}
        got = bench.match([(s.limb, int(s.end), holds[s.limb, int(s.end)]) for s in found], label["strikes"],
                          label["maybe"], motion.frame_time)
        hits, missed, extra = hits + len(got["hits"]), missed + len(got["missed"]), extra + len(got["extra"])
    precision, recall = hits / (hits + extra), hits / (hits + missed)
    assert precision >= 0.9 and recall >= 0.9, (precision, recall, missed, extra)


def test_verbose_says_what_was_found_or_the_strongest_candidate(tmp_path):
    run = subprocess.run(
        [sys.executable, "-m", "mocap_exaggerate_cli.main", "-v", "exaggerate", str(SAMPLE_DIR / "cmu_09_01_run_daz.bvh"),
         "-o", str(tmp_path), "--auto-stretch", "--no-glb"], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert "auto-stretch: no strike found; the strongest candidate, " in run.stderr
    assert "was not taken: " in run.stderr


def test_a_pipeline_file_from_before_still_reads_and_says_what_it_ignored(tmp_path):
    # Every pipeline file the speed-based finder wrote has these three keys.
    old = tmp_path / "walk.pipeline.toml"
    old.write_text('preset = "looney"\n[auto_stretch]\nenabled = true\nmin_rate = 3.0\nmin_speed = 8.0\n'
                   "min_extension = 0.3\nmin_reach = 0.85\n")
    run = subprocess.run(
        [sys.executable, "-m", "mocap_exaggerate_cli.main", "exaggerate", str(SAMPLE_DIR / "cmu_09_01_run_daz.bvh"),
         "-o", str(tmp_path / "out"), "--config", str(old), "--no-glb"], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    for key in ("min_rate", "min_speed", "min_extension"):
        assert run.stderr.count(f"auto_stretch.{key} is retired and ignored") == 1, run.stderr
    written = (tmp_path / "out" / "cmu_09_01_run_daz.pipeline.toml").read_text()
    assert "min_rate" not in written and "min_reach = 0.85" in written


def test_a_refused_pipeline_file_gets_one_line_even_with_retired_keys(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[auto_stretch]\nmin_rate = 3.0\nmin_angle = -5\n")
    run = subprocess.run(
        [sys.executable, "-m", "mocap_exaggerate_cli.main", "exaggerate", str(SAMPLE_DIR / "cmu_09_01_run_daz.bvh"),
         "-o", str(tmp_path / "out"), "--config", str(bad)], capture_output=True, text=True)
    assert run.returncode == 2 and run.stderr.count("\n") == 1, run.stderr
    assert "min_angle" in run.stderr and not (tmp_path / "out").exists()
