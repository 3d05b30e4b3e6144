"""BVH that every reader reads the same (issue 23, point 4).

Every shared clip (and MakeHuman's six-channel T-pose, and iClone clips of the wide set),
exaggerated on both output skeletons, is written by the library and read back by bvhio, by
Blender (one launch imports every file) and by our own reader: each puts every joint where
the library's result says (`PipelineResult.world_positions`), within 1e-4 of the skeleton's
height. iClone and MakeHuman files add their position channels to the OFFSETs; the writer
writes the standard convention (channels replace the OFFSET) unless asked for the input's
own (``positions="input"``, ``--bvh-positions input``), which our reader reads back as adding.

Each clip is cut to its first `FRAMES` frames (iClone's leading rest pose included) so the
whole module stays a few seconds (plus one Blender launch).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import NamedTuple

import bvhio
import numpy as np
import pytest

from mocap_exaggerate.config import resolve_config
from mocap_exaggerate.core.errors import ConfigError
from mocap_exaggerate.io.bvh import format_bvh, read_bvh, save_bvh
from mocap_exaggerate.pipeline import PipelineResult, run

from .helpers import SHARED_BVH, SHARED_CLIPS, SHARED_REASON, shared
from .test_blender import BPY, needs_blender

FRAMES = 40
SKELETONS = ("sub", "original")
#: MakeHuman's T-pose: six channels on nearly every joint, position channels added to the OFFSETs.
MAKEHUMAN_TPOSE = SHARED_BVH.parent / "skin" / "makehuman_default_tpose.bvh"
#: iClone clips of the wide set: three read as adding, one (a climb, feet off the floor) that auto reads as replacing.
WIDE_ICLONE = ["cmu_01_08_playground_climb_iclone.bvh", "cmu_02_06_bend_scoop_lift_arm_iclone.bvh",
               "cmu_03_01_walk_uneven_iclone.bvh", "cmu_07_04_slow_walk_iclone.bvh"]
CLIPS = SHARED_CLIPS + [path for path in [MAKEHUMAN_TPOSE, *(SHARED_BVH / "wide" / name for name in WIDE_ICLONE)]
                        if path.exists()]
ICLONE = "cmu_06_15_basketball_dribble_shoot_iclone.bvh"
BLENDER_SCRIPT = Path(__file__).parent / "blender" / "read_bvhs.py"


def case_params():
    """Every clip on both output skeletons, or one skipped case that says why."""
    if not CLIPS:
        return [pytest.param(None, None, marks=pytest.mark.skip(reason=SHARED_REASON), id="no-shared-data")]
    return [pytest.param(path, skeleton, id=f"{path.stem}-{skeleton}") for path in CLIPS for skeleton in SKELETONS]


class Written(NamedTuple):
    path: Path  # the BVH the library wrote (default: standard convention)
    result: PipelineResult
    height: float
    root_offset: str  # how the input was read: replace or add


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """``written(clip, skeleton)``: the clip's first frames exaggerated (cartoon) and written, once per module."""
    folder = tmp_path_factory.mktemp("readers")
    cache: dict[tuple[Path, str], Written] = {}

    def get(path: Path, skeleton: str) -> Written:
        if (path, skeleton) not in cache:
            motion, report = read_bvh(path)
            motion = motion.slice(slice(0, FRAMES))
            result = run(motion, resolve_config("cartoon", None, {"output": {"skeleton": skeleton}}))
            target = folder / f"{path.stem}.{skeleton}.bvh"
            save_bvh(result.motion, target)
            cache[path, skeleton] = Written(target, result, motion.skeleton.height(), report.root_offset)
        return cache[path, skeleton]

    return get


def worst(theirs: np.ndarray, case: Written) -> float:
    """Largest distance along any axis from the library's joints, in heights."""
    return float(np.max(np.abs(theirs - case.result.world_positions))) / case.height


@pytest.mark.parametrize("path, skeleton", case_params())
def test_bvhio_reads_every_joint_where_the_library_put_it(path, skeleton, written):
    case = written(path, skeleton)
    root = bvhio.readAsHierarchy(str(case.path))
    layout = root.layout()
    assert [joint.Name for joint, _, _ in layout] == list(case.result.motion.skeleton.names)
    theirs = []
    for frame in range(case.result.motion.num_frames):
        root.loadPose(frame)
        theirs.append([list(joint.PositionWorld) for joint, _, _ in layout])
    assert worst(np.array(theirs), case) < 1e-4


@pytest.mark.parametrize("path, skeleton", case_params())
def test_our_reader_reads_the_standard_file_as_the_same_motion(path, skeleton, written):
    """The default output read back (root_offset auto): the standard convention, the same joints."""
    case = written(path, skeleton)
    again, report = read_bvh(case.path)
    assert report.root_offset == "replace" and again.skeleton.positions == "replace"
    assert worst(again.world_positions(), case) < 1e-5


