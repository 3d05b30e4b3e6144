"""How fast are the pictures? Wall time of previews and compare grids, as users run them.

Prints, best of ``--repeat`` runs each, the whole command in a fresh process (`mocap-exaggerate
preview` / `compare`: start-up, reading, the pipeline, posing, drawing, writing), on:

- the shipped 15 s sit-down clip (30 fps; an animation shows its first 10 s) and the shared laugh
  (120 fps) cut to its first 10 s (1,200 frames), with the default body and, where ../shared is
  beside the checkout, the MakeHuman body (``--skin``);
- a PNG of five still frames, a 10 s GIF (20 fps: 200 pictures at 120 fps), and a 3x3 compare grid
  (``--sigma 0.1s,0.2s,0.3s --omega 2,4,6``) as a PNG and as a 10 s GIF;
- the size of each picture in pixels, so that a faster picture is not a smaller one;
- ``tune`` on the laugh's first 1,000 frames: the round trip of one slider change, from the request
  to the new GLB received (HTTP, best of 5), and, where Chromium and Playwright are, in the page: from
  the slider's change to the new motion shown.

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
    folder = tempfile.mkdtemp(prefix="bench-preview-")
    clips = [(SIT, None)]
    if LAUGH.exists():
        clips.append((first_frames(LAUGH, 1200, Path(folder) / "laugh_10s.bvh"), None))
    if MAKEHUMAN.exists():
        clips.append((SIT, MAKEHUMAN))
    print("| clip | body | picture | seconds | size |")
    print("|---|---|---|---|---|")
    if True:
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


    if LAUGH.exists():
        tuner_round_trip(first_frames(LAUGH, 1000, Path(folder) / "laugh_1000.bvh"))


def first_frames(path: Path, count: int, target: Path) -> Path:
    """The clip's first ``count`` frames as a BVH of their own."""
    head, motion = path.read_text().split("MOTION\n", 1)
    lines = motion.splitlines()
    target.write_text(head + f"MOTION\nFrames: {count}\n{lines[1]}\n" + "\n".join(lines[2:2 + count]) + "\n")
    return target


def tuner_round_trip(clip: Path) -> None:
    import json
    import re
    import signal
    import urllib.request

    server = subprocess.Popen(TOOL + ["tune", str(clip)], stderr=subprocess.PIPE, text=True)
    try:
        url = re.search(r"(http://127\.0\.0\.1:\d+/)", server.stderr.readline()).group(1)
        best = float("inf")
        for omega in (3, 4, 5, 6, 7):
            body = json.dumps({"preset": "cartoon", "settings": {"extrapolate.omega": omega}}).encode()
            start = time.perf_counter()
            request = urllib.request.Request(url + "run", data=body, method="POST",
                                             headers={"Content-Type": "application/json"})
            with urllib.request.urlopen(request) as answer:
                took = json.loads(answer.read())["seconds"]
            best = min(best, time.perf_counter() - start)
        print(f"\ntune, {clip.stem} (1,000 frames): a slider change to its new GLB over HTTP {best:.2f} s "
              f"(the run itself {took:.2f} s)")
        try:
            from playwright.sync_api import sync_playwright
        except ImportError:
            return
        import shutil

        browser_path = shutil.which("chromium") or shutil.which("chromium-browser")
        if browser_path is None:
            return
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=browser_path, args=[
                "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist"])
            page = browser.new_page(viewport={"width": 1200, "height": 700})
            page.goto(url)
            page.wait_for_function("window.player && window.player.ready", timeout=60_000)
            page.evaluate("player.pause()")
            times = []
            for omega in ("3", "5", "7", "4", "6", "8"):
                # In the page: the slider moved as a hand moves it, until the new motion is shown.
                times.append(page.evaluate("""(value) => new Promise((done) => {
                    const slider = document.querySelector("#settings input[data-key='extrapolate.omega']");
                    const before = player.tuned, start = performance.now();
                    slider.value = value;
                    slider.dispatchEvent(new Event('input', {bubbles: true}));
                    const wait = () => player.tuned > before ? done((performance.now() - start) / 1000)
                                                             : setTimeout(wait, 2);
                    wait();
                })""", omega))
            browser.close()
        print(f"in Chromium (software WebGL), from the slider's change to the new motion shown: best "
              f"{min(times):.2f} s (median {sorted(times)[len(times) // 2]:.2f} s), of which 0.03 s the page gathers a burst")
    finally:
        server.send_signal(signal.SIGINT)
        server.wait(timeout=30)


if __name__ == "__main__":
    main()
