"""The page that plays skinned GLB motions side by side (`mocap_exaggerate.viz.page`).

The page is checked as text (one file, nothing fetched, the same bytes for the same inputs, no
label that breaks out of its script), then opened in Chromium through Playwright where both can
be had: from disk, with software WebGL, and served with a tuner by a small stand-in for the
tuning server.
"""

from __future__ import annotations

import base64
import functools
import io
import json
import re
import threading
from html.parser import HTMLParser
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib.resources import files

import numpy as np
import pytest

from mocap_exaggerate import load_bvh, load_preset
from mocap_exaggerate.config import resolve_config
from mocap_exaggerate.jobs.outputs import make_glb
from mocap_exaggerate.pipeline import run
from mocap_exaggerate.viz.page import PageFigure, page_html

from .helpers import SAMPLE_DIR, chromium

RUN = SAMPLE_DIR / "cmu_09_01_run_daz.bvh"
ENDS = ["lHand", "rHand", "lFoot", "rFoot", "noSuchJoint"]
# The captured motion as a GLB on the same rubber body: the pipeline with its identity settings.
CAPTURED = {"extrapolate": {"omega": 1.0}, "correct": {"enabled": False}, "springs": {"enabled": False}}
# Software WebGL (SwiftShader) in headless Chromium, as on a machine with no GPU.
WEBGL_ARGS = ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist",
              "--disable-quic", "--no-first-run", "--disable-background-networking", "--disable-component-update",
              "--disable-sync"]
VIEWPORT = {"width": 1200, "height": 600}


@functools.cache
def run_glb(preset: str) -> bytes:
    """The sample run's skinned GLB at a preset, or as captured (``"captured"``)."""
    motion = load_bvh(RUN)
    config = resolve_config("cartoon", None, CAPTURED) if preset == "captured" else load_preset(preset)
    glb, _, _ = make_glb(motion, run(motion, config))
    return glb


def two_figures(label: str = "cartoon") -> list[PageFigure]:
    return [PageFigure("captured", run_glb("captured")),
            PageFigure(label, run_glb("cartoon"), {"largest limb stretch": "1.42x", "jerk ratio": "0.91"})]


def run_page(figures: list[PageFigure] | None = None, **options) -> str:
    options = {"title": "cmu 09_01 run", "fps": 120.0, "ends": ENDS, "sigma_frames": 24.0, **options}
    return page_html(two_figures() if figures is None else figures, **options)


class Elements(HTMLParser):
    """The page's elements as a browser's parser finds them, and the text of each <script>."""

    def __init__(self) -> None:
        super().__init__()
        self.tags: list[tuple[str, dict]] = []
        self.scripts: list[str] = []
        self._in_script = False

    def handle_starttag(self, tag, attrs):
        self.tags.append((tag, dict(attrs)))
        self._in_script = tag == "script"
        if self._in_script:
            self.scripts.append("")

    def handle_endtag(self, tag):
        if tag == "script":
            self._in_script = False

    def handle_data(self, data):
        if self._in_script:
            self.scripts[-1] += data


def elements(page: str) -> Elements:
    parsed = Elements()
    parsed.feed(page)
    parsed.close()
    return parsed


# ---------------------------------------------------------------------------- the page as text


def test_the_page_is_one_file_that_fetches_nothing():
    page = run_page()
    parsed = elements(page)
    assert [tag for tag, _ in parsed.tags if tag in ("script", "link", "img", "iframe")] == ["script", "script"]
    assert all("src" not in attrs and "href" not in attrs for _, attrs in parsed.tags)
    for fetched in (r"""(src|href)\s*=\s*["']?\s*(https?:)?//""", r"""\bimport\b[^;()]*?\bfrom\s*["'](https?:)?//""",
                    r"""\bimport\s*\(\s*["'](https?:)?//""", r"""@import""", r"""url\(\s*["']?(https?:)?//""",
                    r"""fetch\(\s*["'](https?:)?//"""):
        assert not re.search(fetched, page), fetched
    data = json.loads(parsed.scripts[0])
    assert [base64.b64decode(f["glb"]) for f in data["figures"]] == [run_glb("captured"), run_glb("cartoon")]
    assert data["ends"] == ENDS and data["fps"] == 120.0 and data["tune"] is None
    assert data["figures"][1]["notes"] == {"largest limb stretch": "1.42x", "jerk ratio": "0.91"}  # in their order
    web = files("mocap_exaggerate.viz").joinpath("web")
    viewer = web.joinpath("viewer.js").read_text(encoding="utf-8")
    assert viewer.splitlines()[0].startswith("// ") and "three.js" in viewer.splitlines()[0]
    assert viewer in page and "MIT License" in web.joinpath("LICENSE-three.txt").read_text(encoding="utf-8")


