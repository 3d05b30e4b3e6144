"""A batch's report: ``OUT_DIR/index.html``, one row per clip, with its pictures and figures.

`write_pictures` draws a converted clip's two pictures (in the worker that
converted it): the captured and exaggerated body at the frames where it is
most exaggerated, and the path of its fastest end effector captured, averaged
and exaggerated (Kwon and Lee's Figure 3), and writes the page that plays it (`page`, linked as
"play"). They go to ``OUT_DIR/report/``,
mirroring the clips' folders, with a small record of the BVH they were drawn
from, so a resumed batch knows whether they still show its output.
`write_report` then writes the page from the batch's results and the clips'
manifests: static HTML with relative links, opened from disk with no server.
"""

from __future__ import annotations

import html
import json
import os
from pathlib import Path
from urllib.parse import quote

from ..core.errors import ConfigError, printable

__all__ = ["REPORT_FOLDER", "picture_paths", "write_pictures", "pictures_current", "write_report", "check_report"]

#: Where the report's pictures go, under the output folder.
REPORT_FOLDER = "report"
#: What marks an index.html as this tool's (and so ours to replace).
GENERATOR = "mocap_exaggerate batch report"


def picture_paths(out_dir: str | os.PathLike, manifest: str | os.PathLike) -> dict[str, Path]:
    """The report files of the clip whose manifest is ``manifest``: ``preview``, ``trajectory``, ``page`` (the
    page that plays it, `mocap_exaggerate.viz.page`), ``record``."""
    relative = Path(os.path.relpath(Path(manifest), Path(out_dir)))
    folder = Path(out_dir) / REPORT_FOLDER / relative.parent
    stem = relative.stem
    return {"preview": folder / f"{stem}.preview.png", "trajectory": folder / f"{stem}.trajectory.png",
            "page": folder / f"{stem}.page.html", "record": folder / f"{stem}.report.json"}


def write_pictures(record, out_dir: str | os.PathLike, config=None) -> dict:
    """Draw the pictures of a converted clip (a `JobRecord` with its ``captured`` motion); their record.

    The record names the fastest end effector, the frames drawn, and the output BVH's
    digest the pictures were drawn from.
    """
    from ..io.files import write_files
    from .framing import fastest_end, telling_frames, telling_window
    from .page import run_page
    from .stills import render_preview, render_trajectory

    motion, result = record.captured, record.result
    paths = picture_paths(out_dir, record.outputs["manifest"])
    world = motion.world_positions()  # once, for every choice and picture below
    joint = fastest_end(motion, result.rest_frames, world=world)
    frames = telling_frames(motion, result, 4, world=world)
    window = telling_window(motion, result, joint, world=world)
    info = {"bvh": record.manifest["outputs"]["hashes"]["bvh"], "joint": motion.skeleton.names[joint],
            "frames": frames, "window": list(window), "preview": paths["preview"].name,
            "trajectory": paths["trajectory"].name, "page": paths["page"].name}
    skin, units = None, "auto"
    if config is not None:  # the page plays the batch's own character, as its GLB holds it
        from ..jobs.job import Character

        character = Character.of(config.glb, glb=True, skin=None, joint_map=None, units=None, influences=None)
        skin, units = character.bound_to(motion, str(record.outputs["manifest"]))[0], config.glb.units
    page = run_page(motion, result, config, label="exaggerated", title=Path(record.outputs["manifest"]).stem, skin=skin,
                    units=units)
    write_files([(paths["preview"], render_preview(motion, result, at=frames, width=1.8, dpi=110)),
                 (paths["trajectory"], render_trajectory(motion, result, joint, config, frames=window, dpi=100,
                                                          world=world)),
                 (paths["page"], page.encode("utf-8")),
                 (paths["record"], (json.dumps(info, indent=2) + "\n").encode("utf-8"))], overwrite=True)
    return info


def pictures_current(out_dir: str | os.PathLike, manifest: str | os.PathLike, info: dict | None = None) -> bool:
    """Whether the clip's pictures are there and were drawn from the BVH its manifest lists
    (``info``: the manifest's data, when the caller has read it)."""
    listed = info if info is not None else _read_json(Path(manifest))
    return _current_record(picture_paths(out_dir, manifest), listed) is not None


def _current_record(paths: dict[str, Path], listed: dict | None) -> dict | None:
    """The pictures' record when they are there and were drawn from the BVH the manifest ``listed`` lists."""
    info = _read_json(paths["record"])
    if info is None or listed is None:
        return None
    bvh = listed.get("outputs", {}).get("hashes", {}).get("bvh")
    current = bvh is not None and info.get("bvh") == bvh and all(paths[kind].is_file()
                                                                 for kind in ("preview", "trajectory", "page"))
    return info if current else None


