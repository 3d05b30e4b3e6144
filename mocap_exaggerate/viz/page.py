"""A page that plays skinned GLB motions side by side: `page_html`.

The page is one HTML file that needs no network, opened from disk or served: the player
(``web/viewer_src.js``, bundled with three.js into ``web/viewer.js`` by ``web/build.sh``) and
every GLB, as base64, are inside it. Each figure gets a panel; one camera at one scale frames
them all. Over them are the paths of the end effectors named in ``ends`` (Kwon and Lee's
Figure 3): the first figure's, the captured motion's, in grey with its Gaussian average in
green, and each other figure's in its own colour, orange for the first exaggerated one.
A timeline, play and step buttons (space and the arrow keys) and a speed keep every figure on
one frame.

With ``tune`` the page also carries a tuner: a preset and a slider per setting, whose changes
it posts to ``./run`` on the server that served it (the page side of that protocol is in
`page_html`'s docstring).

The page exposes ``window.player`` (``ready``, ``frame``, ``frames``, ``playing``, ``figures``,
``drawnFrames``, ``tuned``, ``lastCommand``, ``error``, ``setFrame(n)``, ``play()``, ``pause()``,
``load(index, base64Glb)``) and sets ``document.body.dataset.ready = "1"`` once every figure is
shown and its paths drawn.
"""

from __future__ import annotations

import base64
import functools
import html
import json
import math
import re
from dataclasses import dataclass, field
from importlib.resources import files

__all__ = ["PageFigure", "page_html", "page_ends", "page_sigma", "run_page"]

#: What the page's <meta name="generator"> says.
GENERATOR = "mocap_exaggerate page"
_TUNE_KEYS = ("presets", "settings", "preset", "command", "toml")
_SETTING_KEYS = ("key", "min", "max", "step", "value")


@dataclass(frozen=True)
class PageFigure:
    """One figure of the page: its caption, its GLB and short figures shown under the caption.

    label : the caption ("captured", "cartoon", "sigma 0.2s omega 4")
    glb : a binary glTF: a skinned mesh with one animation, Y up, in metres
    notes : name to value, shown in this order ({"largest limb stretch": "1.42x"})
    """

    label: str
    glb: bytes
    notes: dict[str, str] = field(default_factory=dict)


@functools.cache
def _web_file(name: str) -> str:
    return files(__package__).joinpath("web", name).read_text(encoding="utf-8")


def _script_json(value: object) -> str:
    """JSON that stays inside a <script> element whatever its strings hold."""
    text = json.dumps(value, ensure_ascii=False, separators=(",", ":"), allow_nan=False)
    # "</" would end the element at "</script"; "<!--" would open the script-escape states in which
    # the real end tag no longer ends it. Both escapes still parse to the same JSON.
    return text.replace("</", "<\\/").replace("<!--", "\\u003c!--")


def _check_figure(index: int, figure: PageFigure) -> dict:
    if not isinstance(figure, PageFigure):
        raise TypeError(f"figures[{index}] must be a PageFigure, got {type(figure).__name__}")
    if not isinstance(figure.glb, bytes | bytearray | memoryview) or bytes(figure.glb[:4]) != b"glTF":
        raise ValueError(f"figures[{index}] ({figure.label!r}): glb is not a binary glTF (it does not start with b'glTF')")
    return {"label": str(figure.label), "notes": {str(k): str(v) for k, v in figure.notes.items()},
            "glb": base64.b64encode(bytes(figure.glb)).decode("ascii")}


def _check_tune(tune: dict) -> dict:
    missing = [key for key in _TUNE_KEYS if key not in tune]
    if missing:
        raise ValueError(f"tune has no {', '.join(repr(k) for k in missing)}")
    for index, setting in enumerate(tune["settings"]):
        absent = [key for key in _SETTING_KEYS if key not in setting]
        if absent:
            raise ValueError(f"tune['settings'][{index}] has no {', '.join(repr(k) for k in absent)}")
    return tune


