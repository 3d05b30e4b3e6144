"""Whole jobs with the compiled loops and without them (``MOCAP_EXAGGERATE_NUMPY_ONLY``, as an install
without a C compiler runs): every output byte the same. The loops are checked one by one beside their
NumPy code in test_bvh, test_rotations, test_rubber_frames and test_springs; this is the end to end."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading

import numpy as np
import pytest

from mocap_exaggerate.core import native

from .helpers import SAMPLE_DIR

CLI = [sys.executable, "-m", "mocap_exaggerate_cli.main"]


def _halves_in_a_child() -> list[int]:
    seen = [0] * 10

    def mark(part: slice) -> None:
        for k in range(part.start, part.stop):
            seen[k] += 1

    native.on_both_cores(mark, [slice(0, 5), slice(5, 10)])
    return seen


def _outputs(folder) -> dict[str, bytes]:
    found = {}
    for path in sorted(folder.iterdir()):
        data = path.read_bytes()
        if path.suffix == ".json":  # the manifest: its timings are the run's own
            manifest = json.loads(data)
            manifest.pop("timings")
            data = json.dumps(manifest, sort_keys=True).encode()
        found[path.name] = data
    return found


@pytest.mark.parametrize("preset", ["cartoon", "looney"])
def test_the_numpy_code_writes_the_compiled_codes_bytes(tmp_path, preset):
    if native.kernels is None:
        pytest.skip("the compiled loops were not built (or MOCAP_EXAGGERATE_NUMPY_ONLY is set): nothing to compare")
    clips = sorted(SAMPLE_DIR.glob("*.bvh"))
    runs = {}
    for name, only in (("compiled", "0"), ("numpy", "1")):
        out = tmp_path / name
        env = {**os.environ, native.NUMPY_ONLY: only}
        done = subprocess.run([*CLI, "batch", str(SAMPLE_DIR), str(out), "--preset", preset, "-j", "1"],
                              env=env, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr
        runs[name] = _outputs(out)
    assert runs["compiled"].keys() == runs["numpy"].keys() and len(runs["compiled"]) >= 5 * len(clips)
    differ = [name for name in runs["compiled"] if runs["compiled"][name] != runs["numpy"][name]]
    assert not differ


def test_the_variable_turns_every_compiled_loop_off():
    code = ("from mocap_exaggerate.core import kinematics, rotations; from mocap_exaggerate.io import bvh; "
            "from mocap_exaggerate.stages import orient, springs; "
            "print([m is None for m in (kinematics._kernels, rotations._kernels, bvh._compiled, orient._kernels, "
            "springs._kernels)])")
    for value, expected in (("1", "[True, True, True, True, True]"), ("yes", "[True, True, True, True, True]")):
        done = subprocess.run([sys.executable, "-c", code], env={**os.environ, native.NUMPY_ONLY: value},
                              capture_output=True, text=True, timeout=120)
        assert done.stdout.strip() == expected, done.stderr


def test_a_long_clip_shared_between_two_cores_is_the_same_bits(tmp_path, monkeypatch):
    """From `native.SHARE_FROM` frames on, the compiled loops, the Gaussian's FFTs and the per-frame NumPy work
    (`native.by_frame_halves`) run in two halves on two threads: every output byte as in one piece (each
    frame, each series, is made on its own). The shipped and shared clips are all shorter, so one is tiled
    to 5,000 frames."""
    from mocap_exaggerate import convert

    data = (SAMPLE_DIR / "cmu_09_01_run_daz.bvh").read_bytes()
    head, _, rest = data.partition(b"MOTION")
    lines = rest.strip().split(b"\n")
    frame_time, motion = lines[1], lines[2:]
    tiled = (head + b"MOTION\nFrames: 5000\n" + frame_time + b"\n"
             + b"\n".join((motion * (5000 // len(motion) + 1))[:5000]) + b"\n")
    clip = tmp_path / "long.bvh"
    clip.write_bytes(tiled)
    made = {}
    for name, share in (("halves", 4096), ("whole", 10**12)):
        monkeypatch.setattr(native, "SHARE_FROM", share)
        assert len(native.frame_halves(5000)) == (2 if share == 4096 else 1) or (os.cpu_count() or 1) < 2
        convert(clip, tmp_path / name, preset="looney")
        made[name] = _outputs(tmp_path / name)
        made[name].pop("long.json")  # (its timings aside, the manifest is the same; the others are compared whole)
    assert made["halves"] == made["whole"]


def test_work_on_both_cores_waits_for_both_and_raises_what_either_raised():
    import numpy as np

    seen = np.zeros(10, int)
    native.on_both_cores(lambda part: seen.__setitem__(part, seen[part] + 1), [slice(0, 5), slice(5, 10)])
    assert seen.tolist() == [1] * 10

    def fail_first(part):
        if part.start == 0:
            raise ValueError("the helper's half")
        seen[part] += 1

    with pytest.raises(ValueError, match="helper's half"):
        native.on_both_cores(fail_first, [slice(0, 5), slice(5, 10)])
    assert seen[5:].tolist() == [2] * 5  # the other half was done, and waited for
    assert native.frame_halves(100) == [slice(0, 100)] and native.frame_halves(1, per_item=10**6) == [slice(0, 1)]


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no fork here")
def test_a_process_forked_after_the_helper_started_makes_its_own():
    """A child made by fork has no copy of the parent's helper thread: its executor, copied, would queue the
    work and never run it (a hang). The child starts its own."""
    import multiprocessing

    native.on_both_cores(lambda part: None, [slice(0, 1), slice(1, 2)])  # the parent's helper is up
    assert native._helper is not None
    context = multiprocessing.get_context("fork")
    with context.Pool(1) as pool:
        assert pool.apply_async(_halves_in_a_child).get(timeout=60) == [1] * 10


def test_work_shared_again_inside_a_shared_part_runs_whole(monkeypatch):
    """A part of `on_both_cores` that asks to share its own work runs it whole (the one helper thread is busy
    with the other part: waiting for it would never end), and `by_frame_halves` puts the halves back in order."""
    if (os.cpu_count() or 1) < 2:
        pytest.skip("one core: nothing is shared")
    monkeypatch.setattr(native, "SHARE_FROM", 2)
    inner = []
    native.on_both_cores(lambda part: inner.append(native.frame_halves(100)), native.frame_halves(100))
    assert inner == [[slice(0, 100)], [slice(0, 100)]]
    assert native.frame_halves(100) == [slice(0, 50), slice(50, 100)]  # (and outside, shared again)
    threads = set()

    def make(part):
        threads.add(threading.get_ident())
        return np.arange(100)[part] * 2

    assert native.by_frame_halves(make, 100).tolist() == list(range(0, 200, 2))
    assert len(threads) == 2
    # Two parts asked for inside a part run there, one after the other (not waiting on the busy helper), and
    # the rest of the outer part still runs whole.
    after = []

    def outer(part):
        native.on_both_cores(lambda inner_part: None, [slice(0, 1), slice(1, 2)])
        after.append(native.frame_halves(100))

    native.on_both_cores(outer, native.frame_halves(100))
    assert after == [[slice(0, 100)], [slice(0, 100)]]


_CHANGED_UNDER = r"""
import sys, threading
import numpy as np
from mocap_exaggerate.core.native import kernels
from mocap_exaggerate.io import bvh

