"""Tuning you can see: a page on localhost with a slider per setting that re-runs the clip as you move it.

`Tuner` holds a clip read once and runs it with a preset and the sliders' values (`Tuner.run`): the
pipeline in memory, the exaggerated GLB, its figures, and the exact ``exaggerate`` command and
pipeline TOML that make the same files. `serve` puts the page of `mocap_exaggerate.viz.page` on the
loopback address with those sliders: ``GET /`` the page, ``POST /run`` a run (JSON in and out, the
protocol `page_html` documents). Only 127.0.0.1 is served (a tuner is one animator's, not the
network's); a request is one run at a time.
"""

from __future__ import annotations

import base64
import json
import math
import shlex
import sys
import threading
import time
from dataclasses import dataclass
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

from ..core.errors import ConfigError, MocapError, printable

__all__ = ["TUNED", "Slider", "Tuner", "serve", "bind_port", "TuneServer", "slider_values"]


@dataclass(frozen=True)
class Slider:
    """A setting the tuner shows: its TOML ``key``, a ``label``, the range and step, and ``unit`` (``"s"``:
    a duration in seconds, written ``"0.25s"``)."""

    key: str
    label: str
    low: float
    high: float
    step: float
    unit: str = ""


#: The settings of the README's parameter table that take a number, as sliders.
TUNED = (
    Slider("extrapolate.sigma", "sigma", 0.02, 1.0, 0.01, "s"),
    Slider("extrapolate.omega", "omega", 0.0, 12.0, 0.1),
    Slider("extrapolate.max_speed", "speed limit (0: none)", 0.0, 5.0, 0.05),
    Slider("extrapolate.smooth", "smooth", 0.0, 0.2, 0.01, "s"),
    Slider("extrapolate.still", "still", 0.0, 0.3, 0.01),
    Slider("extrapolate.torso", "torso share", 0.0, 1.0, 0.05),
    Slider("correct.threshold", "correction threshold", 0.0, 0.3, 0.005),
    Slider("correct.max_stretch", "free stretch", 1.0, 2.0, 0.01),
    Slider("correct.delta", "correction step", 0.05, 1.0, 0.05),
    Slider("correct.accent_speed", "accent speed", 0.0, 6.0, 0.1),
    Slider("correct.torso", "torso stretch share", 0.0, 1.0, 0.05),
    Slider("subjoints.per_link", "sub-joints a link", 1, 8, 1),
    Slider("springs.stiffness", "spring stiffness", 10.0, 1000.0, 10.0),
    Slider("springs.link_stiffness", "link stiffness", 10.0, 1000.0, 10.0),
    Slider("springs.damping", "damping", 0.0, 60.0, 0.5),
    Slider("springs.blend", "follow-through", 0.0, 1.0, 0.05),
)
_BY_KEY = {slider.key: slider for slider in TUNED}


def _value(config, key: str, frame_time: float):
    """A setting's value in ``config`` as its slider shows it (a duration in seconds)."""
    from ..core.timing import parse_duration

    block, name = key.split(".")
    value = getattr(getattr(config, block), name)
    if _BY_KEY[key].unit == "s":
        return round(parse_duration(value, frame_time, what=key) * frame_time, 6)
    return value


def _written(key: str, value) -> str:
    """A slider's value as a setting's text: ``0.25s`` for a duration, a count as an integer, else the number."""
    if _BY_KEY[key].unit == "s":
        return f"{float(value):g}s"
    if key == "subjoints.per_link":  # a count: 2.5 is refused, as --set refuses it (it was run as 2)
        if not float(value).is_integer():
            raise ConfigError(f"subjoints.per_link must be a whole number, got {value!r}")
        return str(int(float(value)))
    return repr(float(value))


def slider_values(config, frame_time: float) -> dict[str, object]:
    """Every slider's value in ``config``."""
    return {slider.key: _value(config, slider.key, frame_time) for slider in TUNED}


