"""``batch --resume``: which clips' outputs can be kept, and what a kept clip reports.

A clip's outputs are kept when its manifest reads, was made with the same
parameters (`batch_parameters`) from the same input bytes, and every file it
lists is there with the digest it lists (and, for a batch with a report, its
pictures were drawn from those outputs). Anything else is redone, saying why.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

from .batch_types import BatchOptions, Clip, FileResult
from .discovery import read_manifest

__all__ = ["batch_parameters", "is_complete", "resume_check", "kept_result"]


def batch_parameters(options: BatchOptions) -> str:
    """The digest of what shapes a batch's outputs (`parameters_digest`), recorded in each manifest."""
    from .job import parameters_digest

    glb = options.config.glb
    return parameters_digest(options.config, preset=options.preset, glb=glb.enabled, units=glb.units,
                             influences=glb.influences, skin=glb.skin or None, joint_map=glb.joint_map or None)


def is_complete(clip: Clip, out_dir: str | os.PathLike, options: BatchOptions, parameters: str | None = None) -> bool:
    """Whether ``clip``'s output set under ``out_dir`` is complete and was made from these input
    bytes with these parameters (`batch_parameters`; computed when not given)."""
    return resume_check(clip, out_dir, options, parameters)[0] is None


def resume_check(clip: Clip, out_dir: str | os.PathLike, options: BatchOptions,
                 parameters: str | None = None) -> tuple[str | None, dict | None]:
    """Why ``clip`` must be (re)done under ``out_dir`` (None when its outputs can be kept), and
    the manifest as read (None when it does not read), read once for the checks and for `kept_result`.

    The cheap reasons first (no manifest, other options, another input), the
    hashing of every output last.
    """
    from ..io.files import digest_of_file
    from .job import check_output_set

    manifest = Path(out_dir) / clip.relative.parent / f"{clip.name}.json"
    info = read_manifest(manifest)
    if info is None:
        return ("no outputs yet" if not manifest.exists() else "outputs incomplete (the manifest does not read)"), None
    if parameters is None:
        parameters = batch_parameters(options)
    if info.get("parameters") != parameters:
        return "made with other options", info
    try:
        if digest_of_file(clip.source) != (info.get("input") or {}).get("hash"):
            return "the input changed", info
    except OSError:
        return "the input cannot be read", info
    problems = check_output_set(manifest, info)
    if problems:
        return f"outputs incomplete ({problems[0]})", info
    if options.report:
        from ..viz.report import pictures_current

        if not pictures_current(out_dir, manifest, info):
            return "its report pictures are missing or were drawn from other outputs", info
    return None, info


def kept_result(label: str, clip: Clip, out_dir: str | os.PathLike, started: float, info: dict) -> FileResult:
    """The result of a clip whose complete outputs are kept: what its manifest says.

    started : `time.perf_counter` when the clip was taken up
    info : its manifest, as `resume_check` read it
    """
    from .job import output_paths

    folder = Path(out_dir) / clip.relative.parent
    listed = info.get("outputs") or {}
    usd = Path(str(listed.get("usd", ""))).suffix.lstrip(".")
    outputs = {kind: str(path) for kind, path in output_paths(folder, clip.name, usd=usd, fbx="fbx" in listed).items()
               if kind in listed or kind == "manifest"}
    stretch = (info.get("result") or {}).get("max_link_stretch")
    return FileResult(label, "skipped", outputs=outputs, frames=(info.get("result") or {}).get("frames"),
                      seconds=time.perf_counter() - started, max_link_stretch=stretch,
                      error="outputs complete, from the same input and parameters")