@pytest.fixture(scope="module")
def blender_seen(written, tmp_path_factory):
    """What Blender reads from every written file: one Blender launch for them all."""
    cases = [written(path, skeleton) for path in CLIPS for skeleton in SKELETONS]
    folder = tmp_path_factory.mktemp("blender")
    jobs = [{"path": str(case.path), "frames": list(range(case.result.motion.num_frames))} for case in cases]
    (folder / "jobs.json").write_text(json.dumps(jobs))
    done = subprocess.run([BPY, str(BLENDER_SCRIPT), str(folder / "jobs.json"), str(folder / "seen.json")],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads((folder / "seen.json").read_text())


@needs_blender
@pytest.mark.parametrize("path, skeleton", case_params())
def test_blender_reads_every_joint_where_the_library_put_it(path, skeleton, written, blender_seen):
    """Blender's importer puts a joint with position channels at its parent plus the parent's rotation
    of the channels (it keys ``channels - OFFSET`` as the bone's location, relative to its rest head):
    the standard convention, whatever the OFFSETs."""
    case = written(path, skeleton)
    seen = blender_seen[str(case.path)]
    names = case.result.motion.skeleton.names
    assert seen["bones"] == len(names)
    theirs = np.array([[seen["positions"][str(f)][name] for name in names] for f in range(case.result.motion.num_frames)])
    assert worst(theirs, case) < 1e-4  # Blender computes in float32


# ---------------------------------------------------------------------------- the input's own convention


def test_input_convention_writes_an_iclone_clip_back_as_iclone_wrote_it(written):
    """``positions="input"``: the channels go back out added to the OFFSETs (iClone's convention: the
    root's channels stay near zero, every joint's a displacement); our reader (auto) reads that file
    as adding, and it is the same motion as the library's and as the standard file's."""
    path = shared(ICLONE)
    for skeleton in SKELETONS:
        case = written(path, skeleton)
        assert case.root_offset == "add"
        skeleton_out = case.result.motion.skeleton
        data = format_bvh(case.result.motion, positions="input")
        assert data != case.path.read_bytes()
        again, report = read_bvh(data)
        assert report.root_offset == "add" and again.skeleton.positions == "add"
        assert worst(again.world_positions(), case) < 1e-5
        standard, _ = read_bvh(case.path)
        assert np.abs(again.world_positions() - standard.world_positions()).max() < 1e-5 * case.height

        # The root's first channels: near zero added, the hips' height (the OFFSET) standard.
        def first(text):
            return np.array(text.split(b"Frame Time:")[1].splitlines()[1].split()[:3], float)

        assert np.allclose(first(case.path.read_bytes()) - first(data), skeleton_out.offsets[0], atol=2e-6)
        # The same file written again in its own convention: the same bytes.
        assert format_bvh(again, positions="input") == data


def test_input_convention_changes_nothing_for_a_standard_clip(written):
    case = written(shared("cmu_09_01_run_daz.bvh"), "sub")
    assert case.root_offset == "replace"
    assert format_bvh(case.result.motion, positions="input") == case.path.read_bytes()


def test_a_bad_convention_is_refused_before_anything_is_written(written, tmp_path):
    case = written(shared(ICLONE), "original")
    for bad in ("add", "Standard", None, 1, "x" * 1000):
        with pytest.raises(ConfigError, match="bvh positions must be one of standard, input") as error:
            save_bvh(case.result.motion, tmp_path / "out.bvh", positions=bad)
        assert len(str(error.value)) < 200
    with pytest.raises(ConfigError, match="output.bvh_positions must be one of standard, input"):
        resolve_config("cartoon", None, {"output": {"bvh_positions": "add"}})
    assert not (tmp_path / "out.bvh").exists()


# ---------------------------------------------------------------------------- as users run it


def cli(*args):
    return subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", *map(str, args)],
                          capture_output=True, text=True, timeout=120)


def test_bvh_positions_on_the_command_line_is_recorded_and_rebuilds(tmp_path):
    """--bvh-positions input on exaggerate and batch: the pipeline file and the manifest say so, the
    BVH reads back as adding; the default (standard) is recorded too, and its BVH reads as replacing."""
    path = shared(ICLONE)
    for folder, extra in ((tmp_path / "input", ["--bvh-positions", "input"]), (tmp_path / "standard", [])):
        done = cli("-q", "exaggerate", path, "-o", folder, "--no-glb", "--subjoints", "2", *extra)
        assert done.returncode == 0, done.stderr
        wanted = "input" if extra else "standard"
        assert f'bvh_positions = "{wanted}"' in (folder / f"{path.stem}.pipeline.toml").read_text()
        info = json.loads((folder / f"{path.stem}.json").read_text())
        assert info["config"]["output"]["bvh_positions"] == wanted
        assert info["result"]["bvh_position_channels"] == ("add" if extra else "replace")
        _, report = read_bvh(folder / f"{path.stem}.bvh")
        assert report.root_offset == info["result"]["bvh_position_channels"]
    # The pipeline file rebuilds the input-convention output byte for byte.
    done = cli("-q", "exaggerate", path, "-o", tmp_path / "again", "--no-glb",
               "--config", tmp_path / "input" / f"{path.stem}.pipeline.toml")
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "again" / f"{path.stem}.bvh").read_bytes() == (tmp_path / "input" / f"{path.stem}.bvh").read_bytes()
    # batch takes it too.
    (tmp_path / "in").mkdir()
    (tmp_path / "in" / path.name).write_bytes(path.read_bytes())
    done = cli("-q", "batch", tmp_path / "in", tmp_path / "batch", "-j", "1", "--no-glb", "--subjoints", "2",
               "--bvh-positions", "input")
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "batch" / f"{path.stem}.bvh").read_bytes() == (tmp_path / "input" / f"{path.stem}.bvh").read_bytes()


def test_a_bad_bvh_positions_is_one_line_exit_2_and_nothing_written(tmp_path):
    path = shared(ICLONE)
    (tmp_path / "bad.toml").write_text('[output]\nbvh_positions = "add"\n')
    for args in (["--bvh-positions", "sideways"], ["--config", tmp_path / "bad.toml"]):
        done = cli("exaggerate", path, "-o", tmp_path / "out", *args)
        lines = done.stderr.strip().splitlines()
        assert done.returncode == 2 and len(lines) == 1 and lines[0].startswith("Error: "), done.stderr
        assert "bvh-positions" in lines[0] or "bvh_positions" in lines[0]
        assert not (tmp_path / "out").exists()
