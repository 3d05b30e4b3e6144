"""Whole folders (issue 12): `batch`, several files to `exaggerate`, resume, pools, `plan`.

Run the way users run them: a real process, its exit code and stderr, the files it leaves.
"""

from __future__ import annotations

import functools
import json
import os
import shlex
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mocap_exaggerate.jobs.batch import BatchOptions, Clip, find_clips, glob_regex, run_batch
from mocap_exaggerate.jobs.job import check_output_set

from .helpers import SAMPLE_DIR, ended, no_glb

RUN = SAMPLE_DIR / "cmu_09_01_run_daz.bvh"
SIT = SAMPLE_DIR / "mocapbank_sit_down_stand_up.bvh"
JUMP = SAMPLE_DIR / "cmu_16_01_jump_amc2bvh.bvh"
SUFFIXES = (".bvh", ".glb", ".weights.npz", ".pipeline.toml", ".json")


def command(*args, timeout=300, **kwargs):
    kwargs.setdefault("stdout", subprocess.PIPE)
    return subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", *map(str, args)],
                          stderr=subprocess.PIPE, text=True, timeout=timeout, **kwargs)


def mixed_folder(root: Path) -> Path:
    """Good clips in sub-folders, and every kind of bad file a library holds."""
    folder = root / "mocap"
    (folder / "walks" / "slow").mkdir(parents=True)
    (folder / "jumps").mkdir()
    shutil.copy(RUN, folder / "walks" / "run.bvh")
    shutil.copy(SIT, folder / "walks" / "slow" / "sit.BVH")  # any case
    shutil.copy(JUMP, folder / "jumps" / "jump.bvh")
    (folder / "empty.bvh").write_bytes(b"")
    (folder / "picture.bvh").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(256)))
    (folder / "broken.bvh").write_bytes(RUN.read_bytes()[:3000])  # cut off mid-hierarchy
    (folder / "notes.txt").write_text("not a clip, not matched")
    (folder / "gone.bvh").symlink_to(folder / "nowhere.bvh")  # unreadable: a link to nothing
    (folder / "jumps" / "again").symlink_to(folder)  # a loop
    return folder


def files_under(folder: Path) -> set[str]:
    return {p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()}


def expected_outputs(*stems: str) -> set[str]:
    return {stem + suffix for stem in stems for suffix in SUFFIXES}


# ---------------------------------------------------------------------------- finding clips


def test_the_glob_matches_paths_by_folder_and_without_regard_to_case():
    deep = glob_regex("**/*.bvh")
    assert deep.fullmatch("a.bvh") and deep.fullmatch("x/y/A.BVH") and not deep.fullmatch("a.bvh.txt")
    assert not glob_regex("*.bvh").fullmatch("x/a.bvh")
    assert glob_regex("walk*/**/*.bvh").fullmatch("walks/a/b.bvh") and not glob_regex("walk*/**/*.bvh").fullmatch("run/a.bvh")
    assert glob_regex("[ab]?.bvh").fullmatch("b1.bvh") and not glob_regex("[!ab]?.bvh").fullmatch("b1.bvh")
    assert glob_regex("x[.bvh").fullmatch("x[.bvh")  # an unclosed bracket is itself


def test_clips_are_found_sorted_with_loops_and_clashes_reported(tmp_path):
    folder = mixed_folder(tmp_path)
    shutil.copy(RUN, folder / "walks" / "run.BVH")  # the same outputs as run.bvh
    clips, problems = find_clips(folder)
    relative = [c.relative.as_posix() for c in clips]
    assert relative == sorted(relative)
    assert {"walks/slow/sit.BVH", "jumps/jump.bvh", "empty.bvh", "gone.bvh"} <= set(relative)
    assert not any("again" in r for r in relative)  # the loop is not walked
    reasons = {Path(p.input).name: p.error for p in problems}
    assert "already walked" in reasons["again"]
    # run.bvh and run.BVH would write the same files: the first in order is kept, the other reported.
    assert "walks/run.BVH" in relative and "walks/run.bvh" not in relative
    assert "would be those of" in reasons["run.bvh"] and "run.BVH" in reasons["run.bvh"]
    # An output folder inside the input folder is not walked (its .bvh files are outputs).
    (folder / "out").mkdir()
    shutil.copy(RUN, folder / "out" / "old.bvh")
    clips, _ = find_clips(folder, exclude=[folder / "out"])
    assert not any(c.relative.parts[0] == "out" for c in clips)