def check_report(out_dir: str | os.PathLike) -> None:
    """Refuse (ConfigError) to write the report over an index.html this tool did not write, or
    where its pictures cannot go."""
    pictures = Path(out_dir) / REPORT_FOLDER
    if (pictures.exists() or pictures.is_symlink()) and not pictures.is_dir():
        raise ConfigError(f"{pictures}: is not a folder; the report's pictures go there (move it, or choose "
                          "another output folder)")
    index = Path(out_dir) / "index.html"
    if index.exists():
        try:
            head = index.read_bytes()[:2000].decode("utf-8", "replace")
        except OSError as error:
            raise ConfigError(f"{index}: cannot read it to tell whether it is a report of ours: {error.strerror}") from None
        if GENERATOR not in head:
            raise ConfigError(f"{index}: exists and is not a batch report; --report would replace it "
                              "(move it, or choose another output folder)")


def _read_json(path: Path) -> dict | None:
    try:
        value = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):
        return None
    return value if isinstance(value, dict) else None


def write_report(out_dir: str | os.PathLike, results, *, pending=(), title: str = "Batch report",
                 settings: str = "") -> Path:
    """Write ``out_dir/index.html`` for a batch's ``results`` (`FileResult`, in the clips' order).

    pending : clips never started (an interrupted batch), listed as such
    settings : one line saying how the batch ran (preset, options), shown under the title
    """
    from ..io.files import atomic_write

    out_dir = Path(out_dir)
    rows = [_row(out_dir, result, number) for number, result in enumerate(results)]
    rows += [_pending_row(clip) for clip in pending]
    counts = {status: sum(r.status == status for r in results) for status in ("converted", "skipped", "failed")}
    frames = sum(r.frames or 0 for r in results)
    seconds = sum(r.seconds for r in results)
    failed = [(i, r) for i, r in enumerate(results) if r.status == "failed"]
    summary = ", ".join(f"{n} {status}" for status, n in counts.items()) + (f", {len(pending)} not started"
                                                                           if pending else "")
    failures = "".join(f'<li><a href="#clip-{i}">{_e(r.error or r.input)}</a></li>'
                       for i, r in failed)
    page = _PAGE.format(
        generator=_e(GENERATOR), title=_e(title), settings=_e(settings), summary=_e(summary),
        figures=_e(f"{frames:,} frames converted or kept, {seconds:.1f} s of conversion"),
        failures=f'<h2>Failed</h2><ul class="failures">{failures}</ul>' if failures else "",
        rows="\n".join(rows))
    index = out_dir / "index.html"
    atomic_write(index, page.encode("utf-8"), overwrite=True)
    return index


def _row(out_dir: Path, result, number: int) -> str:
    name = _e(result.input)
    status = f'<span class="status {result.status}">{result.status}</span>'
    manifest_path = result.outputs.get("manifest")
    if result.status == "failed" or not manifest_path:  # failed, or skipped with nothing made (a folder loop)
        return (f'<tr class="{result.status}" id="clip-{number}"><td class="clip">{name}<br>{status}</td>'
                f'<td colspan="7" class="error">{_e(result.error or "")}</td></tr>')
    listed = _read_json(Path(manifest_path)) if manifest_path else None
    links = " ".join(f'<a href="{_href(out_dir, path)}">{kind}</a>' for kind, path in result.outputs.items()
                     if kind in ("bvh", "glb", "weights", "pipeline", "manifest"))
    pictures = '<td class="none" colspan="2">no pictures</td>'
    if manifest_path:
        paths = picture_paths(out_dir, manifest_path)
        info = _current_record(paths, listed)
        if info is not None:
            links += f' <a href="{_href(out_dir, paths["page"])}" class="play">play</a>'
            pictures = (f'<td><a href="{_href(out_dir, paths["preview"])}"><img loading="lazy" alt="captured and '
                        f'exaggerated poses of {name}" src="{_href(out_dir, paths["preview"])}" class="preview"></a></td>'
                        f'<td><a href="{_href(out_dir, paths["trajectory"])}"><img loading="lazy" alt="path of '
                        f'{_e(info.get("joint", ""))}, captured and exaggerated" src="{_href(out_dir, paths["trajectory"])}" '
                        f'class="trajectory"></a></td>')
    result_info = (listed or {}).get("result", {})
    fps = (listed or {}).get("input", {}).get("fps")
    frames = result.frames if result.frames is not None else result_info.get("frames")
    length = f"<br><small>{frames / fps:.1f} s at {fps:.4g} fps</small>" if frames and fps else ""
    stretch = result.max_link_stretch if result.max_link_stretch is not None else result_info.get("max_link_stretch")
    seconds = result.seconds if result.status == "converted" else (listed or {}).get("timings", {}).get("total")
    return (f'<tr class="{result.status}" id="clip-{number}">'
            f'<td class="clip">{name}<br>{status}<div class="links">{links}</div></td>'
            f'{pictures}<td class="number">{frames if frames is not None else "?"}{length}</td>'
            f'<td class="number">{f"{stretch:.2f}x" if stretch is not None else "?"}</td>'
            f'<td class="events">{_events(result_info.get("stretch"))}</td>'
            f'<td>{_contacts(result_info.get("constraints"))}</td>'
            f'<td class="number">{f"{seconds:.2f} s" if seconds is not None else "?"}'
            f'{"<br><small>(earlier run)</small>" if result.status == "skipped" else ""}</td></tr>')


