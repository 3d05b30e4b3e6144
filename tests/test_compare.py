"""Issue 27, part 1: ``compare`` runs one clip with lists of settings and draws them side by side.

Run as users run it (a real process): the grid's pictures, its labels' figures, the command lines
it prints (each writes what its cell showed), one camera and one scale for every cell, and the
lists it refuses.
"""

from __future__ import annotations

import io
import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from mocap_exaggerate import load_bvh
from mocap_exaggerate.config import resolve_config
from mocap_exaggerate.viz.compare import Cell, render_grid_frames, run_cells

from .helpers import SAMPLE_DIR

RUN = SAMPLE_DIR / "cmu_09_01_run_daz.bvh"
TOOL = Path(sys.executable).with_name("mocap-exaggerate")
FAST = ["--subjoints", "2"]


def compare(*args, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([str(TOOL), "compare", *map(str, args)], capture_output=True, text=True, timeout=300, cwd=cwd,
                          env={**os.environ, "PYTHONHASHSEED": "0"})


def test_a_grid_png_has_every_cell_and_prints_each_cells_command(tmp_path):
    target = tmp_path / "grid.png"
    done = compare(RUN, "-o", target, "--sigma", "0.1s,0.3s", "--omega", "2,6", *FAST)
    assert done.returncode == 0, done.stderr
    commands = [line for line in done.stdout.splitlines() if line.startswith("mocap-exaggerate exaggerate")]
    figures = [line for line in done.stdout.splitlines() if line.startswith("# ")]
    assert len(commands) == 4 and len(figures) == 4
    assert figures[0].startswith("# sigma 0.1s, omega 2: stretch ") and "speed limit took" in figures[0]
    assert commands[3].endswith("--sigma 0.3s --omega 6 --subjoints 2")
    with Image.open(target) as picture:
        grid = np.asarray(picture.convert("RGB"))
    # Orange (exaggerated) in three rows below the grey (captured) one: the captured cell and 2 x 2 runs.
    orange = (grid[..., 0] > 200) & (grid[..., 1] > 90) & (grid[..., 1] < 190) & (grid[..., 2] < 120)
    grey = (np.abs(grid[..., 0].astype(int) - grid[..., 2]) < 12) & (grid[..., 0] > 120) & (grid[..., 0] < 215)
    rows = np.flatnonzero(orange.any(axis=1))
    assert grey[: rows.min()].sum() > 1000 and not orange[: rows.min()].any()
    assert len(np.flatnonzero(np.diff(rows) > 20)) == 1  # two rows of runs
    # Each printed command writes its cell's run: the same figures as the line above it says.
    words = shlex.split(commands[3])
    made = subprocess.run([str(TOOL), *words[1:3], "-o", str(tmp_path / "out"), *words[5:], "--no-glb", "-q"],
                          capture_output=True, text=True, env={**os.environ, "PYTHONHASHSEED": "0"})
    assert made.returncode == 0, made.stderr
    manifest = json.loads((tmp_path / "out" / f"{RUN.stem}.json").read_text())
    assert manifest["config"]["extrapolate"]["omega"] == 6 and manifest["config"]["extrapolate"]["sigma"] == "0.3s"
    again = tmp_path / "again.png"
    assert compare(RUN, "-o", again, "--sigma", "0.1s,0.3s", "--omega", "2,6", *FAST, "-q").returncode == 0
    assert again.read_bytes() == target.read_bytes()  # the same bytes twice


def test_a_cell_draws_the_same_pixels_wherever_it_sits_in_the_grid():
    # Two cells with the same settings written two ways draw the same pixels in their two places: the view
    # is the grid's, not the cell's position's (one camera and one scale: `render_grid_frames`).
    motion = load_bvh(RUN)
    config = resolve_config("cartoon", overrides={"subjoints": {"per_link": 2}})
    cells = [Cell("omega 4", ("--omega", "4"), config), Cell("omega 4.0", ("--omega", "4.0"), config)]
    ran = run_cells(motion, cells)
    picture = next(iter(render_grid_frames(motion, ran, np.array([70]), columns=2)))
    height = picture.shape[0]
    top = picture[: height // 2 - 20]
    left, right = (picture[height // 2 - 20: height - 20, : picture.shape[1] // 2 - 5],
                   picture[height // 2 - 20: height - 20, picture.shape[1] // 2 + 5:])
    body = (right < 250).any(axis=-1)
    assert body.sum() > 500  # a body is drawn there
    width = min(left.shape[1], right.shape[1])
    cut = slice(40, None)  # below the labels, which differ
    np.testing.assert_array_equal(left[cut, :width], right[cut, :width])
    assert (top < 250).any()  # the captured cell above them


def test_an_animated_grid_plays_every_cell_in_step(tmp_path):
    target = tmp_path / "grid.gif"
    done = compare(RUN, "-o", target, "--preset", "subtle,looney", *FAST, "--seconds", "0.5", "-q")
    assert done.returncode == 0, done.stderr
    with Image.open(target) as gif:
        assert gif.n_frames == 10  # 0.5 s of a 120 fps clip at 20 fps
        first = np.asarray(gif.convert("RGB"))
        gif.seek(9)
        last = np.asarray(gif.convert("RGB"))
    assert first.shape == last.shape and (first != last).any()


def test_a_grid_page_holds_every_cells_glb(tmp_path):
    target = tmp_path / "grid.html"
    done = compare(RUN, "-o", target, "--omega", "2,4,6", *FAST, "-q")
    assert done.returncode == 0, done.stderr
    text = target.read_text()
    data = json.loads(re.search(r'<script type="application/json" id="data">(.*?)</script>', text, re.S).group(1)
                      .replace("<\\/", "</"))
    labels = [figure["label"] for figure in data["figures"]]
    assert labels == ["captured", "omega 2", "omega 4", "omega 6"]
    assert "http://" not in text.replace("http://www.w3.org", "") and "https://" not in text.split("<script")[0]


@pytest.mark.parametrize("args, says", [
    (["--omega", "4"], "nothing to compare"),
    (["--omega", "2,2"], "nothing to compare: --omega '2,2' gives one value"),
    (["--omega", "2,,4"], "an empty value in the list"),
    (["--omega", "2,abc"], "--omega abc"),
    (["--omega", "1,2,3,4,5,6,7", "--sigma", "0.1s,0.2s,0.3s,0.4s,0.5s,0.6s"], "42 settings to compare; at most 36"),
    (["--preset", "cartoon,wobbly"], "wobbly"),
    (["--sigma", "0.1s,99999s"], "sigma"),
])
def test_a_list_it_cannot_run_is_one_line_and_writes_nothing(tmp_path, args, says):
    done = compare(RUN, "-o", tmp_path / "g.png", *args, cwd=tmp_path)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1 and lines[0].startswith("Error: "), done.stderr
    assert says in lines[0], lines[0]
    assert list(tmp_path.iterdir()) == []


def test_a_grid_of_no_known_picture_is_refused_before_running(tmp_path):
    done = compare(RUN, "-o", tmp_path / "g.bmp", "--omega", "2,4", cwd=tmp_path)
    assert done.returncode == 2 and "a grid is .png" in done.stderr
    assert list(tmp_path.iterdir()) == []


def test_the_grid_png_reads_back(tmp_path):
    target = tmp_path / "g.png"
    assert compare(RUN, "-o", target, "--omega", "2,4", *FAST, "--frames", "2", "-q").returncode == 0
    with Image.open(io.BytesIO(target.read_bytes())) as picture:
        assert picture.format == "PNG" and picture.width > 300 and picture.height > 300