if kernels is None or bvh._compiled is None:
    print("not built"); sys.exit(0)
rows = 200_000
table = np.zeros((rows, 3))
picks = np.array([0, 1, 2], dtype=np.int64)
pos, links = np.zeros((rows, 4, 3)), np.zeros((rows, 3, 3))
parents = np.array([-1, 0, 1, 2], dtype=np.int64)
follow, out = np.zeros((50_000, 3, 3)), np.zeros((50_000, 3, 3))
ends = np.array([0, 1], dtype=np.int64)
was, turned = np.ones((rows, 4, 3)), np.zeros((rows, 4, 4))
stop = False

def flip():  # the index arrays changed again and again while the loops run with the GIL let go
    while not stop:
        picks[0] = parents[3] = ends[1] = 1 << 40
        picks[0], parents[3], ends[1] = 0, 2, 1

thread = threading.Thread(target=flip)
thread.start()
try:
    for _ in range(40):
        for call in (lambda: bvh._compiled.format_columns(table, table, picks, rows, 3, 3, 6),
                     lambda: kernels.chain_add(pos, parents, links, rows, 4),
                     lambda: kernels.springs(follow, out, ends, ends[::-1].copy(), 50_000, 3, 2, 0.01, 1, 100.0,
                                             10.0, 1.0),
                     lambda: kernels.single_turns(was, was, turned, turned, ends, ends, ends, rows, 4, 2),
                     lambda: kernels.rigid_branches(turned, was, turned, was, parents[1:3].copy() + 1, ends, rows, 4,
                                                    2)):
            try:
                call()
            except ValueError:
                pass
finally:
    stop = True
    thread.join()
