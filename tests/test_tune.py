"""Issue 27, parts 4 and 5: ``tune`` serves a page on localhost whose sliders re-run the clip, and the
command it copies writes exactly what it showed.

The server is run as users run it (``mocap-exaggerate tune``, a real process, stopped with Ctrl-C);
the page is opened in Chromium where Chromium and Playwright are installed.
"""

from __future__ import annotations

import base64
import json
import os
import re
import shlex
import signal
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest

from .helpers import SAMPLE_DIR
from .test_page import browser, in_chromium  # noqa: F401  (the module's Chromium, shared)

RUN = SAMPLE_DIR / "cmu_09_01_run_daz.bvh"
TOOL = Path(sys.executable).with_name("mocap-exaggerate")


class Tuning:
    """``mocap-exaggerate tune`` in its own process, and its address."""

    def __init__(self, *options: str) -> None:
        self.process = subprocess.Popen([str(TOOL), "tune", str(RUN), *options], stderr=subprocess.PIPE, text=True,
                                        env={**os.environ, "PYTHONHASHSEED": "0"})
        line = self.process.stderr.readline()
        found = re.search(r"at (http://127\.0\.0\.1:\d+/)", line)
        if not found:
            self.process.kill()
            raise AssertionError(f"the tuner said {line!r}: {self.process.stderr.read()}")
        self.url = found.group(1)

    def post(self, body: bytes | dict, path: str = "run") -> tuple[int, dict]:
        data = body if isinstance(body, bytes) else json.dumps(body).encode()
        try:
            request = urllib.request.Request(self.url + path, data=data, method="POST",
                                             headers={"Content-Type": "application/json"})
            with urllib.request.urlopen(request, timeout=60) as r:
                return r.status, json.loads(r.read())
        except urllib.error.HTTPError as error:
            return error.code, json.loads(error.read() or b"{}")

    def stop(self) -> tuple[int, str]:
        """Ctrl-C, as a user stops it: the exit code and what it said."""
        self.process.send_signal(signal.SIGINT)
        try:
            code = self.process.wait(timeout=20)
        finally:
            self.process.kill()
        return code, self.process.stderr.read()


@pytest.fixture
def tuning():
    server = Tuning("--sigma", "0.25s")
    yield server
    if server.process.poll() is None:
        server.stop()


def written_glb(command: str, folder: Path) -> bytes:
    """Run a copied ``exaggerate`` command (its ``-o out`` into ``folder``) and read the GLB it wrote."""
    words = shlex.split(command)
    assert words[:2] == ["mocap-exaggerate", "exaggerate"] and words[3:5] == ["-o", "out"]
    done = subprocess.run([str(TOOL), *words[1:3], "-o", str(folder), *words[5:], "-q"], capture_output=True, text=True,
                          env={**os.environ, "PYTHONHASHSEED": "0"})
    assert done.returncode == 0, done.stderr
    return (folder / f"{RUN.stem}.glb").read_bytes()


def test_a_run_the_page_asks_for_is_what_the_copied_command_writes(tuning, tmp_path):
    status, answer = tuning.post({"preset": "looney", "settings": {"extrapolate.omega": 6, "springs.blend": 0.55}})
    assert status == 200, answer
    assert "--preset looney" in answer["command"] and "--set extrapolate.omega=6.0" in answer["command"]
    assert "--set springs.blend=0.55" in answer["command"] and "sigma" not in answer["command"]  # looney's own
    assert answer["command"].count("--set") == 2  # the sliders moved, nothing else
    assert float(answer["notes"]["stretch"].rstrip("x")) > 1.0 and answer["seconds"] < 30
    assert written_glb(answer["command"], tmp_path / "a") == base64.b64decode(answer["glb"])
    # The options given hold for the first preset: --sigma 0.25s is where its slider starts.
    status, answer = tuning.post({"preset": "cartoon", "settings": {}})
    assert status == 200 and answer["settings"]["extrapolate.sigma"] == 0.25
    assert "--set extrapolate.sigma=0.25s" in answer["command"]
    assert written_glb(answer["command"], tmp_path / "b") == base64.b64decode(answer["glb"])
    assert 'sigma = "0.25s"' in answer["toml"]


@pytest.mark.parametrize("body, code, says", [
    (b"not json", 400, "not JSON"),
    ({"preset": "wobbly"}, 400, "no preset 'wobbly'"),
    ({"preset": "cartoon", "settings": {"extrapolate.omega": "lots"}}, 400, "settings must be an object of finite numbers"),
    ({"preset": "cartoon", "settings": {"extrapolate.omega": -5}}, 400, "extrapolate.omega must be"),
    ({"preset": "cartoon", "settings": {"input.fps": 5}}, 400, "not a setting the tuner has"),
    ({"preset": "cartoon", "settings": {"subjoints.per_link": 2.5}}, 400, "subjoints.per_link must be a whole number"),
    (b"[" * 60_000, 400, "not JSON"),
    (b"x" * 100_000, 413, "small JSON object"),
    (b'{"preset": "cartoon", "settings": {"subjoints.per_link": Infinity}}', 400, "finite numbers"),
    (b'{"preset": "cartoon", "settings": {"extrapolate.omega": NaN}}', 400, "finite numbers"),
])
def test_a_bad_request_is_answered_in_one_line_and_the_tuner_goes_on(tuning, body, code, says):
    status, answer = tuning.post(body)
    assert status == code and says in answer["error"], answer
    status, _ = tuning.post({"preset": "subtle", "settings": {}})
    assert status == 200  # still serving