def _pending_row(clip) -> str:
    return (f'<tr class="pending"><td class="clip">{_e(clip.source)}<br>'
            f'<span class="status pending">not started</span></td><td colspan="7">the batch was interrupted; '
            f'<code>--resume</code> converts it</td></tr>')


def _events(events) -> str:
    """Few events listed; many summed up, with the list one click away."""
    if not events:
        return '<span class="none">none</span>'
    items = []
    for event in events:
        first, last = (event.get("frames") or [None, None])[:2]
        items.append(f'{_e(str(event.get("limb", "?")))} {float(event.get("scale", 0)):.2f}x, frames {first}-{last}')
    if len(items) <= 3:
        return "<br>".join(items)
    scales = [float(event.get("scale", 0)) for event in events]
    limbs = sorted({str(event.get("limb", "?")) for event in events})
    return (f'<details><summary>{len(items)} on {_e(", ".join(limbs))}, {min(scales):.2f}-{max(scales):.2f}x'
            f'</summary>{"<br>".join(items)}</details>')


def _contacts(constraints) -> str:
    contacts = (constraints or {}).get("contacts") or {}
    if not contacts:
        return '<span class="none">none</span>'
    items = []
    for joint, runs in contacts.items():
        held = sum(int(end) - int(start) + 1 for start, end in runs)
        items.append(f"{_e(joint)}: {len(runs)}x, {held} frames down")
    return "<br>".join(items)


def _href(out_dir: Path, path) -> str:
    """A link from the report to ``path``, relative, every character that needs it escaped
    (a name's bytes as they are on disk, UTF-8 or not)."""
    relative = os.path.relpath(Path(path).resolve(), out_dir.resolve())
    return html.escape(quote(os.fsencode(Path(relative).as_posix())), quote=True)


def _e(text) -> str:
    """``text`` for the page: HTML-escaped, a name that is not UTF-8 shown with its odd bytes replaced,
    control characters as Python writes them (``\\x1b``)."""
    text = str(text).encode("utf-8", "surrogateescape").decode("utf-8", "replace")
    return html.escape(printable(text, keep=" \t"), quote=True)


_PAGE = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="generator" content="{generator}">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{title}</title>
<style>
body {{ font: 14px/1.4 system-ui, sans-serif; margin: 1.5em; color: #222; }}
h1 {{ font-size: 1.4em; margin-bottom: 0.2em; }}
.settings, .figures {{ color: #555; margin: 0.2em 0; }}
table {{ border-collapse: collapse; width: 100%; }}
th, td {{ border-bottom: 1px solid #ddd; padding: 6px 8px; vertical-align: top; text-align: left; }}
th {{ background: #f4f4f4; position: sticky; top: 0; }}
td.clip {{ min-width: 11em; max-width: 20em; overflow-wrap: anywhere; }}
td.events {{ min-width: 11em; }}
summary {{ cursor: pointer; }}
td.number {{ text-align: right; white-space: nowrap; }}
img.preview {{ width: 440px; }}
img.trajectory {{ width: 400px; }}
.links a {{ margin-right: 0.5em; font-size: 0.9em; }}
.status {{ font-size: 0.85em; padding: 1px 6px; border-radius: 3px; }}
.status.converted {{ background: #dff3e4; }}
.status.skipped {{ background: #e8eef8; }}
.status.failed {{ background: #f9dcdc; }}
.status.pending {{ background: #f3f3f3; }}
tr.failed td.error {{ color: #a01010; font-family: monospace; }}
tr.skipped td.error {{ color: #555; }}
.none {{ color: #999; }}
</style>
</head>
<body>
<h1>{title}</h1>
<p class="settings">{settings}</p>
<p class="figures"><strong>{summary}</strong>; {figures}</p>
{failures}
<table>
<thead><tr><th>clip</th><th>captured (grey) and exaggerated (orange)</th>
<th>fastest end effector's path: captured (grey), average (green), exaggerated (orange)</th>\
<th>frames</th><th>largest stretch</th>
<th>stretch events</th><th>ground contacts (times, frames)</th><th>time</th></tr></thead>
<tbody>
{rows}
</tbody>
</table>
</body>
</html>
"""
