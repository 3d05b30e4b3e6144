"""How fast does a whole folder convert, serially and in a pool of worker processes?

Copies every shared clip (or the shipped samples, without ../shared) ``--copies``
times into a folder, runs ``mocap-exaggerate batch`` on it as a user would (a new
process, ``--json``), serially (``-j 1``) and with ``-j 2`` (or ``--jobs``), and
prints files/s, frames/s, the speed-up, and the overhead: wall time a file costs
beyond its own conversion (worker start-up and imports, handing work out, reporting),
``(wall x workers - sum of per-file seconds) / files``. ``--dask`` adds a run on a Dask
LocalCluster of as many workers (its start included) and one on as many standing workers
(``dask scheduler`` and ``dask worker`` with their defaults, up before the batch), each
with its wall time against the pool's; ``--report`` draws the report's pictures in every run.

It also prints the machine's own ceiling: the same conversions run in one process
alone, then in ``--jobs`` independent processes at once (no pool, no hand-out, nothing
shared). On a virtual machine two "cores" may not give two cores' work; the pool's
speed-up is to be read against that.

Not a test: run it by hand (``python bench/batch.py``) and quote the figures.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import FPS, ROOT, SHARED


def clips() -> list[Path]:
    shared = sorted(SHARED.glob("*.bvh")) if SHARED.is_dir() else []
    # A clip whose header lies about its frame rate would need --fps of its own: left out.
    shared = [p for p in shared if p.name not in FPS]
    return shared or sorted((ROOT / "sample_data").glob("*.bvh"))


def run(folder: Path, out: Path, jobs: int | None, extra: list[str]) -> tuple[float, list[dict]]:
    """Wall seconds and the --json lines of one batch (``jobs`` None: the scheduler's workers)."""
    start = time.perf_counter()
    size = [] if jobs is None else ["-j", str(jobs)]
    done = subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", "-q", "batch", str(folder), str(out),
                           *size, "--json", *extra], capture_output=True, text=True)
    if done.returncode != 0 and "--scheduler" in extra:
        sys.exit(f"batch {' '.join(extra)}: {done.stderr.strip()}")
    wall = time.perf_counter() - start
    if done.returncode != 0:
        sys.exit(f"batch -j {jobs} failed ({done.returncode}): {done.stderr.strip()}")
    return wall, [json.loads(line) for line in done.stdout.splitlines()]


_SOLO = """
import sys, tempfile, time
from mocap_exaggerate.jobs.job import convert
clips = sys.argv[1:]
with tempfile.TemporaryDirectory() as out:
    convert(clips[0], out, overwrite=True)  # warm
    start = time.perf_counter()
    for clip in clips:
        convert(clip, out, overwrite=True)
    print(time.perf_counter() - start)
"""


def ceiling(clips: list[Path], jobs: int, rounds: int = 3) -> tuple[float, float, float]:
    """Seconds for ``clips`` converted in one process alone, and in ``jobs`` processes at once
    (each converting all of them); the speed-up those ``jobs`` processes give (best of ``rounds``)."""
    command = [sys.executable, "-c", _SOLO, *map(str, clips)]
    alone, together = [], []
    for _ in range(rounds):
        alone.append(float(subprocess.run(command, capture_output=True, text=True, check=True).stdout))
        running = [subprocess.Popen(command, stdout=subprocess.PIPE, text=True) for _ in range(jobs)]
        together.append(max(float(p.communicate()[0]) for p in running))
    best_alone, best_together = min(alone), min(together)
    return best_alone, best_together, jobs * best_alone / best_together


_STANDING: list[subprocess.Popen] = []


def standing_cluster(jobs: int) -> str:
    """A scheduler and ``jobs`` one-thread workers started as a user starts them (``dask scheduler``, ``dask
    worker``, the nanny's defaults), already up when the batch starts (they are ended at exit): its address."""
    import atexit
    import socket

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    _STANDING.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                                       "--port", str(port), "--dashboard-address", ":0"], **quiet))
    _STANDING.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nworkers",
                                       str(jobs), "--nthreads", "1"], **quiet))
    atexit.register(lambda: [p.terminate() for p in _STANDING])
    from distributed import Client

    with Client(address, timeout=30) as client:
        client.wait_for_workers(jobs, timeout=60)
    return address


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--copies", type=int, default=2, help="copies of each clip (default 2)")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--no-glb", action="store_true", help="BVH and manifest only")
    parser.add_argument("--dask", action="store_true", help="also on a Dask LocalCluster of --jobs workers, and on "
                        "--jobs standing workers (dask scheduler and dask worker, started before the batch)")
    parser.add_argument("--report", action="store_true", help="with --report (the pictures of every clip)")
    parser.add_argument("--no-ceiling", action="store_true", help="skip measuring the machine's own speed-up")
    args = parser.parse_args()
    extra = (["--no-glb"] if args.no_glb else []) + (["--report"] if args.report else [])
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "in"
        for k in range(args.copies):
            (folder / f"copy{k}").mkdir(parents=True)
            for clip in clips():
                shutil.copy(clip, folder / f"copy{k}" / clip.name)
        files = sum(1 for _ in folder.rglob("*.bvh"))
        rows = []
        runs = [("serial", 1, []), ("pool", args.jobs, [])]
        if args.dask:
            runs.append(("Dask LocalCluster", args.jobs, ["--scheduler", "local"]))
            runs.append(("Dask, standing workers", args.jobs, ["--scheduler", standing_cluster(args.jobs)]))
        for engine, jobs, more in runs:
            out = Path(tmp) / f"out-{engine.split()[0]}"
            wall, results = run(folder, out, None if "tcp" in " ".join(more) else jobs, extra + more)
            frames = sum(r["frames"] or 0 for r in results)
            inside = sum(r["seconds"] for r in results)
            rows.append((engine, jobs, wall, frames, inside, out))
        print(f"{files} files ({args.copies} copies of {files // args.copies} clips), "
              f"{'BVH only' if args.no_glb else 'BVH + GLB'}{', with --report' if args.report else ''}, "
              f"on {Path(tmp)}\n")
        print("| engine | workers | wall (s) | files/s | frames/s | speed-up | overhead per file (s) |")
        print("|---|---|---|---|---|---|---|")
        serial = rows[0][2]
        for engine, jobs, wall, frames, inside, _ in rows:
            overhead = (wall * jobs - inside) / files
            print(f"| {engine} | {jobs} | {wall:.2f} | {files / wall:.2f} | {frames / wall:,.0f} | {serial / wall:.2f}x "
                  f"| {overhead:.3f} |")
        pool = rows[1][2]
        for engine, _, wall, *_ in rows[2:]:
            print(f"\n{engine}: {wall / pool:.2f}x the pool's wall time")
        first = rows[0][5]
        for engine, *_, out in rows[1:]:
            same = all((first / p.relative_to(first)).read_bytes() == (out / p.relative_to(first)).read_bytes()
                       for p in first.rglob("*") if p.is_file() and p.suffix != ".json")
            print(f"\noutputs byte-identical serial vs {engine} (manifests aside, whose timings differ): {same}")
        if not args.no_ceiling:
            alone, together, speedup = ceiling(clips(), args.jobs)
            print(f"\nthis machine's ceiling: the {files // args.copies} clips in one process {alone:.2f} s; in "
                  f"{args.jobs} processes at once (each all of them) {together:.2f} s: {speedup:.2f}x")


if __name__ == "__main__":
    main()
