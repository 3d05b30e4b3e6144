"""The whole job from Python: `convert` writes a complete set or nothing, from paths, bytes or streams."""

from __future__ import annotations

import hashlib
import io
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from mocap_exaggerate import convert
from mocap_exaggerate.config import resolve_config
from mocap_exaggerate.core.errors import ConfigError, InputError
from mocap_exaggerate.io.bvh import read_bvh
from mocap_exaggerate.io.files import OutputExistsError, OutputSet, write_files
from mocap_exaggerate.pipeline import STAGES, Stage, run

from .helpers import SAMPLE_DIR

FAST = resolve_config("cartoon", None, {"subjoints": {"per_link": 2}})


def snapshot(folder):
    """Every file below ``folder`` with its bytes (and nothing for a folder that is not there)."""
    if not folder.exists():
        return None
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_convert_writes_the_set_and_returns_what_it_did(sample_clip, tmp_path):
    record = convert(sample_clip, tmp_path / "out", FAST, preset="cartoon")
    names = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert names == ["cmu_09_01_run_daz.bvh", "cmu_09_01_run_daz.glb", "cmu_09_01_run_daz.json",
                     "cmu_09_01_run_daz.pipeline.toml", "cmu_09_01_run_daz.weights.npz"]
    assert set(record.outputs) == {"bvh", "glb", "weights", "pipeline", "manifest"}
    assert all(path.exists() for path in record.outputs.values())
    written = read_bvh(record.outputs["bvh"])[0]
    assert record.frames == written.num_frames == 149 and record.joints == written.skeleton.num_joints
    assert record.max_link_stretch >= 1.0 and record.seconds > 0 and record.input == str(sample_clip)
    assert {"read", "extrapolate", "springs", "orient", "write", "glb"} <= set(record.timings)
    assert any("rest-pose frame" in note for note in record.notes)
    # The manifest is written last and names the hash of every other file of the set.
    manifest = json.loads(record.outputs["manifest"].read_text())
    assert manifest == json.loads(json.dumps(record.manifest))
    for kind, digest in manifest["outputs"]["hashes"].items():
        assert digest == "sha256:" + hashlib.sha256(record.outputs[kind].read_bytes()).hexdigest(), kind
    assert manifest["input"]["hash"] == "sha256:" + hashlib.sha256(sample_clip.read_bytes()).hexdigest()


def test_the_written_pipeline_file_rebuilds_the_same_output(sample_clip, tmp_path):
    config = resolve_config("looney", None, {"extrapolate": {"omega": 3.5, "weights": {"left_arm": 2.0}}})
    first = convert(sample_clip, tmp_path / "a", config, glb=False)
    again = resolve_config(None, first.outputs["pipeline"].read_text(), None)
    assert again == replace(config, glb=replace(config.glb, enabled=False))  # the GLB left out is recorded too
    second = convert(sample_clip, tmp_path / "b", again)
    assert first.outputs["bvh"].read_bytes() == second.outputs["bvh"].read_bytes()
    assert set(second.outputs) == {"bvh", "pipeline", "manifest"}


def test_bytes_and_streams_in_and_out(sample_clip, tmp_path):
    data = sample_clip.read_bytes()
    from_path = convert(sample_clip, tmp_path / "p", FAST, glb=False)
    from_bytes = convert(data, tmp_path / "b", FAST, glb=False, name="take")
    assert from_bytes.outputs["bvh"].name == "take.bvh" and from_bytes.input == "<bytes>"
    assert from_bytes.outputs["bvh"].read_bytes() == from_path.outputs["bvh"].read_bytes()
    stream = io.BytesIO(data)
    out = io.BytesIO()
    record = convert(stream, out, FAST)  # a stream gets the BVH alone: no manifest, no GLB
    assert out.getvalue() == from_path.outputs["bvh"].read_bytes()
    assert record.manifest is None and record.outputs == {}