class Tuner:
    """A clip read once, run again for each setting the page asks for.

    source : the clip's path as given (for the command line)
    motion : the clip read (`mocap_exaggerate.jobs.job.read_clip`)
    preset : the preset the sliders start from
    configure : ``preset -> PipelineConfig``, the config the command line's other options make with that
        preset (``--config``, ``--skin``, ``--fps``, switches; not the sliders' settings); ``base`` those
        options' words, kept in every command
    start : the sliders' values the command line gave (``--sigma 0.3s``, ``--set springs.blend=0.5``): where
        they start with ``preset``, and set in every run and command of it
    skin : the character drawn (bound to the clip), None for the default body
    """

    def __init__(self, source: str, motion, preset: str, configure, base: tuple[str, ...] = (),
                 start: dict | None = None, skin=None, units: str = "auto") -> None:
        from ..config import preset_names

        self.source, self.motion, self.skin, self.units = source, motion, skin, units
        self.preset, self._configure, self.base = preset, configure, tuple(base)
        self._configured: dict[str, object] = {}
        self.presets = preset_names()
        self.given = dict(start or {})
        self.lock = threading.Lock()

    def configure(self, preset: str):
        """The config the other options make with ``preset`` (found once a preset)."""
        if preset not in self._configured:
            self._configured[preset] = self._configure(preset)
        return self._configured[preset]

    def _own(self, preset: str) -> dict[str, object]:
        """The sliders' values ``configure(preset)`` has."""
        return slider_values(self.configure(preset), self.motion.frame_time)

    def settings(self, preset: str) -> dict[str, object]:
        """The sliders' values a preset starts them at (with the command line's own, for the first preset)."""
        values = self._own(preset)
        if preset == self.preset:
            values.update({key: value for key, value in self.given.items() if key in _BY_KEY})
        return values

    def applied(self, preset: str, values: dict[str, object]) -> dict[str, object]:
        """What a run sets: the sliders moved (``values``), over the command line's own for the first preset."""
        return {**(self.given if preset == self.preset else {}), **values}

    def _config(self, preset: str, values: dict[str, object]):
        from ..config import resolve_config

        table: dict = {}
        for key, value in values.items():
            if key not in _BY_KEY:
                raise ConfigError(f"{key!r} is not a setting the tuner has (it has {', '.join(_BY_KEY)})")
            block, name = key.split(".")
            text = _written(key, value)
            table.setdefault(block, {})[name] = text if _BY_KEY[key].unit == "s" else (
                int(text) if key == "subjoints.per_link" else float(text))
        return resolve_config(None, self.configure(preset).to_toml(preset=preset), table, config_source="tuner")

    def command(self, preset: str, values: dict[str, object]) -> str:
        """The ``exaggerate`` command that writes what the page shows (the GLB byte for byte): the preset,
        the other options given, and ``--set`` for each setting the run set (`applied`), written as the run
        read it (a slider left alone is not set: a "7f" from a pipeline file stays "7f")."""
        words = ["mocap-exaggerate", "exaggerate", self.source, "-o", "out", "--preset", preset, *self.base]
        for key, value in values.items():
            words += ["--set", f"{key}={_written(key, value)}"]
        return shlex.join(words)

    def start(self) -> dict:
        """The page's ``tune`` (`mocap_exaggerate.viz.page.page_html`): presets, sliders, the command and TOML."""
        values = self.settings(self.preset)
        config = self._config(self.preset, self.applied(self.preset, {}))
        presets = [{"name": name, "settings": self.settings(name)} for name in self.presets]
        sliders = [{"key": s.key, "label": s.label, "min": s.low, "max": s.high, "step": s.step,
                    "value": values[s.key], "unit": s.unit} for s in TUNED]
        return {"presets": presets, "settings": sliders, "preset": self.preset,
                "command": self.command(self.preset, self.applied(self.preset, {})),
                "toml": config.to_toml(preset=self.preset)}

    def run(self, request: dict) -> dict:
        """One run for the page: ``{"preset", "settings"}`` in, ``{"glb" (base64), "notes", "command", "toml",
        "settings", "sigma_frames", "seconds"}`` out, or ``{"error"}`` for settings the config refuses."""
        from ..jobs.outputs import make_glb
        from ..pipeline import run
        from .compare import cell_figures
        from .page import page_sigma

        start = time.perf_counter()
        if not isinstance(request, dict):
            return {"error": "a run is asked for with a JSON object {\"preset\": ..., \"settings\": {...}}"}
        preset = request.get("preset", self.preset)
        values = request.get("settings") or {}
        if preset not in self.presets:
            return {"error": f"no preset {preset!r} (there are {', '.join(self.presets)})"}
        if not isinstance(values, dict) or not all(isinstance(v, int | float) and not isinstance(v, bool)
                                                   and math.isfinite(v) for v in values.values()):
            return {"error": "settings must be an object of finite numbers"}
        applied = self.applied(preset, values)
        try:
            config = self._config(preset, applied)
            with self.lock:
                result = run(self.motion, config)
                glb, _, _ = make_glb(self.motion, result, self.skin, self.units)
        except MocapError as error:
            return {"error": str(error)}
        shown = {**self._own(preset), **applied}
        return {"glb": base64.b64encode(glb).decode("ascii"), "notes": cell_figures(self.motion, result),
                "command": self.command(preset, applied), "toml": config.to_toml(preset=preset),
                "settings": {key: shown[key] for key in _BY_KEY},
                "sigma_frames": page_sigma(self.motion, config), "seconds": round(time.perf_counter() - start, 3)}

    def page(self) -> str:
        """The page the tuner serves: the captured motion and the preset's run, with the sliders."""
        from ..pipeline import run
        from .page import run_page

        config = self._config(self.preset, self.applied(self.preset, {}))
        result = run(self.motion, config)
        return run_page(self.motion, result, config, label="tuned", skin=self.skin, units=self.units,
                        title=f"tune: {Path(self.source).name}", tune=self.start())


