"""A run killed at any moment: the folder holds a complete set or reads as incomplete, and the next run mends it."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

import pytest

from mocap_exaggerate.jobs.job import check_output_set

from .helpers import SAMPLE_DIR

NAMES = {"long.bvh", "long.glb", "long.weights.npz", "long.pipeline.toml", "long.json"}


def long_clip(folder, frames=3000):
    """A sample clip's motion lines repeated: long enough that writing takes a while."""
    data = (SAMPLE_DIR / "cmu_16_01_jump_amc2bvh.bvh").read_bytes()
    head, _, body = data.partition(b"MOTION")
    lines = [line for line in body.splitlines()[1:] if line.strip()]
    rows = lines[2:] * (frames // (len(lines) - 2) + 1)
    path = folder / "long.bvh"
    path.write_bytes(head + b"MOTION\nFrames: %d\n" % frames + lines[1] + b"\n" + b"\n".join(rows[:frames]) + b"\n")
    return path


def exaggerate(clip, out, omega):
    return [sys.executable, "-m", "mocap_exaggerate_cli.main", "-q", "exaggerate", str(clip), "-o", str(out),
            "--omega", str(omega), "--overwrite"]


@pytest.mark.parametrize("moment", [0.3, 0.6, 0.75, 0.85, 0.95])
def test_a_killed_run_leaves_a_complete_set_or_none_and_the_next_run_mends_it(tmp_path, moment):
    """Killed at a share of a whole run's time: reading, running, writing the files, renaming them."""
    clip = long_clip(tmp_path)
    out = tmp_path / "out"
    start = time.perf_counter()
    subprocess.run(exaggerate(clip, out, 2), check=True, timeout=120)
    whole = time.perf_counter() - start
    assert check_output_set(out / "long.json") == []

    process = subprocess.Popen(exaggerate(clip, out, 4), stderr=subprocess.DEVNULL)
    time.sleep(moment * whole)
    process.send_signal(signal.SIGKILL)
    process.wait(timeout=60)
    if (out / "long.json").exists():
        # A manifest only ever vouches for the files it describes: the old set or the new one, whole.
        assert check_output_set(out / "long.json") == []
        omega = json.loads((out / "long.json").read_text())["config"]["extrapolate"]["omega"]
        assert omega in (2.0, 4.0)
    # else: killed while the set was being replaced; it reads as incomplete (no manifest).

    subprocess.run(exaggerate(clip, out, 4), check=True, timeout=120)
    assert {p.name for p in out.iterdir()} == NAMES  # nothing else: no temporary left behind
    assert check_output_set(out / "long.json") == []
    assert json.loads((out / "long.json").read_text())["config"]["extrapolate"]["omega"] == 4.0
