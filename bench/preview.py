"""How fast are the pictures? Wall time of previews and compare grids, as users run them.

Prints, best of ``--repeat`` runs each, the whole command in a fresh process (`mocap-exaggerate
preview` / `compare`: start-up, reading, the pipeline, posing, drawing, writing), on:

- the shipped 15 s sit-down clip (30 fps) and the shared 23 s laugh (120 fps), both cut to 10 s
  (the animation's default), with the default body and, where ../shared is beside the checkout, the
  MakeHuman body (``--skin``);
- a PNG of five still frames, a 10 s GIF (20 fps: 200 pictures at 120 fps), and a 3x3 compare grid
  (``--sigma 0.1s,0.2s,0.3s --omega 2,4,6``) as a PNG and as a 10 s GIF;
- the size of each picture in pixels, so that a faster picture is not a smaller one.

Issue 27's bounds on this machine (2 cores): a 10 s GIF in at most 3 s, a PNG in at most 1 s, a 3x3
grid of a 10 s clip in at most 10 s. Not a test: run it by hand (``python bench/preview.py``) and
quote the figures.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SHARED = ROOT.parent / "shared" / "data"
SIT = ROOT / "sample_data" / "mocapbank_sit_down_stand_up.bvh"
LAUGH = SHARED / "bvh" / "cmu_14_19_laugh_idle_daz.bvh"
MAKEHUMAN = SHARED / "skin" / "makehuman_base.obj"
TOOL = [sys.executable, "-c", "from mocap_exaggerate_cli.main import main; main()"]


def timed(args: list[str], repeat: int) -> float:
    """The best wall time of ``repeat`` runs of the command (its exit code checked)."""
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        done = subprocess.run(TOOL + args, capture_output=True, text=True, env={**os.environ, "PYTHONHASHSEED": "0"})
        best = min(best, time.perf_counter() - start)
        if done.returncode != 0:
            raise SystemExit(f"{' '.join(args)}: exit {done.returncode}: {done.stderr.strip()}")
    return best


def size(path: Path) -> str:
    from PIL import Image

    with Image.open(path) as picture:
        return f"{picture.width}x{picture.height}, {getattr(picture, 'n_frames', 1)} picture(s)"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--no-compare", action="store_true", help="only the previews (before `compare` existed)")
    args = parser.parse_args()
    clips = [(SIT, None)]
    if LAUGH.exists():
        clips.append((LAUGH, None))
    if MAKEHUMAN.exists():
        clips.append((SIT, MAKEHUMAN))
    print("| clip | body | picture | seconds | size |")
    print("|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as folder:
        for clip, skin in clips:
            body = ["--skin", str(skin)] if skin else []
            cases = [("PNG, 5 frames", "preview", "png", []), ("GIF, 10 s", "preview", "gif", [])]
            if not args.no_compare:
                grid = ["--sigma", "0.1s,0.2s,0.3s", "--omega", "2,4,6"]
                cases += [("3x3 grid, PNG", "compare", "png", grid), ("3x3 grid, GIF 10 s", "compare", "gif", grid)]
            for name, command, suffix, more in cases:
                target = Path(folder) / f"{clip.stem}-{command}.{suffix}"
                seconds = timed([command, str(clip), "-o", str(target), "--overwrite", *body, *more], args.repeat)
                print(f"| {clip.stem} | {'MakeHuman' if skin else 'default'} | {name} | {seconds:.2f} | "
                      f"{size(target)} |", flush=True)


if __name__ == "__main__":
    main()
