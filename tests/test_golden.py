"""Golden files: the whole pipeline's output on three shipped clips, so a change that moves a
number fails here, not in a user's render.

Each case runs `convert` as a user would (BVH, GLB, weights) and compares, against
``tests/golden/<clip>-<preset>.npz``: the joints of the written BVH read back (every 8th frame,
within 1e-6 of the body's height) and the re-weighted skin (joint indices exactly, weights within
1e-7), every 4th vertex. A deliberate change re-writes them::

    MOCAP_GOLDEN_WRITE=1 pytest tests/test_golden.py

and the diff of the ``.npz`` files goes in the commit that explains it. For a move that must not
change one byte, ``bench/golden.py`` compares every output file of every clip by hash.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

from mocap_exaggerate import convert
from mocap_exaggerate.config import resolve_config
from mocap_exaggerate.io.bvh import read_bvh

from .helpers import SAMPLE_DIR

GOLDEN = SAMPLE_DIR.parent / "tests" / "golden"
CASES = [(clip, preset) for clip in ("cmu_09_01_run_daz", "cmu_16_01_jump_amc2bvh", "mocapbank_sit_down_stand_up")
         for preset in ("cartoon", "looney")]


def _outputs(clip: str, preset: str, folder, config=None) -> dict[str, np.ndarray]:
    convert(SAMPLE_DIR / f"{clip}.bvh", folder, config, preset=preset)
    motion, _ = read_bvh(folder / f"{clip}.bvh")
    _, positions = motion.forward_kinematics()
    skin = np.load(folder / f"{clip}.weights.npz")
    return {
        "positions": positions[::8],
        "height": np.array(motion.skeleton.height()),
        "names": np.array(motion.skeleton.names),
        "joints": skin["joints"][::4].astype(np.int16),
        "weights": skin["weights"][::4],
    }


@pytest.mark.parametrize(("clip", "preset"), CASES, ids=[f"{c}-{p}" for c, p in CASES])
def test_the_pipelines_output_matches_its_golden_file(clip, preset, tmp_path):
    found = _outputs(clip, preset, tmp_path)
    path = GOLDEN / f"{clip}-{preset}.npz"
    if os.environ.get("MOCAP_GOLDEN_WRITE"):
        GOLDEN.mkdir(exist_ok=True)
        np.savez_compressed(path, **found)
        pytest.skip(f"wrote {path.name}")
    golden = np.load(path)
    assert list(found["names"]) == list(golden["names"])
    assert found["positions"].shape == golden["positions"].shape
    error = np.abs(found["positions"] - golden["positions"]).max() / float(golden["height"])
    assert error < 1e-6, f"joints moved by {error:.3g} of the height"
    assert np.array_equal(found["joints"], golden["joints"])
    assert np.abs(found["weights"] - golden["weights"]).max() < 1e-7


def test_a_changed_number_fails_the_golden_comparison(tmp_path):
    # The comparison can fail: omega 1 % off the cartoon preset's moves the joints past it.
    omega = resolve_config("cartoon").extrapolate.omega
    config = resolve_config("cartoon", overrides={"extrapolate": {"omega": omega * 1.01}})
    found = _outputs("cmu_09_01_run_daz", "cartoon", tmp_path, config)
    golden = np.load(GOLDEN / "cmu_09_01_run_daz-cartoon.npz")
    assert np.abs(found["positions"] - golden["positions"]).max() / float(golden["height"]) > 1e-5