def test_the_manifest_names_the_preset_a_config_is(sample_clip, tmp_path):
    """``convert(clip, out, load_preset("looney"))``, the README's example, recorded no preset: the
    preset a config is, setting for setting, is recorded; a changed one is none; no config is the default."""
    from mocap_exaggerate import load_preset

    looney = load_preset("looney")
    changed = replace(looney, extrapolate=replace(looney.extrapolate, omega=3.0))
    for name, config, expected in (("a", looney, "looney"), ("b", changed, None), ("c", None, "cartoon")):
        record = convert(sample_clip, tmp_path / name, config, glb=False)
        assert json.loads(record.outputs["manifest"].read_text())["preset"] == expected, name
        pipeline = record.outputs["pipeline"].read_text()
        assert (f'preset = "{expected}"' in pipeline) == (expected is not None), pipeline[:200]


class _Disk(io.RawIOBase):
    """A raw stream, as ``sys.stdout.buffer`` is under ``PYTHONUNBUFFERED``, onto a disk with ``room`` bytes
    left: a write takes at most 4,096 bytes and what fits, then the disk is full (ENOSPC)."""

    def __init__(self, room: int) -> None:
        self.room, self.data = room, bytearray()

    def writable(self) -> bool:
        return True

    def write(self, piece) -> int:
        if not self.room:
            raise OSError(28, "No space left on device")
        taken = bytes(piece[: min(4096, self.room)])
        self.data += taken
        self.room -= len(taken)
        return len(taken)


