"""A batch past one machine and the page people look at (issue 12): `batch --scheduler`, `batch --report`.

Dask runs against a real `LocalCluster` (worker processes started by Dask); the report is
opened in Chromium through Playwright where both can be had, and parsed otherwise.
"""

from __future__ import annotations

import json
import os
import shutil
from html.parser import HTMLParser
from importlib.util import find_spec
from pathlib import Path
from urllib.parse import unquote, unquote_to_bytes

import pytest

from mocap_exaggerate.jobs.batch import BatchOptions, FileResult, find_clips, run_batch
from mocap_exaggerate.viz.report import GENERATOR, picture_paths, pictures_current, write_report

from .helpers import SAMPLE_DIR, chromium, no_glb
from .test_batch import JUMP, RUN, command, files_under, mixed_folder

needs_dask = pytest.mark.skipif(find_spec("distributed") is None,
                                reason="Dask distributed is not installed (pip install 'mocap-exaggerate[dask]')")


def same_outputs(a: Path, b: Path) -> None:
    """Two output folders hold the same files with the same bytes (manifests apart from their timings)."""
    assert files_under(a) == files_under(b)
    for name in files_under(a):
        x, y = (a / name).read_bytes(), (b / name).read_bytes()
        if name.endswith(".json") and not name.endswith(".report.json"):
            x, y = (json.loads(v) for v in (x, y))
            x.pop("timings"), y.pop("timings")
        assert x == y, name


# ---------------------------------------------------------------------------- Dask


@needs_dask
def test_a_local_dask_cluster_writes_what_a_serial_batch_writes(tmp_path):
    mixed_folder(tmp_path)
    serial = command("batch", "mocap", "serial", "-j", "1", "--json", cwd=tmp_path)
    dask = command("batch", "mocap", "dask", "--scheduler", "local", "-j", "2", "--json", cwd=tmp_path)
    assert serial.returncode == dask.returncode == 1, dask.stderr
    assert "Traceback" not in dask.stderr and "INFO" not in dask.stderr  # Dask's own chatter kept out
    assert "on a local Dask cluster of 2 worker(s)" in dask.stderr
    same_outputs(tmp_path / "serial", tmp_path / "dask")
    manifest = json.loads((tmp_path / "dask" / "walks" / "run.json").read_text())
    assert manifest["input"]["file"] == "mocap/walks/run.bvh"  # named as given, though workers read it by full path
    lines = {json.loads(line)["input"]: json.loads(line) for line in dask.stdout.splitlines()}
    serial_lines = {json.loads(line)["input"]: json.loads(line) for line in serial.stdout.splitlines()}
    assert lines.keys() == serial_lines.keys()
    for name, line in lines.items():  # each file's result streamed back, failures with their reasons
        assert {k: v for k, v in line.items() if k not in ("seconds", "outputs")} == \
               {k: v for k, v in serial_lines[name].items() if k not in ("seconds", "outputs")}, name
    assert lines["mocap/walks/run.bvh"]["outputs"]["bvh"] == "dask/walks/run.bvh"
    assert lines["mocap/empty.bvh"]["status"] == "failed" and "empty" in lines["mocap/empty.bvh"]["error"]


@needs_dask
def test_the_library_runs_a_batch_on_dask_and_resumes(tmp_path):
    folder = tmp_path / "in"
    (folder / "a").mkdir(parents=True)
    shutil.copy(RUN, folder / "a" / "run.bvh")
    shutil.copy(JUMP, folder / "jump.bvh")
    clips, problems = find_clips(folder)
    options = BatchOptions(no_glb("subtle"), preset="subtle")
    heard = []
    results = run_batch(clips, tmp_path / "out", options, jobs=2, scheduler="local", on_result=heard.append)
    assert [r.status for r in results] == ["converted", "converted"] and len(heard) == 2
    assert [r.input for r in results] == [str(c.source) for c in clips]  # in the clips' order
    again = run_batch(clips, tmp_path / "out", BatchOptions(options.config, preset="subtle", resume=True),
                      jobs=1, scheduler="local")
    assert [r.status for r in again] == ["skipped", "skipped"]
    assert again[0].frames == results[0].frames and again[0].outputs == results[0].outputs  # told by the manifest