def page_html(figures: list[PageFigure], *, title: str, fps: float, ends: list[str], sigma_frames: float,
              tune: dict | None = None) -> str:
    """One self-contained HTML page that plays ``figures`` side by side, with their end effectors' paths.

    figures : the first is the captured motion (its paths are the grey reference and their
        average the green one), the others exaggerated ones
    title : the page's title and heading
    fps : frames per second; the timeline has a frame every 1/fps s up to the longest animation's end
    ends : node names of the joints whose paths are drawn ("lHand", "rFoot"); a name a GLB does
        not have is skipped for that figure
    sigma_frames : the width, in frames, of the Gaussian average of the captured paths
        (truncated at 4 sigma, edges by their nearest value, as scipy's ``gaussian_filter1d``)
    tune : None, or the tuner's start: ``{"presets": [...], "settings": [...], "preset": name,
        "command": str, "toml": str}``. A preset is a name, or ``{"name": ..., "settings":
        {key: value}}`` to move the sliders when chosen. A setting is ``{"key": "extrapolate.sigma",
        "label": "sigma", "min", "max", "step", "value", "unit": "s"}`` (label and unit optional).

    Returns the page as text; the same arguments give the same text.

    The tuner posts ``{"preset": name, "settings": {key: value, ...}}`` (every slider's value;
    none when a preset that carries no settings was just chosen) to ``./run`` 150 ms after the
    last change, and expects ``{"glb": base64, "notes": {...}, "command": str, "toml": str,
    "seconds": float}`` back, optionally with ``"settings"`` (moves the sliders) and
    ``"sigma_frames"`` (redraws the average), or ``{"error": message}``, shown in the tuner.
    The new GLB replaces figure 1.
    """
    if not figures:
        raise ValueError("figures is empty: the page needs at least one figure")
    if not (isinstance(fps, int | float) and math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be a positive number, got {fps!r}")
    if not (isinstance(sigma_frames, int | float) and math.isfinite(sigma_frames) and sigma_frames >= 0):
        raise ValueError(f"sigma_frames must be a number >= 0, got {sigma_frames!r}")
    if isinstance(ends, str):
        raise TypeError(f"ends must be a list of joint names, got the string {ends!r}")
    data = {"title": str(title), "fps": fps, "ends": [str(name) for name in ends], "sigma_frames": sigma_frames,
            "figures": [_check_figure(index, figure) for index, figure in enumerate(figures)],
            "tune": None if tune is None else _check_tune(tune)}
    fills = {"title": html.escape(str(title)), "data": _script_json(data), "viewer": _web_file("viewer.js")}
    # One pass over the template: what is filled in is never searched for placeholders again.
    text = re.sub(r"\{\{(\w+)\}\}", lambda match: fills[match.group(1)], _web_file("page.html"))
    # A name read from a file name that is not UTF-8 (its bytes kept as lone surrogates) shows as U+FFFD.
    try:
        return text.encode("utf-8", "surrogateescape").decode("utf-8", "replace")
    except UnicodeEncodeError:  # a surrogate no file name made
        return text.encode("utf-8", "surrogatepass").decode("utf-8", "replace")


def page_ends(motion) -> list[str]:
    """The joints whose paths a page draws: the ends of the arms and legs found (hands and feet), else the
    fastest end effector (`mocap_exaggerate.viz.framing.fastest_end`)."""
    from ..analysis.limbs import find_limbs
    from .framing import fastest_end

    limbs = find_limbs(motion.skeleton)
    ends = [motion.skeleton.names[limbs[name].end] for name in ("left_arm", "right_arm", "left_leg", "right_leg")
            if name in limbs]
    return ends or [motion.skeleton.names[fastest_end(motion)]]


def page_sigma(motion, config) -> float:
    """The extrapolation's sigma in frames, for the captured paths' average (0 with extrapolation off)."""
    if config is None or not config.extrapolate.enabled:
        return 0.0
    return float(config.extrapolate.sigma_frames(motion.frame_time, max(motion.num_frames, 1)))


def run_page(motion, result, config, *, label: str, skin=None, title: str, tune: dict | None = None,
             units: str = "auto") -> str:
    """The page of one run: the captured motion and ``result`` (labelled ``label``, with its figures)."""
    from ..jobs.outputs import captured_glb, make_glb
    from .compare import cell_figures

    figures = [PageFigure("captured", captured_glb(motion, result, skin, units), {}),
               PageFigure(label, make_glb(motion, result, skin, units)[0], cell_figures(motion, result))]
    return page_html(figures, title=title, fps=motion.fps, ends=page_ends(motion),
                     sigma_frames=page_sigma(motion, config), tune=tune)