# ---------------------------------------------------------------------------- the command


def test_a_mixed_folder_converts_the_good_lists_the_bad_and_exits_1(tmp_path):
    folder = mixed_folder(tmp_path)
    out = tmp_path / "out"
    done = command("batch", folder, out, "-j", "2", "--json")
    assert done.returncode == 1, done.stderr
    assert "Traceback" not in done.stderr
    assert files_under(out) == (expected_outputs("walks/run", "walks/slow/sit", "jumps/jump"))  # no stray file
    for manifest in out.rglob("*.json"):
        assert check_output_set(manifest) == []
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    by_name = {Path(line["input"]).name: line for line in lines}
    for name in ("run.bvh", "sit.BVH", "jump.bvh"):
        assert by_name[name]["status"] == "converted" and by_name[name]["frames"] > 0
        assert set(by_name[name]["outputs"]) == {"bvh", "glb", "weights", "pipeline", "manifest"}
    for name, says in (("empty.bvh", "empty"), ("picture.bvh", "not a BVH file"), ("broken.bvh", "broken.bvh:"),
                       ("gone.bvh", "nowhere.bvh, which does not exist")):
        assert by_name[name]["status"] == "failed" and says in by_name[name]["error"], by_name[name]
        assert "failed: " in done.stderr and says in done.stderr
    assert by_name["again"]["status"] == "skipped"
    assert "converted       3" in done.stderr and "failed          4" in done.stderr


def test_serial_and_pool_write_the_same_bytes(tmp_path):
    folder = mixed_folder(tmp_path)
    serial, pool = tmp_path / "serial", tmp_path / "pool"
    assert command("batch", folder, serial, "-j", "1", "-q").returncode == 1
    assert command("batch", folder, pool, "-j", "2", "-q").returncode == 1
    assert files_under(serial) == files_under(pool)
    for name in files_under(serial):
        a, b = (serial / name).read_bytes(), (pool / name).read_bytes()
        if name.endswith(".json"):  # manifests differ in their timings only
            a, b = (json.loads(x) for x in (a, b))
            a.pop("timings"), b.pop("timings")
        assert a == b, name


def test_every_option_reaches_every_file_and_glob_chooses(tmp_path):
    folder = mixed_folder(tmp_path)
    out = tmp_path / "out"
    done = command("batch", folder, out, "--glob", "walks/**/*.bvh", "--no-glb", "--omega", "2", "--preset",
                   "subtle", "-j", "1")
    assert done.returncode == 0, done.stderr
    assert files_under(out) == {f"{s}{x}" for s in ("walks/run", "walks/slow/sit")
                                for x in (".bvh", ".pipeline.toml", ".json")}
    info = json.loads((out / "walks" / "run.json").read_text())
    assert info["preset"] == "subtle" and info["config"]["extrapolate"]["omega"] == 2.0


def test_usage_mistakes_exit_2_in_one_line(tmp_path):
    folder = mixed_folder(tmp_path)
    for args, says in (
        ((tmp_path / "nowhere", tmp_path / "o"), "no such folder"),
        ((RUN, tmp_path / "o"), "is a file"),
        ((folder, folder), "is the input folder"),
        ((folder, tmp_path / "o", "--glob", "*.fbx"), "no file matches"),
        ((folder, tmp_path / "o", "--sigma", "-1"), "sigma"),
        ((folder, tmp_path / "o", "-j", "0"), "-j"),
        ((folder, tmp_path / "o", "-j", "99999999999999999999"), "-j"),
        ((folder, tmp_path / "o", "--glob", "a" * 5000), "5000 characters"),
        ((folder, tmp_path / "o", "--glob", "["), "no file matches"),
        ((folder, tmp_path / "o", "--units", "furlongs"), "furlongs"),
    ):
        done = command("batch", *args)
        assert done.returncode == 2, (args, done.stderr)
        assert says in done.stderr and "Traceback" not in done.stderr, (args, done.stderr)
        assert len(done.stderr.splitlines()) == 1 and len(done.stderr) < 400, done.stderr
        assert not (tmp_path / "o").exists()