@needs_dask
@pytest.mark.parametrize("address, says", [
    ("foo", "give 'local' or a Dask scheduler's address"),
    ("tcp" * 2000, "... (6000 characters): give 'local'"),  # a pasted log is cut short in the message
    ("tcp://127.0.0.1:1", "cannot reach the Dask scheduler"),
])
def test_a_scheduler_that_is_not_there_is_a_usage_error(tmp_path, address, says):
    shutil.copy(RUN, tmp_path / "run.bvh")
    done = command("batch", tmp_path, tmp_path / "out", "--scheduler", address)
    assert done.returncode == 2 and says in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and not (tmp_path / "out" / "run.bvh").exists()


@needs_dask
def test_jobs_belong_to_the_local_cluster_only(tmp_path):
    shutil.copy(RUN, tmp_path / "run.bvh")
    done = command("batch", tmp_path, tmp_path / "out", "--scheduler", "tcp://127.0.0.1:8786", "-j", "4")
    assert done.returncode == 2 and "-j sets the size of --scheduler local" in done.stderr


# ---------------------------------------------------------------------------- the report


class Page(HTMLParser):
    """What a browser would show: rows by id, images by row, links."""

    def __init__(self) -> None:
        super().__init__()
        self.rows: dict[str, dict] = {}
        self.row: dict | None = None
        self.generator = None
        self.failures: list[str] = []

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "meta" and attrs.get("name") == "generator":
            self.generator = attrs.get("content")
        if tag == "tr" and "id" in attrs:
            self.row = self.rows[attrs["id"]] = {"class": attrs.get("class"), "images": [], "links": [], "text": ""}
        elif tag == "img" and self.row is not None:
            self.row["images"].append(attrs["src"])
        elif tag == "a" and self.row is not None:
            self.row["links"].append(attrs["href"])

    def handle_endtag(self, tag):
        if tag == "tr":
            self.row = None

    def handle_data(self, data):
        if self.row is not None:
            self.row["text"] += data


def parse(index: Path) -> Page:
    page = Page()
    page.feed(index.read_text(encoding="utf-8"))
    return page


def test_the_report_has_a_row_and_pictures_per_clip_and_the_errors(tmp_path):
    folder = mixed_folder(tmp_path)
    shutil.copy(RUN, folder / "walks" / "run #2 (take).bvh")  # a name that links must escape
    out = tmp_path / "out"
    done = command("batch", folder, out, "-j", "2", "--report", "--preset", "looney", "--auto-stretch")
    assert done.returncode == 1, done.stderr
    assert f"report: {out / 'index.html'}" in done.stderr
    page = parse(out / "index.html")
    assert page.generator == GENERATOR
    rows = list(page.rows.values())
    converted = [r for r in rows if r["class"] == "converted"]
    failed = [r for r in rows if r["class"] == "failed"]
    assert len(converted) == 4 and len(failed) == 4  # run, run #2, sit, jump; empty, picture, broken, gone
    for row in converted:
        assert len(row["images"]) == 2
        for link in row["images"] + row["links"]:
            target = out / unquote(link)
            assert target.is_file(), link  # every picture and output link leads to a file
        pictures = [(out / unquote(link)).read_bytes() for link in row["images"]]
        assert all(p.startswith(b"\x89PNG") and len(p) > 5000 for p in pictures)
    run_row = next(r for r in converted if "walks/run.bvh" in r["text"])
    assert "149" in run_row["text"] and "lFoot" in run_row["text"] and "rFoot" in run_row["text"]
    # A run's strides are not kicks (issue 25: the speed-based finder took one for a strike).
    assert "left_leg" not in run_row["text"] and "right_leg" not in run_row["text"]
    texts = " ".join(r["text"] for r in failed)
    for says in ("file is empty", "not a BVH file", "file ends where", "does not exist"):
        assert says in texts
    # The pictures sit apart from the outputs; the output files are those a batch always writes.
    assert all(name.startswith("report/") or not name.endswith(".png") for name in files_under(out))