def test_the_same_inputs_give_the_same_bytes():
    assert run_page() == run_page()
    assert run_page() != run_page(sigma_frames=12.0)


def test_a_label_cannot_break_out_of_its_script():
    hostile = "</script><b>x"
    figures = [PageFigure(hostile, run_glb("captured"), {"<!--<script>": "</SCRIPT><b>y"}),
               PageFigure("cartoon </scr" + "ipt>", run_glb("cartoon"))]
    page = run_page(figures, title="</title><b>t", ends=["</script><b>e"])
    parsed = elements(page)
    assert "b" not in [tag for tag, _ in parsed.tags]
    assert [tag for tag, _ in parsed.tags].count("script") == 2
    data = json.loads(parsed.scripts[0])  # the escapes parse back to the very strings
    assert [f["label"] for f in data["figures"]] == [hostile, "cartoon </script>"]
    assert data["figures"][0]["notes"] == {"<!--<script>": "</SCRIPT><b>y"}
    assert data["title"] == "</title><b>t" and data["ends"] == ["</script><b>e"]
    assert "<title>&lt;/title&gt;&lt;b&gt;t</title>" in page


@pytest.mark.parametrize("change, says", [
    ({"figures": []}, "figures is empty"),
    ({"figures": [PageFigure("a BVH", b"HIERARCHY\nROOT Hips")]}, "figures[0] ('a BVH'): glb is not a binary glTF"),
    ({"fps": 0}, "fps must be a positive number, got 0"),
    ({"sigma_frames": float("nan")}, "sigma_frames must be a number >= 0"),
    ({"tune": {"presets": ["cartoon"], "settings": []}}, "tune has no 'preset', 'command', 'toml'"),
    ({"tune": {"presets": [], "settings": [{"key": "extrapolate.omega"}], "preset": "", "command": "", "toml": ""}},
     "tune['settings'][0] has no 'min', 'max', 'step', 'value'"),
])
def test_what_the_page_cannot_show_is_refused_naming_it(change, says):
    with pytest.raises(ValueError, match=re.escape(says)):
        run_page(**change)


# ---------------------------------------------------------------------------- in a browser


@pytest.fixture(scope="module")
def browser():
    """One Chromium with software WebGL for the module's tests (a launch is a second or so)."""
    sync_api = pytest.importorskip("playwright.sync_api", reason="Playwright is not installed")
    path = chromium()
    if path is None:
        pytest.skip("no Chromium on this machine (apt-get install chromium, or set MOCAP_CHROMIUM)")
    with sync_api.sync_playwright() as playwright:
        launched = playwright.chromium.launch(executable_path=path, args=WEBGL_ARGS)
        try:
            yield launched
        finally:
            launched.close()


def in_chromium(browser, url: str, *, ready: bool = True, before: str | None = None):
    """A new page at ``url``, once its player is ready (or has failed, without ``ready``)."""
    context = browser.new_context(viewport=VIEWPORT)
    page = context.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    if before:
        page.add_init_script(before)
    page.goto(url)
    page.wait_for_function("window.player && (window.player.ready || window.player.error !== null)", timeout=30_000)
    if ready:
        assert page.evaluate("player.error") is None and not errors, (page.evaluate("player.error"), errors)
    return page


def next_frame(page) -> None:
    """Wait until the browser has drawn what the last call changed."""
    page.evaluate("new Promise(done => requestAnimationFrame(() => requestAnimationFrame(done)))")


def canvas_pixels(page) -> np.ndarray:
    from PIL import Image

    next_frame(page)
    return np.asarray(Image.open(io.BytesIO(page.locator("#view").screenshot())).convert("RGB")).astype(int)


