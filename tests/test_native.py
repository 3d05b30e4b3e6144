"""Whole jobs with the compiled loops and without them (``MOCAP_EXAGGERATE_NUMPY_ONLY``, as an install
without a C compiler runs): every output byte the same. The loops are checked one by one beside their
NumPy code in test_bvh, test_rotations, test_rubber_frames and test_springs; this is the end to end."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from mocap_exaggerate.core import native

from .helpers import SAMPLE_DIR

CLI = [sys.executable, "-m", "mocap_exaggerate_cli.main"]


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
