"""A batch when something under it fails: a worker process killed mid-clip, a Dask worker lost, a
second Ctrl-C, a report picture that cannot be drawn.

Run the way users run them (a real process, its exit code and stderr, the files it leaves), and
the failures are real too: the worker is found under the batch by the temporary output it has
open and killed with SIGKILL, as the kernel's out-of-memory killer would.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from importlib.util import find_spec
from pathlib import Path

import pytest

from mocap_exaggerate.jobs.job import check_output_set

from .helpers import ended
from .test_batch import JUMP, RUN, SIT, expected_outputs, files_under
from .test_interrupted import long_clip

needs_proc = pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="finds the worker through /proc (Linux)")
needs_dask = pytest.mark.skipif(find_spec("distributed") is None,
                                reason="Dask distributed is not installed (pip install 'mocap-exaggerate[dask]')")


def batch(*args) -> list[str]:
    return [sys.executable, "-m", "mocap_exaggerate_cli.main", *map(str, args)]


def descendants(pid: int) -> list[int]:
    """The processes below ``pid`` (its children, theirs, ...), read from /proc."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:  # gone meanwhile
            continue
        parent = int(stat.rsplit(")", 1)[1].split()[1])  # the name in brackets may hold spaces
        children.setdefault(parent, []).append(int(entry.name))
    found, todo = [], [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            found.append(child)
            todo.append(child)
    return found


def writer_of(stem: str, under: int, batch_process: subprocess.Popen, timeout: float = 120.0) -> int:
    """The pid of the process below ``under`` that has a temporary output of clip ``stem`` open
    (``.<stem>.bvh.<random>.tmp``): the worker converting that clip, caught while it writes."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and batch_process.poll() is None:
        for pid in descendants(under):
            try:
                names = [os.path.basename(os.readlink(f"/proc/{pid}/fd/{fd}")) for fd in os.listdir(f"/proc/{pid}/fd")]
            except OSError:
                continue
            if any(name.startswith(f".{stem}.") and name.endswith(".tmp") for name in names):
                return pid
        time.sleep(0.005)
    raise AssertionError(f"no process was seen writing {stem}'s outputs")


@needs_proc
def test_a_worker_killed_mid_clip_fails_that_clip_alone(tmp_path):
    folder = tmp_path / "mocap"
    folder.mkdir()
    for clip in (RUN, SIT, JUMP):
        shutil.copy(clip, folder / clip.name)
    # The two long clips go first, one to each worker; "other" is a little longer, so that it is
    # still being converted when the worker writing "long" dies, and the short ones are queued.
    long_clip(folder, frames=7000).rename(folder / "other.bvh")
    long_clip(folder, frames=6000)
    out = tmp_path / "out"
    process = subprocess.Popen(batch("-q", "batch", folder, out, "-j", "2", "--json"), stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    os.kill(writer_of("long", process.pid, process), signal.SIGKILL)
    stdout, stderr = process.communicate(timeout=300)

    statuses = _one_failure(process, stdout, stderr, f"failed: {folder / 'long.bvh'}: its worker process died")
    assert statuses == {"long": "failed", "other": "converted", RUN.stem: "converted", SIT.stem: "converted",
                        JUMP.stem: "converted"}
    # The others' outputs whole; of the killed clip's, nothing: not even the temporaries it was writing.
    assert files_under(out) == expected_outputs("other", RUN.stem, SIT.stem, JUMP.stem)
    assert all(check_output_set(manifest) == [] for manifest in out.glob("*.json"))


def _hears_ctrl_c() -> None:
    """Ctrl-C at its default in the child, as in a terminal (a background shell ignores it)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@needs_proc
def test_a_second_ctrl_c_ends_the_workers_at_once_and_leaves_no_temporaries(tmp_path):
    folder = tmp_path / "mocap"
    folder.mkdir()
    for name in ("a", "b", "c"):
        long_clip(folder, frames=12000).rename(folder / f"{name}.bvh")
    out = tmp_path / "out"
    process = subprocess.Popen(batch("batch", folder, out, "-j", "2"), stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE, text=True, start_new_session=True, preexec_fn=_hears_ctrl_c)
    writer_of("a", process.pid, process)  # the workers are in the middle of clips
    below = descendants(process.pid)
    os.killpg(process.pid, signal.SIGINT)
    time.sleep(0.2)  # two at once would be heard as one
    os.killpg(process.pid, signal.SIGINT)
    _, stderr = process.communicate(timeout=120)

    assert process.returncode == 130, stderr
    assert len(list(out.glob("*.json"))) < 2, "the clips in hand should have been ended, not finished"
    assert "Traceback" not in stderr and "not done" in stderr and "--resume" in stderr, stderr
    assert not [name for name in files_under(out) if name.endswith(".tmp")]
    assert all(check_output_set(manifest) == [] for manifest in out.glob("*.json"))
    assert all(ended(pid) for pid in below)  # the forkserver and the workers too


@needs_proc
@needs_dask
def test_a_dask_worker_lost_mid_clip_fails_that_clip_and_the_rest_go_on(tmp_path):
    import dask
    from distributed import LocalCluster

    folder = tmp_path / "mocap"
    folder.mkdir()
    shutil.copy(RUN, folder / RUN.name)
    long_clip(folder, frames=6000)
    out = tmp_path / "out"
    # No second try for a task whose worker died (a clip that kills workers would kill them all);
    # two workers, so that the other clip is not waiting on the one that dies (it would fail too).
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}), \
            LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        process = subprocess.Popen(batch("-q", "batch", folder, out, "--scheduler", cluster.scheduler_address,
                                         "--json"), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        os.kill(writer_of("long", os.getpid(), process), signal.SIGKILL)  # the cluster's workers run under this test
        stdout, stderr = process.communicate(timeout=300)

    statuses = _one_failure(process, stdout, stderr, f"failed: {folder / 'long.bvh'}: its Dask task failed: KilledWorker")
    assert statuses == {"long": "failed", RUN.stem: "converted"}
    assert files_under(out) == expected_outputs(RUN.stem)


@needs_proc
@needs_dask
def test_a_scheduler_lost_mid_batch_is_one_line_and_resume_finishes_the_rest(tmp_path):
    """The scheduler killed while a clip converts, then its worker: the batch says so in one line (Dask's
    client printed the traceback of its reconnecting), exit 1, and ``--resume`` converts what was not done
    and clears what the killed worker was writing."""
    import socket

    folder = tmp_path / "mocap"
    folder.mkdir()
    shutil.copy(RUN, folder / RUN.name)
    long_clip(folder, frames=6000)
    out = tmp_path / "out"
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        address = f"tcp://127.0.0.1:{probe.getsockname()[1]}"
    dask = [sys.executable, "-m"]
    scheduler = subprocess.Popen([*dask, "distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port",
                                  address.rsplit(":", 1)[1], "--no-dashboard"], stderr=subprocess.DEVNULL,
                                 start_new_session=True)
    worker = subprocess.Popen([*dask, "distributed.cli.dask_worker", address, "--nthreads", "1", "--no-dashboard"],
                              stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 60  # the scheduler listening before the batch asks (a refusal is exit 2)
        while True:
            try:
                socket.create_connection(("127.0.0.1", int(address.rsplit(":", 1)[1])), timeout=1).close()
                break
            except OSError:
                assert time.monotonic() < deadline and scheduler.poll() is None, "the scheduler did not start"
                time.sleep(0.05)
        process = subprocess.Popen(batch("-q", "batch", folder, out, "--scheduler", address, "--json"),
                                   stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        writer_of("long", worker.pid, process)
        scheduler.kill()
        stdout, stderr = process.communicate(timeout=300)
    finally:
        for started in (scheduler, worker):
            os.killpg(started.pid, signal.SIGKILL)
            started.wait()

    assert process.returncode == 1, stderr
    assert stderr.splitlines() == [f"ERROR: lost the Dask scheduler at {address}; 2 file(s) not done "
                                   "(--resume finishes them)"], stderr

    done = subprocess.run(batch("batch", folder, out, "--resume", "--json"), capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    statuses = {Path(json.loads(line)["input"]).stem: json.loads(line)["status"] for line in done.stdout.splitlines()}
    assert statuses[RUN.stem] == "converted" and statuses["long"] in ("converted", "skipped"), statuses  # (done by then)
    assert files_under(out) == expected_outputs(RUN.stem, "long")
    assert all(check_output_set(manifest) == [] for manifest in out.glob("*.json"))


def test_a_report_picture_that_cannot_be_drawn_is_a_warning_and_the_report_is_written(tmp_path):
    folder = tmp_path / "mocap"
    (folder / "walks").mkdir(parents=True)
    shutil.copy(RUN, folder / "walks" / "run.bvh")
    shutil.copy(JUMP, folder / "jump.bvh")
    out = tmp_path / "out"
    (out / "report").mkdir(parents=True)
    (out / "report" / "walks").write_text("a file where the pictures of walks/ would go")

    done = subprocess.run(batch("batch", folder, out, "--report", "--no-glb"), capture_output=True, text=True,
                          timeout=300)

    assert done.returncode == 0, done.stderr  # the outputs are written and sound: the clip converted
    warnings = [line for line in done.stderr.splitlines() if line.startswith("warning:")]
    picture = out / "report" / "walks" / "run.preview.png"
    assert warnings == [f"warning: {folder / 'walks' / 'run.bvh'}: no report pictures: {picture}: File exists"], \
        done.stderr
    assert "Traceback" not in done.stderr
    page = (out / "index.html").read_text()
    assert f"report: {out / 'index.html'}" in done.stderr
    assert page.count("no pictures") == 1 and page.count('class="preview"') == 1  # jump's are drawn, run's said missing
    assert (out / "report" / "jump.preview.png").is_file()
    assert check_output_set(out / "walks" / "run.json") == []


def _one_failure(process, stdout: str, stderr: str, said: str) -> dict[str, str]:
    """Exit 1 with one line on stderr starting with ``said``, no traceback; each clip's status by its stem."""
    assert process.returncode == 1, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in stderr, stderr
    assert lines[0].startswith(said), lines[0]
    return {Path(json.loads(line)["input"]).stem: json.loads(line)["status"] for line in stdout.splitlines()}