def test_the_tuner_serves_only_the_loopback_address_and_stops_cleanly_on_ctrl_c(tuning):
    assert tuning.url.startswith("http://127.0.0.1:")
    with urllib.request.urlopen(tuning.url, timeout=30) as page:
        html = page.read().decode()
    assert 'id="tuner"' in html or "tune" in html
    with pytest.raises(urllib.error.HTTPError) as missing:
        urllib.request.urlopen(tuning.url + "etc/passwd", timeout=30)
    assert missing.value.code == 404
    code, said = tuning.stop()
    assert code == 0 and said.strip() == "stopped", said


def test_a_taken_port_is_one_line(tuning):
    port = tuning.url.rsplit(":", 1)[1].strip("/")
    done = subprocess.run([str(TOOL), "tune", str(RUN), "--port", port], capture_output=True, text=True, timeout=120)
    assert done.returncode != 0 and "Traceback" not in done.stderr and len(done.stderr.strip().splitlines()) == 1


def test_the_tuner_page_runs_a_slider_change_and_copies_a_command_that_writes_it(browser, tuning, tmp_path):  # noqa: F811
    page = in_chromium(browser, tuning.url)
    page.evaluate("player.pause()")
    assert page.evaluate("player.figures") == 2
    omega = page.locator("#settings input[data-key='extrapolate.omega']")
    with page.expect_response(lambda r: r.url.endswith("/run")) as response:
        omega.fill("7")
    page.wait_for_function("player.tuned === 1", timeout=30_000)
    answer = response.value.json()
    command = page.evaluate("player.lastCommand")
    assert command == answer["command"] and "--set extrapolate.omega=7.0" in command
    before = page.evaluate("player.drawnFrames")
    page.evaluate("player.play()")
    page.wait_for_function(f"player.drawnFrames > {before} + 5", timeout=15_000)
    assert written_glb(command, tmp_path) == base64.b64decode(answer["glb"])
    page.context.close()
    # the tuner's own wall time for that run (the figure bench/preview.py prints on a longer clip)
    assert answer["seconds"] > 0 and time.time() > 0


def test_a_request_from_elsewhere_is_refused(tuning):
    # A page on another site can post text/plain without asking first, or reach in through a name of its
    # own that resolves here (DNS rebinding): neither runs anything.
    port = tuning.url.rsplit(":", 1)[1].strip("/")
    body = json.dumps({"preset": "cartoon", "settings": {}}).encode()
    for headers, code in (({"Content-Type": "text/plain"}, 415), ({"Content-Type": "application/json",
                                                                  "Host": f"evil.example:{port}"}, 403)):
        request = urllib.request.Request(tuning.url + "run", data=body, method="POST", headers=headers)
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(request, timeout=30)
        assert refused.value.code == code


def test_a_setting_from_a_pipeline_file_in_frames_is_run_and_copied_as_read(tmp_path):
    # The review's case: sigma "7f" in a --config file was run as 0.058333 s and copied as "7f".
    config = tmp_path / "f7.toml"
    config.write_text('[extrapolate]\nsigma = "7f"\n')
    server = Tuning("--config", str(config), "--stiffness", "158")
    try:
        status, answer = server.post({"preset": "cartoon", "settings": {"extrapolate.omega": 5.1}})
        assert status == 200, answer
        assert "sigma" not in answer["command"] and "--stiffness 158" not in answer["command"]
        assert "--set springs.stiffness=158.0" in answer["command"]  # given on the command line: set as given
        assert written_glb(answer["command"], tmp_path / "out") == base64.b64decode(answer["glb"])
    finally:
        server.stop()


def test_a_browser_that_goes_away_mid_answer_is_not_a_traceback(tuning):
    """A reload, a closed tab or a slider's aborted request drops the connection while the page is sent
    (each was a socketserver traceback on the terminal): nothing is said, and the tuner goes on."""
    import socket

    host, port = tuning.url.removeprefix("http://").strip("/").split(":")
    for _ in range(3):
        with socket.create_connection((host, int(port)), timeout=30) as client:
            client.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b"\x01\x00\x00\x00\x00\x00\x00\x00")  # RST on close
            client.sendall(f"GET / HTTP/1.1\r\nHost: {host}:{port}\r\n\r\n".encode())
            client.recv(16)  # the answer has begun: go away in the middle of it
    status, answer = tuning.post({"preset": "looney"})
    assert status == 200 and "error" not in answer
    code, said = tuning.stop()
    assert code == 0 and said.strip() == "stopped", said