def test_outputs_that_exist_fail_that_file_unless_overwrite_or_resume(tmp_path):
    folder = tmp_path / "in"
    folder.mkdir()
    shutil.copy(RUN, folder / "run.bvh")
    out = tmp_path / "out"
    assert command("batch", folder, out, "--no-glb", "-q").returncode == 0
    again = command("batch", folder, out, "--no-glb")
    assert again.returncode == 1 and "--overwrite" in again.stderr and "--resume" in again.stderr
    assert command("batch", folder, out, "--no-glb", "--overwrite", "-q").returncode == 0


# ---------------------------------------------------------------------------- resume


def copies(root: Path, count: int) -> Path:
    folder = root / "in"
    folder.mkdir()
    for k in range(count):
        shutil.copy(JUMP, folder / f"clip{k:02d}.bvh")
    return folder


def stamps(out: Path) -> dict[str, int]:
    return {p.name: p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file()}


def test_resume_after_a_kill_redoes_only_what_did_not_finish(tmp_path):
    folder = copies(tmp_path, 8)
    out = tmp_path / "out"
    process = subprocess.Popen([sys.executable, "-m", "mocap_exaggerate_cli.main", "-q", "batch", folder, out,
                                "-j", "1"], stderr=subprocess.PIPE, stdout=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while len(list(out.glob("*.json"))) < 2 and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.02)
    process.send_signal(signal.SIGKILL)
    process.wait(timeout=60)
    finished = {m.stem for m in out.glob("*.json") if not check_output_set(m)}
    assert 2 <= len(finished) < 8, "the kill should land mid-batch"
    before = stamps(out)

    done = command("batch", folder, out, "--resume", "-j", "2", "--json")
    assert done.returncode == 0, done.stderr
    statuses = {Path(json.loads(line)["input"]).stem: json.loads(line)["status"] for line in done.stdout.splitlines()}
    assert {stem for stem, status in statuses.items() if status == "skipped"} == finished
    after = stamps(out)
    for stem in finished:  # not one byte of a finished clip rewritten
        for suffix in SUFFIXES:
            assert after[stem + suffix] == before[stem + suffix]
    assert files_under(out) == expected_outputs(*(f"clip{k:02d}" for k in range(8)))  # no temporaries left
    assert all(check_output_set(m) == [] for m in out.glob("*.json"))


def test_resume_redoes_a_clip_whose_input_or_options_changed(tmp_path):
    folder = copies(tmp_path, 2)
    out = tmp_path / "out"
    assert command("batch", folder, out, "--no-glb", "-q").returncode == 0

    def statuses(*extra):
        done = command("batch", folder, out, "--no-glb", "--resume", "--json", *extra)
        assert done.returncode == 0, done.stderr
        return {Path(json.loads(line)["input"]).stem: json.loads(line)["status"] for line in done.stdout.splitlines()}

    assert statuses() == {"clip00": "skipped", "clip01": "skipped"}
    shutil.copy(RUN, folder / "clip01.bvh")  # new bytes under the same name
    assert statuses() == {"clip00": "skipped", "clip01": "converted"}
    assert statuses("--omega", "3") == {"clip00": "converted", "clip01": "converted"}
    (out / "clip00.pipeline.toml").write_text("tampered")
    assert statuses("--omega", "3") == {"clip00": "converted", "clip01": "skipped"}