class TuneServer(ThreadingHTTPServer):
    """The tuner's HTTP server on the loopback address (``port`` 0: one the system picks). `bind_port` makes
    it (before the clip is read, so a taken port is said at once); `serve` gives it its tuner."""

    daemon_threads = True
    #: The largest request body read (a run's settings are a few hundred bytes).
    MAX_BODY = 64 * 1024

    def __init__(self, port: int = 0) -> None:
        self.tuner: Tuner | None = None
        self.html = b""
        super().__init__(("127.0.0.1", port), _Handler)

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.server_address[1]}/"

    def handle_error(self, request, client_address) -> None:
        """A browser that goes away mid-answer (a reload, a closed tab, a slider's aborted request) is
        normal: nothing is said. Anything else is one line, not socketserver's traceback."""
        error = sys.exc_info()[1]
        if isinstance(error, ConnectionError):
            return
        print(printable(f"tune: a request failed: {type(error).__name__}: {str(error)[:200]}"), file=sys.stderr)

    def hosts(self) -> set[str]:
        """The Host headers a request of this machine's browser carries (another is a page elsewhere
        reaching in, through a name that resolves here)."""
        port = self.server_address[1]
        return {f"127.0.0.1:{port}", f"localhost:{port}"}


def bind_port(port: int) -> TuneServer:
    """The server on 127.0.0.1 at ``port``; ConfigError (one line) when it cannot listen there."""
    import errno

    try:
        return TuneServer(port)
    except OSError as error:
        if error.errno == errno.EADDRINUSE:
            raise ConfigError(f"--port {port}: another program listens there; give another port, or --port 0 for "
                              "a free one") from None
        raise ConfigError(f"--port {port}: cannot listen there ({error.strerror or error})") from None


class _Handler(BaseHTTPRequestHandler):
    server: TuneServer
    protocol_version = "HTTP/1.1"

    def log_message(self, format, *args) -> None:  # noqa: A002  (quiet: the command says what matters)
        pass

    def _send(self, code: int, body: bytes, kind: str) -> None:
        self.send_response(code)
        self.send_header("Content-Type", kind)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        self.wfile.write(body)

    def _json(self, code: int, answer: dict) -> None:
        self._send(code, json.dumps(answer).encode("utf-8"), "application/json")

    def _ours(self) -> bool:
        """Whether the request names this server as its host; a 403 when not (DNS rebinding)."""
        if self.headers.get("Host", "") in self.server.hosts():
            return True
        self._send(403, b"this tuner answers only at 127.0.0.1 and localhost\n", "text/plain; charset=utf-8")
        return False

    def do_GET(self) -> None:  # noqa: N802  (http.server's name)
        if not self._ours():
            return
        if self.path.split("?")[0] in ("/", "/index.html"):
            self._send(200, self.server.html, "text/html; charset=utf-8")
        else:
            self._send(404, b"not found\n", "text/plain; charset=utf-8")

    def do_POST(self) -> None:  # noqa: N802
        if not self._ours():
            return
        if self.path.split("?")[0] != "/run":
            self._send(404, b"not found\n", "text/plain; charset=utf-8")
            return
        try:
            length = int(self.headers.get("Content-Length", "0"))
        except ValueError:
            length = -1
        if not 0 <= length <= TuneServer.MAX_BODY:
            self._json(413, {"error": "a run's request is a small JSON object"})
            self.close_connection = True
            return
        body = self.rfile.read(length)
        if not self.headers.get("Content-Type", "").startswith("application/json"):
            # (a page elsewhere can send text/plain without asking first; JSON it must ask for, and is not let)
            self._json(415, {"error": "a run's request is JSON (Content-Type: application/json)"})
            return
        try:
            request = json.loads(body or b"{}")
        except (ValueError, RecursionError):
            self._json(400, {"error": "the request is not JSON"})
            return
        try:
            answer = self.server.tuner.run(request)
        except Exception as error:  # a bug: said to the page in one line, the tuner goes on
            self._json(500, {"error": f"internal error ({type(error).__name__}: {str(error)[:200]}): a bug in "
                                      "mocap-exaggerate (please report it)"})
            return
        self._json(400 if "error" in answer else 200, answer)


def serve(server: TuneServer, tuner: Tuner, ready=None) -> None:
    """Serve ``tuner``'s page on ``server`` until interrupted (Ctrl-C: the server closes and this returns).
    ``ready(url)`` is called once it listens."""
    server.tuner = tuner
    server.html = tuner.page().encode("utf-8")
    try:
        if ready is not None:
            ready(server.url)
        server.serve_forever(poll_interval=0.2)
    except KeyboardInterrupt:
        pass
    finally:
        server.server_close()
