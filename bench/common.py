"""What the bench scripts share: where the shared clips are, their known wrong headers, and the
command line that picks clips and presets, measures each pair and prints a table per preset."""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SHARED = ROOT.parent / "shared" / "data" / "bvh"
#: Clips whose header states the wrong frame rate (amc2bvh writes 30 fps for 120 Hz captures).
FPS = {"cmu_16_01_jump_amc2bvh.bvh": 120.0}
#: Settings laid over every preset by ``--set KEY=VALUE`` (a dotted key, a TOML value), as the CLI's ``--set``.
OVERRIDES: dict = {}


def preset_config(preset: str):
    """The preset with the command line's ``--set`` overrides laid over it."""
    from mocap_exaggerate.config import resolve_config

    return resolve_config(preset, overrides=OVERRIDES)


def cell(value, fmt: str = ".2f") -> str:
    return "-" if value is None else format(value, fmt)


def settings_table(items) -> dict:
    """``--set`` pairs as the CLI reads them (`mocap_exaggerate_cli.options.settings_table`)."""
    import click

    from mocap_exaggerate_cli.options import settings_table as table

    try:
        return table(tuple(items))
    except click.BadParameter as error:
        raise SystemExit(f"--set: {error.message}") from None


def run_bench(description: str, measure: Callable[[Path, str], dict], table: Callable[[str, list], None], *,
              presets: str) -> None:
    """Parse ``--presets --clips --data --json``, measure every clip with every preset, print the tables."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--presets", default=presets)
    parser.add_argument("--clips", default="", help="comma-separated substrings of clip names")
    parser.add_argument("--data", type=Path, default=SHARED)
    parser.add_argument("--json", type=Path, default=None, help="also write every figure here")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="a setting laid over each preset, e.g. subjoints.enabled=false (repeatable)")
    args = parser.parse_args()
    OVERRIDES.update(settings_table(args.set))
    wanted = [s for s in args.clips.split(",") if s]
    clips = [p for p in sorted(args.data.glob("*.bvh")) if not wanted or any(s in p.name for s in wanted)]
    if not clips:
        raise SystemExit(f"no clips in {args.data} match {args.clips!r}")
    everything = {}
    for preset in [p for p in args.presets.split(",") if p]:
        everything[preset] = [measure(path, preset) for path in clips]
        table(preset, everything[preset])
    if args.json:
        args.json.write_text(json.dumps(everything, indent=1) + "\n")