def _hears_ctrl_c() -> None:
    """In the child before it starts: Ctrl-C at its default, as in a terminal. A test run started
    in the background by a non-interactive shell (``.ci/run &``) has SIGINT ignored, and a
    Python started with it ignored never hears it."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_ctrl_c_lets_running_clips_finish_and_says_what_did_not_start(tmp_path):
    folder = copies(tmp_path, 12)
    out = tmp_path / "out"
    process = subprocess.Popen([sys.executable, "-m", "mocap_exaggerate_cli.main", "batch", folder, out, "-j", "2"],
                               stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, start_new_session=True,
                               preexec_fn=_hears_ctrl_c)
    deadline = time.monotonic() + 120
    while not list(out.glob("*.json")) and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.02)
    os.killpg(process.pid, signal.SIGINT)  # what a terminal's Ctrl-C does: the whole group
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 130, stderr
    assert "Traceback" not in stderr and "not done" in stderr and "--resume" in stderr
    assert stderr.count("] converted") == len(list(out.glob("*.json")))  # each file reported once
    names = files_under(out)
    assert not any(name.endswith(".tmp") for name in names), names  # the clips in hand finished whole
    for manifest in out.glob("*.json"):
        assert check_output_set(manifest) == []
    assert 1 <= len(list(out.glob("*.json"))) < 12


def test_a_ctrl_c_held_while_workers_start_is_raised_when_they_are_up():
    from mocap_exaggerate.jobs.pool import ctrl_c_held

    before = signal.signal(signal.SIGINT, signal.default_int_handler)  # (a test run in the background ignores it)
    try:
        with pytest.raises(KeyboardInterrupt):
            with ctrl_c_held():
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(0.05)  # held: not raised in here
                inside = True
        assert inside
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # put back
        assert signal.SIGINT not in signal.pthread_sigmask(signal.SIG_BLOCK, [])  # and no longer blocked
        with ctrl_c_held():  # nothing pressed: nothing raised
            pass
    finally:
        signal.signal(signal.SIGINT, before)


@pytest.mark.process
def test_ctrl_c_while_the_workers_start_is_heard(tmp_path):
    """A Ctrl-C pressed while the forkserver and the workers start (the first half second) ends the
    batch as one pressed later does: exit 130, no traceback from any process, nothing half written.
    It was lost before: SIGINT was ignored while the workers started, and the batch ran to the end."""
    folder = copies(tmp_path, 12)
    for delay in (0.15, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5, 0.6):
        out = tmp_path / f"out{delay}"
        _, stderr = _ctrl_c_into_batch(folder, out, functools.partial(time.sleep, delay))
        assert "Error" not in stderr, (delay, stderr)
        assert len(list(out.glob("*.json"))) < 12, delay


@pytest.mark.process
def test_ctrl_c_on_a_local_dask_cluster_ends_the_batch_and_its_workers_quietly(tmp_path):
    """The workers of ``--scheduler local`` heard the terminal's Ctrl-C too, and each printed a
    KeyboardInterrupt traceback. Now only the batch hears it: exit 130, no traceback, no half-written
    file, and no process of the batch's left."""
    pytest.importorskip("distributed", reason="Dask distributed is not installed")
    folder = copies(tmp_path, 12)
    for moment in ("starting", "converting"):
        out = tmp_path / f"out_{moment}"

        def converting(out=out) -> None:
            deadline = time.monotonic() + 120
            while not list(out.glob("*.json")) and time.monotonic() < deadline:
                time.sleep(0.02)

        wait = functools.partial(time.sleep, 0.5) if moment == "starting" else converting
        process, stderr = _ctrl_c_into_batch(folder, out, wait, "--scheduler", "local")
        assert "KeyboardInterrupt" not in stderr, (moment, stderr)
        assert all(ended(pid) for pid in _group(process.pid)), moment  # no process of the batch's left


def _ctrl_c_into_batch(folder, out, wait, *options: str) -> tuple[subprocess.Popen, str]:
    """``batch folder out -j 2 *options`` as a user runs it, Ctrl-C pressed (to the whole group, as a
    terminal does) when ``wait`` returns; the process and its stderr, checked for what every press
    must give: exit 130, no traceback, nothing half written."""
    process = subprocess.Popen([sys.executable, "-m", "mocap_exaggerate_cli.main", "batch", folder, out, "-j", "2",
                                *options], stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True,
                               start_new_session=True, preexec_fn=_hears_ctrl_c)
    wait()
    os.killpg(process.pid, signal.SIGINT)
    _, stderr = process.communicate(timeout=120)
    # (-SIGINT: pressed while Python itself starts, before any of ours runs; a shell says 130 too)
    assert process.returncode in (130, -signal.SIGINT), (options, process.returncode, stderr)
    assert "Traceback" not in stderr, (options, stderr)
    written = files_under(out) if out.exists() else []
    assert not any(name.endswith(".tmp") for name in written), (options, written)
    return process, stderr