def test_resume_keeps_pictures_of_kept_clips_and_redraws_missing_ones(tmp_path):
    folder = tmp_path / "in"
    folder.mkdir()
    shutil.copy(RUN, folder / "run.bvh")
    shutil.copy(JUMP, folder / "jump.bvh")
    out = tmp_path / "out"
    assert command("batch", folder, out, "-j", "1", "--no-glb", "-q").returncode == 0  # no report yet
    done = command("batch", folder, out, "-j", "1", "--no-glb", "--resume", "--report", "-v")
    assert done.returncode == 0, done.stderr
    assert "report pictures are missing" in done.stderr and "converted       2" in done.stderr
    assert all(pictures_current(out, out / f"{stem}.json") for stem in ("run", "jump"))
    run_preview = picture_paths(out, out / "run.json")["preview"]
    before = run_preview.stat().st_mtime_ns
    picture_paths(out, out / "jump.json")["trajectory"].unlink()
    done = command("batch", folder, out, "-j", "1", "--no-glb", "--resume", "--report")
    assert done.returncode == 0 and "converted       1" in done.stderr and "skipped         1" in done.stderr
    assert run_preview.stat().st_mtime_ns == before
    page = parse(out / "index.html")
    assert sorted(r["class"] for r in page.rows.values()) == ["converted", "skipped"]
    assert all(len(r["images"]) == 2 for r in page.rows.values())


def test_pictures_drawn_from_other_outputs_are_not_shown_and_resume_redraws_them(tmp_path):
    folder = tmp_path / "in"
    folder.mkdir()
    shutil.copy(RUN, folder / "run.bvh")
    out = tmp_path / "out"
    assert command("batch", folder, out, "--no-glb", "--report", "-q").returncode == 0
    assert command("batch", folder, out, "--no-glb", "--overwrite", "--omega", "3", "-q").returncode == 0
    assert not pictures_current(out, out / "run.json")  # the BVH changed under them
    kept = FileResult(str(folder / "run.bvh"), "skipped", outputs={"bvh": str(out / "run.bvh"),
                                                                   "manifest": str(out / "run.json")})
    write_report(out, [kept])
    (row,) = parse(out / "index.html").rows.values()
    assert row["images"] == [] and "no pictures" in row["text"]
    done = command("batch", folder, out, "--no-glb", "--resume", "--omega", "3", "--report", "-v")
    assert done.returncode == 0 and "drawn from other outputs" in done.stderr and "converted       1" in done.stderr
    assert pictures_current(out, out / "run.json")
    (row,) = parse(out / "index.html").rows.values()
    assert len(row["images"]) == 2


@pytest.mark.parametrize("name, says", [("index.html", "is not a batch report"),  # the studio's own page
                                        ("report", "report: is not a folder")])   # where the pictures go
def test_the_report_never_replaces_what_it_did_not_write(tmp_path, name, says):
    shutil.copy(RUN, tmp_path / "run.bvh")
    out = tmp_path / "out"
    out.mkdir()
    (out / name).write_text("<html>the studio's own page</html>")
    done = command("batch", tmp_path, out, "--report")
    assert done.returncode == 2 and says in done.stderr and len(done.stderr.strip().splitlines()) == 1
    assert (out / name).read_text() == "<html>the studio's own page</html>" and not (out / "run.bvh").exists()


def test_an_interrupted_batch_reports_what_did_not_start(tmp_path):
    clips, _ = find_clips(SAMPLE_DIR)
    results = run_batch(clips[:1], tmp_path, BatchOptions(no_glb("cartoon"), report=True))
    write_report(tmp_path, results, pending=clips[1:])
    page = parse(tmp_path / "index.html")
    text = (tmp_path / "index.html").read_text()
    assert len(page.rows) == 1 and text.count('class="pending"') == len(clips) - 1 and "--resume" in text


# ---------------------------------------------------------------------------- in a browser


