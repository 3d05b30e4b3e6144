"""Throughput of read / stages / write, against bvhio's read of the same file.

Prints figures for the longest shared clip and for a 10k-frame clip made by
tiling it. Not a test: run it by hand (python bench/throughput.py) and quote
the figures.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from mocap_exaggerate.config import load_preset, resolve_config
from mocap_exaggerate.io.bvh import format_bvh, read_bvh
from mocap_exaggerate.pipeline import run
from mocap_exaggerate.stages.subjoints import SubjointConfig, build_hierarchy

ROOT = Path(__file__).resolve().parent.parent
SHARED = ROOT.parent / "shared" / "data" / "bvh"


def longest_clip() -> Path:
    clips = sorted(SHARED.glob("*.bvh")) or sorted((ROOT / "sample_data").glob("*.bvh"))
    return max(clips, key=lambda p: read_bvh(p)[0].num_frames)


def tiled(path: Path, frames: int, folder: Path) -> Path:
    """The clip's motion lines repeated until ``frames`` lines, as a new BVH file."""
    data = path.read_bytes()
    motion, _ = read_bvh(data)
    head, _, body = data.partition(b"MOTION")
    lines = [line for line in body.splitlines()[3:] if line.strip()][: motion.num_frames]
    rows = (lines * (frames // len(lines) + 1))[:frames]
    frame_time = np.format_float_positional(motion.frame_time, trim="-")
    out = folder / f"tiled_{frames}.bvh"
    out.write_bytes(head + f"MOTION\nFrames: {frames}\nFrame Time: {frame_time}\n".encode() + b"\n".join(rows) + b"\n")
    return out


def best_of(func, repeat: int = 3) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        func()
        times.append(time.perf_counter() - start)
    return min(times)


def measure(path: Path, preset: str, repeat: int, with_bvhio: bool) -> None:
    motion, _ = read_bvh(path)
    frames, joints = motion.num_frames, motion.skeleton.num_joints
    config = load_preset(preset)
    t_read = best_of(lambda: read_bvh(path), repeat)
    result = run(motion, config)
    t_stages = best_of(lambda: run(motion, config), repeat)
    t_write = best_of(lambda: format_bvh(result.motion), repeat)
    with tempfile.TemporaryDirectory() as tmp:
        command = [sys.executable, "-m", "mocap_exaggerate_cli.main", "-q", "exaggerate", str(path), "-o", tmp, "--overwrite",
                   "--preset", preset]
        t_command = best_of(lambda: subprocess.run(command, check=True, cwd=ROOT), repeat)
    print(f"{path.name}: {frames} frames, {joints} joints, preset {preset}")
    print(f"  read      {t_read * 1e3:8.1f} ms  {frames / t_read:10.0f} frames/s")
    for name, seconds in result.timings.items():
        print(f"    {name:<18}{seconds * 1e3:8.1f} ms")
    print(f"  stages    {t_stages * 1e3:8.1f} ms  {frames / t_stages:10.0f} frames/s  "
          f"({t_stages / frames * 1e3:.4f} ms per frame)")
    print(f"  write     {t_write * 1e3:8.1f} ms  {frames / t_write:10.0f} frames/s")
    print(f"  in memory {(t_read + t_stages + t_write) * 1e3:8.1f} ms (read + stages + write)")
    print(f"  command   {t_command * 1e3:8.1f} ms  (mocap-exaggerate exaggerate, new process, imports included)")
    if with_bvhio:
        import bvhio

        start = time.perf_counter()
        bvhio.readAsHierarchy(str(path))
        t_bvhio = time.perf_counter() - start
        print(f"  bvhio readAsHierarchy {t_bvhio * 1e3:8.1f} ms: our read is {t_bvhio / t_read:.0f}x faster; "
              f"the whole command takes {t_command / t_bvhio:.3f} of bvhio's read (target <= 0.1)")


#: Kwon & Lee 2008, Table 1: ms per frame for 23 joints -> 58 sub-joints on a 2.13 GHz Core2.
PAPER_MS_PER_FRAME = {"Walk": 11.76, "Run": 5.82, "Kick": 12.80, "Cossack": 11.71}
PAPER_SUBJOINTS = 58


def compare_with_paper(path: Path, repeat: int) -> None:
    """The whole in-memory pipeline at the paper's sub-joint count, per frame."""
    motion, _ = read_bvh(path)
    per_link = min(range(1, 9), key=lambda k: abs(
        build_hierarchy(motion.skeleton, SubjointConfig(per_link=k)).skeleton.num_joints - PAPER_SUBJOINTS))
    config = resolve_config("cartoon", None, {"subjoints": {"per_link": per_link}})
    result = run(motion, config)  # also compiles or loads the spring kernel
    seconds = best_of(lambda: run(motion, config), repeat)
    per_frame = seconds / motion.num_frames * 1e3
    joints = result.motion.skeleton.num_joints
    print(f"paper comparison on {path.name}: {motion.skeleton.num_joints} joints -> {joints} sub-joints "
          f"(per_link={per_link}), {result.substeps} spring substep(s) per frame")
    for name, value in result.timings.items():
        print(f"    {name:<18}{value / motion.num_frames * 1e3:8.4f} ms per frame")
    print(f"  whole pipeline  {per_frame:.4f} ms per frame")
    for take, paper in PAPER_MS_PER_FRAME.items():
        print(f"    vs paper {take:<8} {paper:6.2f} ms per frame: {paper / per_frame:6.0f}x faster")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="cartoon")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--frames", type=int, default=10_000, help="length of the tiled clip")
    parser.add_argument("--no-bvhio", action="store_true", help="skip bvhio (slow: ~25 s on 10k frames)")
    args = parser.parse_args()
    clip = longest_clip()
    compare_with_paper(clip, args.repeat)
    measure(clip, args.preset, args.repeat, not args.no_bvhio)
    with tempfile.TemporaryDirectory() as tmp:
        measure(tiled(clip, args.frames, Path(tmp)), args.preset, args.repeat, not args.no_bvhio)


if __name__ == "__main__":
    main()