def _group(leader: int) -> list[int]:
    """The processes of a process group."""
    found = []
    for entry in Path("/proc").iterdir():
        try:
            if entry.name.isdigit() and os.getpgid(int(entry.name)) == leader:
                found.append(int(entry.name))
        except OSError:  # gone meanwhile
            continue
    return found


# ---------------------------------------------------------------------------- the library


def test_the_library_runs_a_batch_and_hears_of_each_file(tmp_path):
    folder = mixed_folder(tmp_path)
    clips, problems = find_clips(folder, "jumps/*.bvh")
    assert [c.relative.as_posix() for c in clips] == ["jumps/jump.bvh"]
    assert [Path(p.input).name for p in problems] == ["again"]  # the loop, met on the way
    heard = []
    results = run_batch(clips + [Clip(folder / "empty.bvh", Path("empty.bvh"))], tmp_path / "out",
                        BatchOptions(no_glb("subtle")), on_result=heard.append)
    assert [r.status for r in results] == ["converted", "failed"] and heard == results
    assert results[0].outputs["bvh"].endswith("jumps/jump.bvh") and results[1].error.endswith("file is empty")


# ---------------------------------------------------------------------------- several files to exaggerate


def test_exaggerate_takes_several_files_and_goes_on_past_a_bad_one(tmp_path):
    bad = tmp_path / "bad.bvh"
    bad.write_bytes(b"HIERARCHY\nROOT")
    out = tmp_path / "out"
    done = command("exaggerate", RUN, bad, JUMP, "-o", out, "--no-glb")
    assert done.returncode == 1 and "Traceback" not in done.stderr
    assert "bad.bvh" in done.stderr and "failed" in done.stderr
    assert {p.name for p in out.iterdir()} == {f"{s}{x}" for s in (RUN.stem, JUMP.stem)
                                              for x in (".bvh", ".pipeline.toml", ".json")}
    good = command("exaggerate", RUN, JUMP, "-o", tmp_path / "two", "--no-glb")
    assert good.returncode == 0, good.stderr


@pytest.mark.parametrize("extra, says", [
    (["-o", "-"], "standard output"),
    (["-o", "OUT", "--name", "x"], "--name"),
    (["-o", "OUT", "SAME"], "same outputs"),
])
def test_several_files_refuse_what_belongs_to_one(tmp_path, extra, says):
    other = tmp_path / "x" / RUN.name
    other.parent.mkdir()
    shutil.copy(RUN, other)
    args = [str(other) if a == "SAME" else str(tmp_path / "out") if a == "OUT" else a for a in extra]
    done = command("exaggerate", RUN, JUMP, *args)
    assert done.returncode == 2 and says in done.stderr and "Traceback" not in done.stderr, done.stderr
    assert not (tmp_path / "out").exists()


# ---------------------------------------------------------------------------- plan


def test_plan_prints_one_command_per_clip_that_makes_what_batch_makes(tmp_path):
    folder = mixed_folder(tmp_path)
    options = ["--preset", "looney", "--weight", "left_leg=0.5", "--no-glb", "--sigma", "0.25s"]
    planned = command("plan", folder, tmp_path / "farm", *options)
    assert planned.returncode == 0, planned.stderr
    lines = planned.stdout.splitlines()
    assert len(lines) == len(find_clips(folder)[0])
    assert not (tmp_path / "farm").exists()  # planning writes nothing
    line = next(line for line in lines if "jump.bvh" in line)
    words = shlex.split(line)
    assert words[:2] == ["mocap-exaggerate", "exaggerate"] and "left_leg=0.5" in words and "0.25s" in words
    ran = command(*words[1:])
    assert ran.returncode == 0, ran.stderr
    assert command("batch", folder, tmp_path / "batch", "--glob", "jumps/*", *options).returncode == 0
    for suffix in (".bvh", ".pipeline.toml"):
        assert ((tmp_path / "farm" / "jumps" / f"jump{suffix}").read_bytes()
                == (tmp_path / "batch" / "jumps" / f"jump{suffix}").read_bytes())


