"""Previews of a clip without a GPU or a display: `write_preview` runs the pipeline on a clip and
writes the picture its file name asks for.

``.png`` still frames of the skinned body captured and exaggerated, or one
joint's path (`stills`); ``.gif`` and ``.mp4`` the two bodies side by side,
moving (`animation`); ``.html`` a page that plays the two GLBs (`page`). The bodies are posed in `posing`, and what each picture
shows is chosen in `framing`.
"""

from __future__ import annotations

import difflib
import logging
import os
import shutil
from pathlib import Path

import numpy as np

from ..core.errors import ConfigError
from ..core.skeleton import Skeleton
from ..rig.skinning import Skin
from .animation import MAX_FPS, NO_FFMPEG, render_gif, render_mp4
from .framing import preview_window
from .stills import render_preview, render_trajectory

__all__ = ["write_preview", "clip_and_character", "joint_named", "PREVIEW_SUFFIXES"]

PREVIEW_SUFFIXES = (".png", ".gif", ".mp4", ".html")

log = logging.getLogger("mocap_exaggerate")


def joint_named(skeleton: Skeleton, name: str, where: str = "the clip") -> int:
    """The index of the joint called ``name``; a ConfigError naming a few close names otherwise."""
    if name in skeleton.names:
        return skeleton.index(name)
    folded = name.casefold()
    close = [n for n in skeleton.names if folded and (folded in n.casefold() or n.casefold() in folded)]
    close += [n for n in difflib.get_close_matches(name, skeleton.names, n=5, cutoff=0.5) if n not in close]
    hint = f"close names: {', '.join(close[:5])}" if close else f"its joints include {', '.join(skeleton.names[:5])}"
    raise ConfigError(f"no joint named {name!r} in {where}; {hint}")


def clip_and_character(source, targets: dict, config, *, skin=None, joint_map=None, overwrite: bool = False,
                       label: str | None = None, protect: tuple = ()):
    """What a picture of a clip starts from: the clip read (``config.input``), the body drawn bound to it
    (the GLB's: ``config.glb``'s character with ``skin`` and ``joint_map`` over it, a glTF clip's own mesh
    where none is named) and how to name the clip in messages; the ``targets`` (kind -> path) checked first
    (never an input; taken only with ``overwrite``), as a job's. What the reading and the binding warn of
    (a frame count the file contradicts, parts of the clip no joint of the character pairs with) is logged
    as warnings, as ``exaggerate`` says them. ``protect``: more files never written over (the pipeline file
    the config came from)."""
    from ..io.gltf_motion import is_gltf
    from ..jobs.job import Character, binding_warnings, check_targets, read_clip

    if is_gltf(source) and skin is None and not config.glb.skin:
        skin = Path(source)  # a game character is drawn with its own mesh, as exaggerate writes it
    character = Character.of(config.glb, glb=True, skin=skin, joint_map=joint_map, units=None, influences=None)
    inputs = [Path(p) for p in (source, character.skin_file, character.map_file, *protect)
              if isinstance(p, (str, os.PathLike)) and str(p) != "-"]
    check_targets(targets, inputs, overwrite)
    motion, report = read_clip(source, config.input, name=label)
    where = label or (str(source) if inputs else "the clip")
    body, binding = character.bound_to(motion, where)
    for warning in [*report.warnings, *binding_warnings(binding)]:
        log.warning("%s: %s", where, warning)
    return motion, body, where


def _kind(output: Path, trajectory: str | None) -> str:
    """The suffix of the picture to write, refusing what cannot be written."""
    suffix = output.suffix.lower()
    if suffix not in PREVIEW_SUFFIXES:
        found = f"cannot write {suffix}" if suffix else "no suffix"
        raise ConfigError(f"{output}: {found}; previews are .png (still frames), .gif or .mp4 (animations) "
                          f"or .html (a page that plays them)")
    if trajectory is not None and suffix != ".png":
        raise ConfigError(f"{output}: a joint's trajectory is a still picture; name the file .png")
    if suffix == ".mp4" and shutil.which("ffmpeg") is None:
        raise ConfigError(f"{output}: {NO_FFMPEG}")
    return suffix


def write_preview(source, output: str | os.PathLike, config=None, *, frames: int = 5, overwrite: bool = False,
                  label: str | None = None, trajectory: str | None = None, start: float = 0.0,
                  seconds: float | None = None, max_fps: float = MAX_FPS,
                  skin: Skin | str | os.PathLike | None = None,
                  joint_map: dict[str, str] | str | os.PathLike | None = None, protect: tuple = ()) -> Path:
    """Run the pipeline on a clip (path, bytes or stream) and write its preview to ``output``.

    By the suffix: ``.png`` the body at ``frames`` evenly spaced frames (`render_preview`), or
    with ``trajectory`` (a joint's name) that joint's paths (`render_trajectory`); ``.gif``
    an animation (`render_gif`); ``.mp4`` the same through ffmpeg (`render_mp4`); ``.html`` a page
    that plays the captured and the exaggerated GLB, with the hands' and feet's paths (`page.run_page`). ``start``
    and ``seconds`` choose the part of the motion shown (default: all of it; an animation
    stops at `MAX_SECONDS`). The name, the joint and ffmpeg are checked and the target is
    checked (never an input; taken only with ``overwrite``) before the clip is run. ``skin``
    (a `Skin` or a skin file, with ``joint_map``, pairs or a joint map file, for joints the pairing misses) is the body drawn,
    bound to the clip as the GLB's is (`mocap_exaggerate.rig.binding`); default: the capsule body.
    ``protect``: more files the output must not land on (the pipeline file ``config`` was read from).
    """
    from ..config import DEFAULT_PRESET, load_preset
    from ..io.files import atomic_write
    from ..pipeline import run

    output = Path(output)
    kind = _kind(output, trajectory)
    config = config or load_preset(DEFAULT_PRESET)
    motion, skin, where = clip_and_character(source, {"preview": output}, config, skin=skin, joint_map=joint_map,
                                             overwrite=overwrite, label=label, protect=protect)
    joint = joint_named(motion.skeleton, trajectory, where) if trajectory is not None else None
    result = run(motion, config)
    if kind == ".gif":
        data = render_gif(motion, result, start=start, seconds=seconds, max_fps=max_fps, skin=skin)
    elif kind == ".mp4":
        data = render_mp4(motion, result, start=start, seconds=seconds, max_fps=max_fps, skin=skin)
    elif kind == ".html":
        from .page import run_page

        name = Path(where).name
        data = run_page(motion, result, config, label=label_of(config), skin=skin, title=name,
                        units=config.glb.units).encode("utf-8")
    elif joint is not None:
        data = render_trajectory(motion, result, joint, config,
                                 frames=preview_window(motion, result, start=start, seconds=seconds))
    else:
        begin, end = preview_window(motion, result, start=start, seconds=seconds)
        data = render_preview(motion, result, at=list(np.linspace(begin, end - 1, frames).astype(int)), skin=skin)
    atomic_write(output, data, overwrite=True)
    return output


def label_of(config) -> str:
    """A run's caption on a page: its sigma and omega (the settings tuned most)."""
    x = config.extrapolate
    if not x.enabled:
        return "exaggerated (no extrapolation)"
    return f"sigma {x.sigma}, omega {x.omega:g}"