def halves(pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    middle = pixels.shape[1] // 2
    return pixels[:, :middle], pixels[:, middle:]


def changed(a: np.ndarray, b: np.ndarray) -> int:
    return int((np.abs(a - b).sum(axis=-1) > 40).sum())


def near(pixels: np.ndarray, colour: str, within: int = 40) -> int:
    target = np.array([int(colour[i:i + 2], 16) for i in (1, 3, 5)])
    return int((np.abs(pixels - target).sum(axis=-1) < within).sum())


def test_the_page_plays_both_figures_from_disk_on_one_frame(tmp_path, browser):
    path = tmp_path / "run.html"
    path.write_text(run_page(), encoding="utf-8")
    page = in_chromium(browser, path.as_uri())
    state = page.evaluate("({...player})")
    assert state["figures"] == 2 and state["frames"] == 149 and state["playing"]  # it plays once loaded
    assert page.evaluate("document.body.dataset.ready") == "1"
    assert page.locator(".caption .label").all_inner_texts() == ["captured", "cartoon"]
    assert "largest limb stretch" in page.locator(".caption").nth(1).inner_text()
    assert page.locator("#legend .joints").inner_text() == "(lHand, rHand, lFoot, rFoot)"  # no GLB has noSuchJoint
    assert page.locator("#speed option").all_inner_texts() == ["0.25x", "0.5x", "1x", "2x"]
    page.wait_for_function(f"player.frame > {state['frame']} && player.drawnFrames > {state['drawnFrames']}")

    page.evaluate("player.pause(); player.setFrame(10)")
    assert page.evaluate("[player.frame, player.playing]") == [10, False]
    assert page.locator("#readout").inner_text().startswith("frame 10 / 148")
    assert page.locator("#timeline").input_value() == "10"
    at_10 = canvas_pixels(page)
    page.keyboard.press("ArrowRight")
    assert page.evaluate("player.frame") == 11
    page.keyboard.press("Space")
    assert page.evaluate("player.playing")
    page.keyboard.press("Space")
    assert not page.evaluate("player.playing")
    page.evaluate("player.setFrame(70)")
    at_70 = canvas_pixels(page)
    for before, after in zip(halves(at_10), halves(at_70)):  # each panel's figure is drawn, and moves
        background = before[2, 2]
        assert (np.abs(before - background).sum(axis=-1) > 40).sum() > 20_000
        assert changed(before, after) > 1500
    page.set_viewport_size({"width": 900, "height": 500})
    next_frame(page)
    page.set_viewport_size(VIEWPORT)  # the view is framed again for each size, every figure still on frame 70
    assert changed(canvas_pixels(page), at_70) < 50
    page.locator("#paths").uncheck()
    bare = canvas_pixels(page)
    for panel, (with_paths, without) in enumerate(zip(halves(at_70), halves(bare))):
        assert near(with_paths, "#27ae60") > 300 and near(without, "#27ae60") < 20  # the captured paths' average
        assert near(with_paths, "#6b6b70", 20) > near(without, "#6b6b70", 20) + 300  # and the captured paths
        orange = near(with_paths, "#f08c2e", 30) - near(without, "#f08c2e", 30)
        assert (orange > 300) if panel else (orange < 20)  # the cartoon's own paths, in its panel only

    page.evaluate(f"player.load(1, '{base64.b64encode(run_glb('subtle')).decode()}')")
    assert page.evaluate("[player.frame, player.ready, player.figures]") == [70, True, 2]
    reloaded = canvas_pixels(page)
    assert changed(halves(bare)[0], halves(reloaded)[0]) < 50 and changed(halves(bare)[1], halves(reloaded)[1]) > 300
    page.context.close()


def test_without_webgl_the_page_says_so(tmp_path, browser):
    path = tmp_path / "run.html"
    path.write_text(run_page(two_figures()[:1]), encoding="utf-8")
    no_webgl = "HTMLCanvasElement.prototype.getContext = function () { return null; };"
    page = in_chromium(browser, path.as_uri(), ready=False, before=no_webgl)
    assert "this page needs WebGL" in page.evaluate("player.error")
    assert page.locator("#message").is_visible() and "this page needs WebGL" in page.locator("#message").inner_text()
    assert page.evaluate("[player.ready, document.body.dataset.ready]") == [False, None]
    page.context.close()


def test_a_glb_that_will_not_load_is_said_in_the_page(tmp_path, browser):
    path = tmp_path / "broken.html"
    path.write_text(run_page([PageFigure("broken", b"glTF\x02\x00\x00\x00" + bytes(40))]), encoding="utf-8")
    page = in_chromium(browser, path.as_uri(), ready=False)
    assert "would not load" in page.evaluate("player.error") and page.locator("#message").is_visible()
    page.context.close()


# ---------------------------------------------------------------------------- the tuner


TUNE = {"presets": ["subtle", "cartoon", "looney"],
        "settings": [{"key": "extrapolate.sigma", "label": "sigma", "min": 0.05, "max": 0.6, "step": 0.05, "value": 0.2,
                      "unit": "s"},
                     {"key": "extrapolate.omega", "label": "omega", "min": 1, "max": 8, "step": 0.5, "value": 4}],
        "preset": "cartoon", "command": "mocap-exaggerate exaggerate run.bvh -o out/", "toml": 'preset = "cartoon"\n'}


class TuningServer(ThreadingHTTPServer):
    """A stand-in for the tuning server: the page at /, and POST /run answered with the requested preset's GLB."""

    def __init__(self, page: str) -> None:
        super().__init__(("127.0.0.1", 0), TuningHandler)
        self.page = page.encode()
        self.asked: list[dict] = []


class TuningHandler(BaseHTTPRequestHandler):
    server: TuningServer

    def reply(self, body: bytes, kind: str, status: int = 200) -> None:
        self.send_response(status)
        self.send_header("Content-Type", kind)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def do_GET(self):
        self.reply(self.server.page, "text/html; charset=utf-8") if self.path == "/" else self.reply(b"", "text/plain", 404)

    def do_POST(self):
        asked = json.loads(self.rfile.read(int(self.headers["Content-Length"])))
        self.server.asked.append(asked)
        omega = asked["settings"].get("extrapolate.omega", 4)
        if omega > 7:
            answer = {"error": f"extrapolate.omega must be a number in [1, 7], got {omega:g}"}
        else:
            flags = "".join(f" --set {key}={value:g}" for key, value in asked["settings"].items())
            answer = {"glb": base64.b64encode(run_glb(asked["preset"])).decode(), "notes": {"preset": asked["preset"]},
                      "command": f"mocap-exaggerate exaggerate run.bvh -o out/ --preset {asked['preset']}{flags}",
                      "toml": f'preset = "{asked["preset"]}"\n', "seconds": 0.25}
        self.reply(json.dumps(answer).encode(), "application/json")

    def log_message(self, format, *args):  # the test's output stays quiet
        pass


def test_the_tuner_posts_each_change_and_shows_the_run_it_gets_back(browser):
    server = TuningServer(run_page(tune=TUNE))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        page = in_chromium(browser, f"http://127.0.0.1:{server.server_port}/")
        page.context.grant_permissions(["clipboard-read", "clipboard-write"])
        page.evaluate("player.pause()")
        assert page.locator("#tuner").is_visible() and page.locator("#tuner output").all_inner_texts() == ["0.20 s", "4.0"]
        assert page.evaluate("player.lastCommand") == TUNE["command"]

        page.select_option("#preset", "subtle")
        page.wait_for_function("player.tuned === 1", timeout=15_000)
        assert server.asked == [{"preset": "subtle", "settings": {}}]  # the preset alone: the page knows not its values
        assert page.locator("#command").inner_text() == "mocap-exaggerate exaggerate run.bvh -o out/ --preset subtle"
        assert page.evaluate("player.lastCommand") == page.locator("#command").inner_text()
        assert page.locator(".caption").nth(1).inner_text().endswith("preset\tsubtle")
        assert page.locator("#tune-status").inner_text() == "done in 0.25 s"

        omega = page.locator("#settings input[data-key='extrapolate.omega']")
        for value in ("5", "5.5", "6"):  # quick moves: one run at a time, the last value run last
            omega.fill(value)
        page.wait_for_function("document.querySelector('#command').textContent.endsWith('omega=6')", timeout=15_000)
        page.wait_for_function("player.tuned >= 2", timeout=15_000)
        assert 2 <= len(server.asked) <= 4
        # Only the slider moved is sent (a slider snaps a value to its step: the others would change unasked).
        assert server.asked[-1] == {"preset": "subtle", "settings": {"extrapolate.omega": 6}}
        tuned = page.evaluate("player.tuned")
        assert page.locator("#command").inner_text().endswith("--preset subtle --set extrapolate.omega=6")

        page.locator("#copy-command").click()
        page.wait_for_function("document.querySelector('#copy-command').textContent === 'copied'")
        assert page.evaluate("navigator.clipboard.readText()") == page.locator("#command").inner_text()

        omega.fill("8")
        page.wait_for_function("document.querySelector('#tune-status').classList.contains('error')", timeout=15_000)
        assert "extrapolate.omega must be a number in [1, 7], got 8" in page.locator("#tune-status").inner_text()
        assert page.evaluate("[player.tuned, player.error]") == [tuned, None]  # the last good run stays shown
        page.context.close()
    finally:
        server.shutdown()
        server.server_close()