def test_a_clip_in_a_folder_named_with_a_terminals_escape_sequence_is_planned_as_itself(tmp_path):
    """Two folders whose names differ only by an escape sequence: piped, each job names its own clip, its
    bytes as they are (click's echo stripped what looked like a terminal's escape, and both lines named
    the same clip, the other never converted); the command that runs it shows the sequence escaped,
    never obeys it. A clip whose own name has one (no output may be named so) is left out, said once."""
    folder = tmp_path / "in"
    for sub in ("x", "x\x1b[0m"):
        (folder / sub).mkdir(parents=True)
        shutil.copy(RUN, folder / sub / "a.bvh")
    shutil.copy(JUMP, folder / "b\x1b[2J.bvh")
    for form in ([], ["--print0"]):
        planned = command("plan", folder, tmp_path / "farm", "--no-glb", *form)
        assert planned.returncode == 0, planned.stderr
        jobs = [shlex.split(line) for line in planned.stdout.split("\0" if form else "\n") if line]
        assert sorted(words[2] for words in jobs) == sorted(str(folder / sub / "a.bvh") for sub in ("x", "x\x1b[0m"))
        assert "b\\x1b[2J.bvh" in planned.stderr and "left out" in planned.stderr and "\x1b" not in planned.stderr
    ran = command(*next(words for words in jobs if "\x1b" in words[4])[1:])
    assert ran.returncode == 0 and "\x1b" not in ran.stderr and "x\\x1b[0m" in ran.stderr, ran.stderr


HOSTILE_NAMES = ["it's [a] dir/jump \"ü\" x.bvh", "run $(touch PWNED) `id` ; *.bvh"]


def _hostile_folder(root: Path) -> Path:
    folder = root / "in dir"
    for name, clip in zip(HOSTILE_NAMES, (JUMP, RUN)):
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(clip, folder / name)
    return folder


def _farm_env() -> dict:
    # The farm runs the installed command: the one beside this interpreter.
    return {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}


def _made(out: Path) -> list[str]:
    return sorted(str(p.relative_to(out)) for p in out.rglob("*.bvh"))