def test_the_report_opens_from_disk_in_a_browser_with_every_picture_shown(tmp_path):
    sync_api = pytest.importorskip("playwright.sync_api", reason="Playwright is not installed")
    browser_path = chromium()
    if browser_path is None:
        pytest.skip("no Chromium on this machine (apt-get install chromium, or set MOCAP_CHROMIUM)")
    folder = tmp_path / "in"
    (folder / "deep" / "er").mkdir(parents=True)
    shutil.copy(RUN, folder / "deep" / "er" / "run ä #1.bvh")
    shutil.copy(JUMP, folder / "jump.bvh")
    (folder / "empty.bvh").write_bytes(b"")
    out = tmp_path / "out"
    assert command("batch", folder, out, "-j", "2", "--report", "-q").returncode == 1
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=browser_path, args=[
            "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
            "--disable-component-update", "--disable-sync"])
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 4000})
            page.goto((out / "index.html").as_uri())
            page.wait_for_load_state("load")
            shown = page.evaluate("""() => Promise.all([...document.images].map(img =>
                img.decode().then(() => [img.getAttribute('src'), img.naturalWidth, img.naturalHeight],
                                  () => [img.getAttribute('src'), 0, 0])))""")
            rows = page.locator("tbody tr").count()
            failed = page.locator("tr.failed td.error").inner_text()
            page.screenshot(path=str(tmp_path / "report.png"), full_page=True)
        finally:
            browser.close()
    assert rows == 3 and "file is empty" in failed
    assert len(shown) == 4 and all(width > 300 and height > 100 for _, width, height in shown), shown


# ---------------------------------------------------------------------------- after a new user's trial


def test_a_name_that_is_not_utf8_gets_a_row_and_a_working_link(tmp_path):
    folder = tmp_path / "in"
    folder.mkdir()
    odd = os.fsdecode(bytes(folder) + b"/bad\xffbyte.bvh")
    shutil.copy(RUN, odd)
    out = tmp_path / "out"
    done = command("batch", folder, out, "--report", "--no-glb")
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    (row,) = parse(out / "index.html").rows.values()
    assert len(row["images"]) == 2 and "bad\ufffdbyte.bvh" in row["text"]
    for link in row["images"] + row["links"]:
        assert os.path.isfile(os.fsencode(out) + b"/" + unquote_to_bytes(link)), link


def test_a_clip_no_output_can_be_named_after_fails_alone(tmp_path):
    folder = tmp_path / "in"
    folder.mkdir()
    shutil.copy(RUN, folder / "run.bvh")
    shutil.copy(RUN, folder / "._run.bvh")  # a macOS sidecar's name
    shutil.copy(RUN, folder / ("long" * 60 + ".bvh"))
    out = tmp_path / "out"
    done = command("batch", folder, out, "--no-glb", "--json")
    assert done.returncode == 1, done.stderr
    lines = {Path(json.loads(line)["input"]).name: json.loads(line) for line in done.stdout.splitlines()}
    assert lines["run.bvh"]["status"] == "converted"
    assert lines["._run.bvh"]["status"] == "failed" and "._run.bvh: output name" in lines["._run.bvh"]["error"]
    assert lines["long" * 60 + ".bvh"]["status"] == "failed" and "bytes long" in lines["long" * 60 + ".bvh"]["error"]


@needs_dask
def test_a_refused_scheduler_leaves_no_output_folder_behind(tmp_path):
    shutil.copy(RUN, tmp_path / "run.bvh")
    done = command("batch", tmp_path, tmp_path / "new" / "out", "--scheduler", "tcp://127.0.0.1:1")
    assert done.returncode == 2 and not (tmp_path / "new" / "out").exists()


@needs_dask
def test_a_scheduler_without_workers_is_said_not_waited_on_forever(monkeypatch):
    from distributed import LocalCluster

    from mocap_exaggerate.core.errors import ConfigError
    from mocap_exaggerate.jobs import on_dask

    monkeypatch.setattr(on_dask, "WAIT_FOR_WORKERS", 1.0)
    # (over tcp: an inproc:// address, another process's memory, is refused as such)
    with LocalCluster(n_workers=0, processes=False, protocol="tcp://", dashboard_address=None) as cluster:
        with pytest.raises(ConfigError, match="has no workers"):
            on_dask.connect_dask(cluster.scheduler_address)
