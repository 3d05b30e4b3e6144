"""Memory per frame: what each stage holds, and the whole command's peak, on long clips.

Prints, for the shared cmu_01_01 clip's motion lines tiled to each ``--frames`` length
(cartoon preset, every default output):

- per stage, Python's traced memory (tracemalloc: NumPy's arrays are traced) when the stage
  starts, at its peak and when it ends, in kB per frame;
- the job's traced peak (``convert``: the pipeline, the BVH, GLB and weights written);
- the command's peak resident memory (a process, ``ru_maxrss``), in MB and kB per frame.

The traced figures are what the code keeps alive (deterministic from run to run); the resident
peak adds the interpreter, the libraries and how glibc's heap lays out freed blocks. Issue 28 asks
for at most 5 kB a frame at 100,000 frames. Not a test: run it by hand (``python bench/memory.py
--frames 30000 100000``) and quote the figures.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import shutil
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from command import CLI, SHARED, tiled  # noqa: E402


def traced(path: Path, folder: Path, frames: int) -> None:
    """The stages' traced memory and the job's traced peak, in this process."""
    import mocap_exaggerate.pipeline as pipeline
    from mocap_exaggerate.jobs.job import convert

    rows = []

    def watched(stage):
        def apply(state, settings):
            start = tracemalloc.get_traced_memory()[0]
            tracemalloc.reset_peak()
            after = stage.apply(state, settings)
            end, peak = tracemalloc.get_traced_memory()
            rows.append((stage.name, start, peak, end))
            return after

        return dataclasses.replace(stage, apply=apply)

    stages = tuple(watched(stage) for stage in pipeline.STAGES)
    defaults = pipeline.run.__kwdefaults__
    saved = defaults["stages"]
    defaults["stages"] = stages  # (convert calls run with the default list)
    out = folder / "traced"
    try:
        tracemalloc.start()
        tick = time.perf_counter()
        convert(path, out)
        seconds = time.perf_counter() - tick
        _, whole = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    finally:
        defaults["stages"] = saved
        shutil.rmtree(out, ignore_errors=True)
    per = 1e3 * frames
    print(f"{frames} frames, traced (kB a frame)      at start    peak   at end")
    for name, start, peak, end in rows:
        print(f"  {name:<34} {start / per:8.2f} {peak / per:7.2f} {end / per:8.2f}")
    print(f"  the whole job (convert, traced)    peak {whole / per:.2f} kB a frame, {whole / 1e6:.0f} MB "
          f"({seconds:.1f} s under tracemalloc)")


def resident(path: Path, folder: Path, frames: int) -> None:
    """The command's peak resident memory, a process as users run it."""
    out = folder / "resident"
    tick = time.perf_counter()
    process = subprocess.Popen([*CLI, "exaggerate", str(path), "-o", str(out)], stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE)
    _, status, usage = os.wait4(process.pid, 0)
    seconds = time.perf_counter() - tick
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"failed: {process.stderr.read().decode()}")
    shutil.rmtree(out, ignore_errors=True)
    peak = usage.ru_maxrss * 1024.0
    print(f"{frames} frames: the command (a process)  peak RSS {peak / 1e6:.0f} MB, {peak / (1e3 * frames):.2f} kB a "
          f"frame, {seconds:.1f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, nargs="+", default=[10_000, 30_000],
                        help="clip lengths to measure, 2 to 500,000 frames (the reader's cap)")
    args = parser.parse_args()
    wrong = [n for n in args.frames if not 2 <= n <= 500_000]
    if wrong:  # (before any clip is tiled: one line, exit 2, nothing written)
        parser.error(f"--frames: {wrong[0]} is not between 2 and 500,000")
    source = SHARED / "cmu_01_01_forward_jumps.bvh"
    if not source.exists():
        raise SystemExit(f"needs the shared clips: {source} is missing")
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        for frames in args.frames:
            path = tiled(source, frames, folder)
            resident(path, folder, frames)  # (first: a child's peak counts the parent's pages until its exec)
            traced(path, folder, frames)
            path.unlink()


if __name__ == "__main__":
    main()