def test_a_raw_stream_gets_the_whole_bvh_or_the_disk_s_error(sample_clip):
    """A raw stream may take part of a write and say so: the rest is written, and a full disk is an
    error (it was a truncated BVH and exit 0 under PYTHONUNBUFFERED)."""
    whole = io.BytesIO()
    convert(sample_clip, whole, FAST)
    roomy = _Disk(1 << 30)
    convert(sample_clip, roomy, FAST)
    assert bytes(roomy.data) == whole.getvalue()
    with pytest.raises(OSError, match="No space left"):
        convert(sample_clip, _Disk(len(whole.getvalue()) // 2), FAST)

    class Sink:  # a file-like object of a caller's, whose write says nothing (None): it takes it all
        def __init__(self) -> None:
            self.pieces = []

        def write(self, piece) -> None:
            self.pieces.append(piece)

    sink = Sink()
    convert(sample_clip, sink, FAST)
    assert b"".join(sink.pieces) == whole.getvalue() and all(type(piece) is bytes for piece in sink.pieces)


@pytest.mark.parametrize("case", ["exists", "trails exists", "input folder", "a folder in the way", "bad units",
                                  "bad name", "bad path file", "bad skin"])
def test_a_refusal_writes_nothing(sample_clip, tmp_path, case):
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("untouched")
    kwargs = {}
    source = sample_clip
    if case == "exists":
        (out / "cmu_09_01_run_daz.glb").write_bytes(b"old")
        kwargs = {"trails": tmp_path / "out" / "trails.json"}  # once written even when the run was refused
        error = OutputExistsError
    elif case == "trails exists":
        (out / "trails.json").write_bytes(b"old")
        kwargs = {"trails": out / "trails.json"}
        error = OutputExistsError
    elif case == "input folder":
        source = out / "clip.bvh"
        source.write_bytes(sample_clip.read_bytes())
        kwargs = {"overwrite": True, "name": "clip"}  # even with overwrite, never over the input
        error = ConfigError
    elif case == "a folder in the way":
        (out / "cmu_09_01_run_daz.json").mkdir()
        kwargs = {"overwrite": True}
        error = ConfigError
    elif case == "bad units":
        kwargs = {"units": "furlong"}
        error = ConfigError
    elif case == "bad name":
        kwargs = {"name": "../escape"}
        error = ConfigError
    elif case == "bad path file":
        (tmp_path / "edit.json").write_text('{"trails": 5}')
        kwargs = {"path_file": tmp_path / "edit.json"}
        error = InputError
    else:
        kwargs = {"skin": tmp_path / "none.npz"}
        error = InputError
    before = snapshot(tmp_path)
    with pytest.raises(error):
        convert(source, out, FAST, **kwargs)
    assert snapshot(tmp_path) == before


def test_a_missing_output_folder_is_not_left_behind_by_a_refusal(sample_clip, tmp_path):
    with pytest.raises(ConfigError):
        convert(sample_clip, tmp_path / "new" / "deeper", FAST, units="furlong")
    assert not (tmp_path / "new").exists()


@pytest.mark.parametrize("name", ["../x", "/abs/x", "a/b", "a\\b", ".hidden", "", "x" * 250, "tab\there"])
def test_names_are_plain_file_names(sample_clip, tmp_path, name):
    with pytest.raises(ConfigError, match="name"):
        convert(sample_clip, tmp_path / "out", FAST, name=name)
    assert not (tmp_path / "out").exists() and sorted(tmp_path.iterdir()) == []


def test_a_failed_set_leaves_no_file_and_no_temporary(tmp_path):
    (tmp_path / "second.bin").mkdir()  # renaming a file onto a folder fails
    with pytest.raises(OSError) as caught:
        write_files([(tmp_path / "first.bin", b"1"), (tmp_path / "second.bin", [b"2", b"2"]),
                     (tmp_path / "third.bin", b"3")], overwrite=True)
    assert caught.value.filename == str(tmp_path / "second.bin")  # the target, not our temporary name
    assert sorted(p.name for p in tmp_path.iterdir()) == ["second.bin"]  # first.bin, renamed already, went again
    assert not list(tmp_path.glob(".*.tmp"))


@pytest.mark.parametrize("links", [True, False], ids=["hard links", "no hard links"])
@pytest.mark.parametrize("failing", [1, 2, 3, 4])
def test_an_overwrite_that_fails_partway_leaves_the_folder_as_it_was(tmp_path, monkeypatch, links, failing):
    """A set over an older one whose ``failing``-th rename fails (an immutable file, say): the files renamed
    already are put back, the retired manifest too; nothing of ours is left. It left the new BVH beside the
    old GLB and no manifest. Where no hard link can be made, nothing can be put back once a file is
    replaced: then the old manifest stays retired (it would vouch for a set half replaced)."""
    import os

    from mocap_exaggerate.io import files

    for name in ("clip.bvh", "clip.glb", "clip.json"):
        (tmp_path / name).write_bytes(b"old " + name.encode())
    (tmp_path / "keep.txt").write_text("untouched")
    before = snapshot(tmp_path)
    calls, real = [], os.replace

    def replace_or_fail(source, target):
        calls.append(target)
        if len(calls) == failing:
            raise PermissionError(1, "Operation not permitted")
        return real(source, target)

    with OutputSet(overwrite=True) as written:
        for name in ("clip.bvh", "clip.glb", "new.npz"):
            written.add(tmp_path / name, b"new " + name.encode())
        written.add(tmp_path / "clip.json", b"new manifest")
        monkeypatch.setattr(files.os, "replace", replace_or_fail)
        if not links:
            monkeypatch.setattr(files.os, "link", lambda *a, **k: (_ for _ in ()).throw(PermissionError(1, "no")))
        with pytest.raises(PermissionError):
            written.commit(retire_first=[tmp_path / "clip.json"])
        monkeypatch.undo()
    after = snapshot(tmp_path)
    assert not [name for name in after if name.startswith(".")]  # no temporary, no kept copy
    if links or failing == 1:  # (the first rename failed: nothing was replaced)
        assert after == before
    else:  # the files that were there and are replaced stay new; one the set added goes again
        replaced = [n for n in ["clip.bvh", "clip.glb", "new.npz"][: failing - 1] if n in before]
        assert after == {**{n: b for n, b in before.items() if n != "clip.json"},
                         **{n: b"new " + n.encode() for n in replaced}}
    assert calls[:failing] == [tmp_path / n for n in ("clip.bvh", "clip.glb", "new.npz", "clip.json")][:failing]


def test_the_bvh_is_renamed_last_but_the_manifest(tmp_path, monkeypatch):
    """A run killed between its renames then leaves the set's other files beside a new BVH (which tells it
    from a clip a batch must not write over), or the old BVH as it was."""
    import os

    from mocap_exaggerate.io import files

    order, real = [], os.replace
    with OutputSet(overwrite=True) as written:
        for name in ("clip.bvh", "clip.glb", "clip.pipeline.toml", "clip.json"):
            written.add(tmp_path / name, name.encode())
        monkeypatch.setattr(files.os, "replace", lambda a, b: (order.append(Path(b).name), real(a, b)))
        written.commit(late=[tmp_path / "clip.bvh"])
    assert order == ["clip.glb", "clip.pipeline.toml", "clip.bvh", "clip.json"]


def test_a_retired_file_that_cannot_be_moved_aside_stops_the_set_before_any_rename(tmp_path, monkeypatch):
    import os

    from mocap_exaggerate.io import files

    (tmp_path / "clip.json").write_bytes(b"old manifest")
    (tmp_path / "clip.bvh").write_bytes(b"old")
    before = snapshot(tmp_path)
    real = os.rename
    with OutputSet(overwrite=True) as written:
        written.add(tmp_path / "clip.bvh", b"new")
        written.add(tmp_path / "clip.json", b"new manifest")
        monkeypatch.setattr(files.os, "rename", lambda a, b: (_ for _ in ()).throw(PermissionError(1, "no"))
                            if Path(a).name == "clip.json" else real(a, b))
        with pytest.raises(PermissionError):
            written.commit(retire_first=[tmp_path / "clip.json"])
    assert snapshot(tmp_path) == before


def test_an_overwrite_keeps_nothing_aside_once_done(tmp_path):
    (tmp_path / "clip.bvh").write_bytes(b"old")
    (tmp_path / "clip.json").write_bytes(b"old manifest")
    write_files([(tmp_path / "clip.bvh", b"new")], overwrite=True)
    with OutputSet(overwrite=True) as written:
        written.add(tmp_path / "clip.bvh", b"newer")
        written.commit(retire_first=[tmp_path / "clip.json"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clip.bvh"] and (tmp_path / "clip.bvh").read_bytes() == b"newer"


def test_an_output_set_is_renamed_only_on_commit(tmp_path):
    with OutputSet() as written:
        digest = written.add(tmp_path / "a" / "x.bin", [b"ab", b"c"])
        assert digest == "sha256:" + hashlib.sha256(b"abc").hexdigest()
        assert not (tmp_path / "a" / "x.bin").exists()
    assert not (tmp_path / "a").exists()  # aborted: the folder it made is gone too
    with OutputSet() as written:
        written.add(tmp_path / "x.bin", b"abc")
        written.commit()
    assert (tmp_path / "x.bin").read_bytes() == b"abc" and not list(tmp_path.glob(".*.tmp"))


def test_a_reserved_file_keeps_its_place_in_the_renames_and_may_be_written_on_another_thread(tmp_path, monkeypatch):
    """The job writes the GLB on the thread that builds it while the BVH is written: the GLB's place among the
    renames is the one it was reserved in, its digest its bytes'; a file reserved and never written is
    not renamed onto its target, and leaves no temporary."""
    import os
    from concurrent.futures import ThreadPoolExecutor

    from mocap_exaggerate.io import files

    order, real = [], os.replace
    pool = ThreadPoolExecutor(max_workers=1)
    pool.submit(int).result()  # (the pool's thread started before the count: it is not the set's)
    before = _open_descriptors()
    with OutputSet(overwrite=True) as written, pool:
        glb = written.reserve(tmp_path / "clip.glb")
        unused = written.reserve(tmp_path / "clip.usdc")
        digest = pool.submit(glb, [b"gl", b"TF"])
        written.add(tmp_path / "clip.bvh", b"motion")
        written.add(tmp_path / "clip.json", b"manifest")
        assert digest.result() == "sha256:" + hashlib.sha256(b"glTF").hexdigest()
        assert unused is not None
        monkeypatch.setattr(files.os, "replace", lambda a, b: (order.append(Path(b).name), real(a, b)))
        written.commit(late=[tmp_path / "clip.bvh"])
    assert order == ["clip.glb", "clip.bvh", "clip.json"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clip.bvh", "clip.glb", "clip.json"]
    assert _open_descriptors() == before
    assert (tmp_path / "clip.glb").read_bytes() == b"glTF"


def _open_descriptors() -> int:
    import os

    return len(os.listdir("/proc/self/fd")) if os.path.isdir("/proc/self/fd") else 0


def test_an_aborted_set_removes_a_reserved_file_written_or_not(tmp_path):
    before = _open_descriptors()
    with OutputSet() as written:
        written.reserve(tmp_path / "a.glb")(b"data")
        written.reserve(tmp_path / "b.glb")
    assert list(tmp_path.iterdir()) == []
    assert _open_descriptors() == before  # (each reserved file's descriptor and lock let go)


def test_a_reserved_file_whose_writing_failed_is_neither_renamed_nor_left(tmp_path):
    """A writer that fails (its data raising half way) leaves the set able to commit the rest: the failed
    file is not renamed onto its target, its temporary is removed, and no descriptor stays open."""
    before = _open_descriptors()

    def broken():
        yield b"half"
        raise OSError(28, "No space left on device")

    with OutputSet() as written:
        usd = written.reserve(tmp_path / "clip.usdc")
        unused = written.reserve(tmp_path / "clip.fbx")
        with pytest.raises(OSError, match="clip.usdc"):
            usd(broken())
        written.add(tmp_path / "clip.bvh", b"motion")
        written.commit()
    assert unused is not None
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clip.bvh"]
    assert _open_descriptors() == before


def test_a_stage_added_to_the_declared_list_runs_in_its_place(sample_clip):
    motion, _ = read_bvh(sample_clip)
    # Contacts off: they would put the lifted feet back where they were captured.
    config = replace(FAST, springs=replace(FAST.springs, enabled=False), contacts=replace(FAST.contacts, enabled=False))

    def lift(state, height):
        positions = state.positions.copy()
        positions[..., 1] += height
        return replace(state, positions=positions)

    stages = STAGES[:3] + (Stage("lift", lift, lambda c: 10.0),) + STAGES[3:]
    plain = run(motion, config)
    lifted = run(motion, config, stages=stages)
    assert lifted.stages == ["extrapolate", "correct", "lift", "subjoints", "orient"]
    assert plain.stages == ["extrapolate", "correct", "subjoints", "orient"]
    moved = lifted.world_positions - plain.world_positions
    np.testing.assert_allclose(moved[..., 1], 10.0, atol=1e-6)
    np.testing.assert_allclose(moved[..., [0, 2]], 0.0, atol=1e-6)
    switched_off = (Stage("lift", lift, lambda c: None),)
    assert run(motion, config, stages=STAGES[:3] + switched_off + STAGES[3:]).stages == plain.stages
    with pytest.raises(ValueError, match="orient"):
        run(motion, config, stages=STAGES[:-1])


def test_a_set_is_complete_only_while_every_file_matches_its_manifest(sample_clip, tmp_path):
    from mocap_exaggerate.jobs.job import check_output_set

    record = convert(sample_clip, tmp_path, FAST, glb=False)
    manifest = record.outputs["manifest"]
    assert check_output_set(manifest) == []
    record.outputs["bvh"].write_bytes(b"HIERARCHY\n")
    assert check_output_set(manifest) == [f"{record.outputs['bvh']}: not the file the manifest recorded"]
    record.outputs["bvh"].unlink()
    assert check_output_set(manifest) == [f"{record.outputs['bvh']}: missing"]
    manifest.unlink()
    assert check_output_set(manifest) == [f"{manifest}: no manifest"]


def test_the_next_run_clears_what_a_killed_one_left(sample_clip, tmp_path):
    stale = tmp_path / ".cmu_09_01_run_daz.bvh.abc123.tmp"
    stale.write_bytes(b"half a file")
    other = tmp_path / ".someone_elses.bvh.abc123.tmp"
    other.write_bytes(b"not ours")
    convert(sample_clip, tmp_path, FAST, glb=False)
    assert not stale.exists() and other.exists()


def test_a_pipeline_file_being_rerun_is_never_written_over(sample_clip, tmp_path):
    first = convert(sample_clip, tmp_path, FAST, glb=False)
    pipeline = first.outputs["pipeline"]
    before = pipeline.read_bytes()
    with pytest.raises(ConfigError, match="input"):
        convert(sample_clip, tmp_path, FAST, glb=False, overwrite=True, protect=(pipeline,))
    assert pipeline.read_bytes() == before


def test_an_input_named_like_a_temporary_is_not_cleared_away(sample_clip, tmp_path):
    clip = tmp_path / ".clip.bvh.mine.tmp"
    clip.write_bytes(sample_clip.read_bytes())
    convert(clip, tmp_path, FAST, glb=False, name="clip")
    assert clip.read_bytes() == sample_clip.read_bytes()


def test_outputs_a_run_no_longer_writes_do_not_stay_beside_its_manifest(sample_clip, tmp_path):
    from mocap_exaggerate.jobs.job import check_output_set

    convert(sample_clip, tmp_path, FAST)
    with pytest.raises(OutputExistsError):
        convert(sample_clip, tmp_path, FAST, glb=False)  # the old GLB is in the way, as any output would be
    convert(sample_clip, tmp_path, FAST, glb=False, overwrite=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cmu_09_01_run_daz.bvh", "cmu_09_01_run_daz.json",
                                                         "cmu_09_01_run_daz.pipeline.toml"]
    assert check_output_set(tmp_path / "cmu_09_01_run_daz.json") == []


def test_the_public_names_stay_the_functions_after_every_subpackage_is_imported():
    # A subpackage named like a public function (a `run/` beside `run()`) replaces the function
    # on the package the moment anything imports it.
    import importlib
    import pkgutil

    import mocap_exaggerate

    for module in pkgutil.walk_packages(mocap_exaggerate.__path__, "mocap_exaggerate."):
        importlib.import_module(module.name)
    for name in mocap_exaggerate.__all__:
        value = getattr(mocap_exaggerate, name)
        assert not isinstance(value, type(mocap_exaggerate)), f"mocap_exaggerate.{name} is a module"
    from mocap_exaggerate import run

    assert callable(run)


def test_units_guessed_into_an_unlikely_figure_are_said(sample_clip, tmp_path):
    """A 64-unit skeleton (inches, say) guessed as centimetres makes a 0.64 m figure: the user hears
    it with what to give, and not for a figure of a likely height or units given."""
    from dataclasses import replace as changed

    from mocap_exaggerate import save_bvh
    from mocap_exaggerate.io.bvh import read_bvh as read

    motion, _ = read(sample_clip.read_bytes())
    factor = 64.0 / motion.skeleton.height()
    skeleton = changed(motion.skeleton, offsets=motion.skeleton.offsets * factor,
                       end_sites=motion.skeleton.end_sites * factor)
    small = tmp_path / "inches.bvh"
    save_bvh(motion.replace(skeleton=skeleton, local_positions=motion.local_positions * factor), small)
    record = convert(small, tmp_path / "out", FAST)
    said = [w for w in record.warnings if "GLB units" in w]
    assert len(said) == 1 and "0.64 m tall" in said[0] and "--units in" in said[0], record.warnings
    assert record.manifest["outputs"]["units"].startswith("cm (guessed")
    assert not [w for w in convert(small, tmp_path / "given", FAST, units="in").warnings if "GLB units" in w]
    assert not [w for w in convert(sample_clip, tmp_path / "likely", FAST).warnings if "GLB units" in w]


def test_a_character_given_with_no_glb_is_said_to_be_unused(tmp_path):
    """``--no-glb --skin X``: nothing uses the character; said once, not silently dropped."""
    from mocap_exaggerate.rig.body import default_skin

    motion = read_bvh(SAMPLE_DIR / "cmu_09_01_run_daz.bvh")[0]
    record = convert(SAMPLE_DIR / "cmu_09_01_run_daz.bvh", tmp_path, glb=False, skin=default_skin(motion.skeleton))
    assert any("not used" in w and "--no-glb" in w for w in record.warnings), record.warnings
    assert not any("not used" in w for w in convert(SAMPLE_DIR / "cmu_09_01_run_daz.bvh", tmp_path / "b", glb=False).warnings)


def test_a_temporary_another_run_is_writing_is_not_cleared_away(tmp_path):
    """Two runs into one folder (a farm's retry beside its first try): each clears what a killed run
    left, but not the other's temporaries while it writes them (it holds a lock on each until its set
    is in place). Before, one run deleted the other's live files, which failed: "No such file"."""
    from mocap_exaggerate.io.files import remove_stale_temporaries

    target = tmp_path / "clip.bvh"
    left = tmp_path / ".clip.bvh.killed01.tmp"  # what a killed run left: nobody holds it
    left.write_bytes(b"half a clip")
    writing = OutputSet()
    writing.add(target, b"the other run's clip")
    (live, _), = writing.pending
    assert remove_stale_temporaries(target) == [left]
    assert Path(live).exists() and not left.exists()
    writing.commit()
    assert target.read_bytes() == b"the other run's clip" and not writing.live
    aborted = OutputSet(overwrite=True)
    aborted.add(target, b"another")
    aborted.abort()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clip.bvh"] and not aborted.live