print("survived")
"""


def test_index_arrays_changed_by_another_thread_never_send_a_loop_out_of_bounds():
    """The compiled loops read their index arrays (the formatter's picks, parents, the springs' links) with the
    GIL let go: each is copied before it is checked, so another thread writing the caller's array meanwhile
    cannot make a loop read or write outside its arrays (a review's reproduction was a segfault). Run in a
    process of its own: a crash fails the test instead of ending the run."""
    done = subprocess.run([sys.executable, "-c", _CHANGED_UNDER], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, f"exit {done.returncode}: {done.stderr[-2000:]}"
    assert done.stdout.strip() in ("survived", "not built")


def test_joints_turned_by_one_link_are_numpys_bits_and_bad_joints_are_refused():
    """`single_turns` (orientation recovery's joints turned by a single link) against the NumPy expression it
    replaces, byte for byte, with a link of no length and one turned to face the other way among them."""
    from mocap_exaggerate.core.rotations import quat_between, quat_mul, quat_normalize

    if native.kernels is None:
        pytest.skip("the compiled loops were not built (or MOCAP_EXAGGERATE_NUMPY_ONLY is set)")
    frames, joints = 500, 9
    rng = np.random.default_rng(12)
    was, now = rng.normal(size=(frames, joints, 3)), rng.normal(size=(frames, joints, 3))
    turned = quat_normalize(rng.normal(size=(frames, joints, 4)))
    start, end, joint = np.array([0, 1, 2, 4, 6]), np.array([1, 2, 3, 5, 8]), np.array([0, 1, 2, 4, 6])
    was[3, 2] = was[3, 1]  # no length: the identity turn
    now[4, 1] = now[4, 0] - 2.0 * (was[4, 1] - was[4, 0])  # opposite: a half turn
    expected = np.zeros((frames, joints, 4))
    turn = quat_between(was[:, end] - was[:, start], now[:, end] - now[:, start])
    expected[:, joint] = quat_normalize(quat_mul(turn, turned[:, joint]))
    got = np.zeros((frames, joints, 4))
    native.kernels.single_turns(was, now, turned, got, start, end, joint, frames, joints, len(joint))
    assert got.tobytes() == expected.tobytes()
    for bad in (np.array([0, 1, 2, 4, joints]), np.array([0, 1, -1, 4, 6])):
        with pytest.raises(ValueError, match="out of range"):
            native.kernels.single_turns(was, now, turned, got, start, bad, joint, frames, joints, len(joint))
    with pytest.raises(ValueError):  # an array of the wrong size
        native.kernels.single_turns(was[:-1], now, turned, got, start, end, joint, frames, joints, len(joint))


def test_rigid_branches_are_numpys_bits_and_bad_joints_are_refused():
    """`rigid_branches` (a rigid branch placed under its recovered parent by its captured local transforms)
    against the NumPy loop it replaces, byte for byte, a rider on a rider among them."""
    from mocap_exaggerate.core.rotations import quat_mul, quat_normalize, quat_rotate

    if native.kernels is None:
        pytest.skip("the compiled loops were not built (or MOCAP_EXAGGERATE_NUMPY_ONLY is set)")
    frames, joints = 400, 8
    rng = np.random.default_rng(13)
    world = quat_normalize(rng.normal(size=(frames, joints, 4)))
    positions = rng.normal(size=(frames, joints, 3))
    local_rot, local_pos = quat_normalize(rng.normal(size=(frames, joints, 4))), rng.normal(size=(frames, joints, 3))
    placed, parents = np.array([2, 3, 6, 7]), np.array([1, 2, 0, 6])  # 3 rides on 2, 7 on 6
    expected_world, expected_positions = world.copy(), positions.copy()
    for j, p in zip(placed, parents):
        expected_world[:, j] = quat_mul(expected_world[:, p], local_rot[:, j])
        expected_positions[:, j] = expected_positions[:, p] + quat_rotate(expected_world[:, p], local_pos[:, j])
    native.kernels.rigid_branches(world, positions, local_rot, local_pos, placed, parents, frames, joints, len(placed))
    assert world.tobytes() == expected_world.tobytes() and positions.tobytes() == expected_positions.tobytes()
    for bad_placed, bad_parents in ((np.array([2, 3, 6, joints]), parents), (placed, np.array([1, 3, 0, 6])),
                                    (np.array([0, 3, 6, 7]), np.array([-1, 2, 0, 6]))):
        with pytest.raises(ValueError, match="out of range or after its parent"):
            native.kernels.rigid_branches(world, positions, local_rot, local_pos, bad_placed, bad_parents, frames,
                                          joints, len(placed))


def test_consecutive_indices_are_a_slice_only_where_they_mean_one():
    from mocap_exaggerate.core.kinematics import consecutive

    assert consecutive(np.array([3, 4, 5]), 10) == slice(3, 6)
    for odd in ([-3, -2, -1], [-1, 0], [8, 9, 10, 11], [3, 5, 6], [4, 3], []):
        assert isinstance(consecutive(np.array(odd, dtype=np.int64), 10), np.ndarray)
    assert isinstance(consecutive(np.array([True, False]), 10), np.ndarray)  # a mask stays a mask
    values = np.arange(10.0)
    for picked in ([2, 3, 4], [-2, -1], [7, 8, 9]):
        assert np.array_equal(values[consecutive(np.array(picked), 10)], values[picked])