@pytest.mark.skipif(shutil.which("xargs") is None or shutil.which("sh") is None, reason="needs sh and xargs")
def test_the_readmes_farm_recipes_work_on_any_path(tmp_path):
    # Spaces, quotes, brackets, non-ASCII and shell syntax in folder and file names: the xargs
    # recipe (NUL-separated), one Slurm array task per line through sh, and the JSON argv.
    folder = _hostile_folder(tmp_path)
    expected = sorted(HOSTILE_NAMES)
    env = _farm_env()
    plan0 = command("plan", folder, tmp_path / "xargs", "--no-glb", "--print0", cwd=tmp_path)
    assert plan0.returncode == 0 and plan0.stdout.count("\0") == 2, plan0.stderr
    done = subprocess.run(["xargs", "-0", "-n", "1", "-P", "2", "sh", "-c"], input=plan0.stdout, text=True,
                          capture_output=True, env=env, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert _made(tmp_path / "xargs") == expected
    lines = command("plan", folder, tmp_path / "slurm", "--no-glb", cwd=tmp_path)
    assert lines.returncode == 0 and len(lines.stdout.splitlines()) == 2, lines.stderr
    (tmp_path / "jobs.txt").write_text(lines.stdout)
    for task in (1, 2):
        done = subprocess.run(["sh", "-c", 'sed -n "${SLURM_ARRAY_TASK_ID}p" jobs.txt | sh'], cwd=tmp_path,
                              env={**env, "SLURM_ARRAY_TASK_ID": str(task)}, capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
    assert _made(tmp_path / "slurm") == expected
    listed = command("plan", folder, tmp_path / "json", "--no-glb", "--json")
    for job in json.loads(listed.stdout):
        assert subprocess.run(job["argv"], env=env, capture_output=True).returncode == 0
    assert _made(tmp_path / "json") == expected
    assert not (tmp_path / "PWNED").exists() and not any(tmp_path.rglob("PWNED"))
    for out in ("xargs", "slurm", "json"):
        assert (tmp_path / out / "it's [a] dir" / "jump \"ü\" x.bvh").read_bytes() == (
            tmp_path / "xargs" / "it's [a] dir" / "jump \"ü\" x.bvh").read_bytes()


def test_a_path_with_a_line_break_is_left_out_of_a_line_list_and_kept_in_the_others(tmp_path):
    folder = tmp_path / "in"
    (folder / "two\nlines").mkdir(parents=True)  # (a clip so named is left out of every form: no output may be)
    shutil.copy(RUN, folder / "two\nlines" / "run.bvh")
    shutil.copy(JUMP, folder / "jump.bvh")
    lines = command("plan", folder, tmp_path / "out")
    assert lines.returncode == 0 and len(lines.stdout.splitlines()) == 1 and "jump.bvh" in lines.stdout
    assert "line break" in lines.stderr and "--print0" in lines.stderr
    nul = command("plan", folder, tmp_path / "out", "--print0")
    assert nul.stdout.count("\0") == 2
    assert len(json.loads(command("plan", folder, tmp_path / "out", "--json").stdout)) == 2
    both = command("plan", folder, tmp_path / "out", "--json", "--print0")
    assert both.returncode == 2 and "give one" in both.stderr and "Traceback" not in both.stderr


def test_resume_knows_a_skin_by_its_content(tmp_path):
    """The skin is part of the parameters: the same skin keeps finished clips, another redoes them."""
    import numpy as np

    from mocap_exaggerate.io.bvh import read_bvh
    from mocap_exaggerate.rig.body import default_skin

    folder = tmp_path / "in"
    folder.mkdir()
    shutil.copy(RUN, folder / "run.bvh")
    body = default_skin(read_bvh(RUN)[0].skeleton)
    skin = tmp_path / "skin.npz"

    def save(weights):
        np.savez(skin, vertices=body.vertices, faces=body.faces, joint_names=np.array(body.joint_names),
                 joints=body.joints, weights=weights)

    save(body.weights)
    out = tmp_path / "out"
    assert command("batch", folder, out, "--skin", skin, "-q").returncode == 0

    def status():
        done = command("batch", folder, out, "--skin", skin, "--resume", "--json")
        assert done.returncode == 0, done.stderr
        return json.loads(done.stdout)["status"]

    assert status() == "skipped"
    save(body.weights[:, ::-1].copy())  # other weights, same file name
    assert status() == "converted"


def test_an_output_folder_inside_the_input_folder_never_replaces_a_clip(tmp_path):
    """batch lib lib/sub --overwrite once replaced lib/sub/run.bvh (a clip) by the output of lib/run.bvh."""
    folder = tmp_path / "lib"
    (folder / "sub").mkdir(parents=True)
    shutil.copy(RUN, folder / "run.bvh")
    shutil.copy(JUMP, folder / "sub" / "run.bvh")  # another clip, under the output's name
    before = (folder / "sub" / "run.bvh").read_bytes()
    for extra in ([], ["--overwrite"], ["--resume"]):
        done = command("batch", folder, folder / "sub", "--no-glb", *extra)
        assert done.returncode == 2 and "holds clips" in done.stderr, done.stderr
    assert (folder / "sub" / "run.bvh").read_bytes() == before
    # An output folder of our own inside the input folder is fine, run after run: its BVHs are
    # known by the manifests beside them and not taken for clips.
    for _ in range(2):
        done = command("batch", folder, folder / "out", "--no-glb", "--overwrite", "--json")
        assert done.returncode == 0, done.stderr
        assert sorted(Path(json.loads(line)["input"]).relative_to(folder).as_posix()
                      for line in done.stdout.splitlines()) == ["run.bvh", "sub/run.bvh"]
    # The input folder inside the output folder: a clip whose outputs would land on another clip fails alone.
    nested = tmp_path / "deep"
    (nested / "a" / "a").mkdir(parents=True)
    shutil.copy(RUN, nested / "a" / "x.bvh")
    shutil.copy(JUMP, nested / "a" / "a" / "x.bvh")
    kept = (nested / "a" / "x.bvh").read_bytes()
    done = command("batch", nested / "a", nested, "--no-glb", "--overwrite")
    assert done.returncode == 1 and "would replace the input" in done.stderr, done.stderr
    assert (nested / "a" / "x.bvh").read_bytes() == kept


def test_a_clip_beside_the_input_folder_is_never_written_over(tmp_path):
    """``batch in . --overwrite`` beside ``run.bvh``, a capture of the same name as ``in/run.bvh``, replaced
    the capture. A BVH with no manifest of ours and none of a set's other files beside it is a clip: that
    clip fails alone, the rest convert; a set of ours (or one a kill cut short) is replaced as ever."""
    (tmp_path / "in").mkdir()
    shutil.copy(RUN, tmp_path / "in" / "run.bvh")
    shutil.copy(JUMP, tmp_path / "in" / "jump.bvh")
    shutil.copy(SIT, tmp_path / "run.bvh")  # the capture
    (tmp_path / "run.glb").write_bytes(b"glTF")  # and another tool's export of it: not a set of ours
    for extra in ([], ["--overwrite"], ["--resume"]):
        done = command("-q", "batch", "in", ".", "--no-glb", "--json", *extra, cwd=tmp_path)
        assert done.returncode == 1, done.stderr
        statuses = {Path(json.loads(line)["input"]).stem: json.loads(line) for line in done.stdout.splitlines()}
        assert "would replace run.bvh, a clip this tool did not write" in statuses["run"]["error"]
        assert statuses["jump"]["status"] in ("converted", "skipped")
        assert (tmp_path / "run.bvh").read_bytes() == SIT.read_bytes()
    # A set a kill cut short between its renames (its BVH, no manifest yet, its pipeline file beside it).
    (tmp_path / "jump.json").unlink()
    assert (tmp_path / "jump.pipeline.toml").is_file()
    done = command("batch", "in", ".", "--no-glb", "--overwrite", "--glob", "jump.bvh", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert check_output_set(tmp_path / "jump.json") == []


@pytest.mark.parametrize("reaped", [True, False], ids=["reaped first", "read first"])
def test_a_killed_batch_leaves_no_worker_behind(tmp_path, reaped):
    folder = copies(tmp_path, 8)
    out = tmp_path / "out"
    process = subprocess.Popen([sys.executable, "-m", "mocap_exaggerate_cli.main", "-q", "batch", folder, out,
                                "-j", "2"], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                               start_new_session=True)
    deadline = time.monotonic() + 120
    while not list(out.glob("*.json")) and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.02)
    os.kill(process.pid, signal.SIGKILL)  # the batch alone, as a crash would
    start = time.monotonic()
    if reaped:
        process.wait(timeout=60)
        # The workers notice and end: whoever reads the batch's output (| tee log) sees its end.
        assert process.stdout.read() == b""
    else:  # read to the end before reaping it (subprocess.run, $(...)): the batch a zombie meanwhile, which
        # still takes signals; the workers held its pipes for ever
        assert process.communicate(timeout=30)[0] == b""
    assert time.monotonic() - start < 20


def test_empty_and_unwritable_output_folders_are_refused_before_any_work(tmp_path):
    folder = copies(tmp_path, 1)
    for args in (["batch", folder, ""], ["exaggerate", RUN, "-o", ""]):
        done = command(*args, cwd=tmp_path)
        assert done.returncode == 2 and "is empty" in done.stderr, done.stderr
    blocked = tmp_path / "file"
    blocked.write_text("x")
    done = command("batch", folder, blocked / "out")
    assert done.returncode == 2 and "cannot write there" in done.stderr and "Traceback" not in done.stderr, done.stderr
