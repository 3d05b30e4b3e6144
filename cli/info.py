"""``mocap-exaggerate info``: what a clip holds (joints, channels, frames, limbs, contacts)."""

from __future__ import annotations

import json
from pathlib import Path

import click

from .app import cli, fail_cleanly, printable, verbosity_options
from .options import FilePath


@cli.command()
@click.argument("input_path", metavar="IN.bvh", type=FilePath(path_type=Path, allow_dash=True))
@click.option("--limbs", is_flag=True, help="Also list the limbs found (base to end effector).")
@click.option("--groups", is_flag=True, help="Also list the rubber-joint groups and the joints that ride rigidly.")
@click.option("--contacts", is_flag=True, help="Also list where the end effectors touch the ground (frames).")
@click.option("--fps", type=float, default=None, help="Frame rate overriding the file's Frame Time.")
@click.option("--root-offset", "root_offset", type=click.Choice(["auto", "replace", "add"]), default="auto",
              show_default=True, help="Position channels replace the joint's OFFSET or add to it (iClone, MakeHuman).")
@click.option("--up", type=click.Choice(["auto", "x", "y", "z"]), default="auto", show_default=True,
              help="The axis the body stands along.")
@click.option("--clip", default="", metavar="NAME",
              help="With a .glb/.gltf: the animation to describe (default: the first; all are listed).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object instead of text.")
@verbosity_options
@fail_cleanly
def info(input_path: Path, limbs: bool, groups: bool, contacts: bool, fps: float | None, root_offset: str, up: str,
         clip: str, as_json: bool) -> None:
    """Describe a clip: joints, channels, rotation orders, frames, fps, duration, height.

    A skinned, animated .glb/.gltf is read as one of its animations (--clip), and all of them
    are listed.

    \b
    Example:
      mocap-exaggerate info sample_data/cmu_09_01_run_daz.bvh --limbs --groups --contacts
      mocap-exaggerate info ../shared/data/gltf/fox_khronos.glb --clip Walk --limbs
    """
    from mocap_exaggerate.jobs.job import describe

    label = "<stdin>" if str(input_path) == "-" else str(input_path)
    data = describe(input_path, fps=fps, limbs=limbs, groups=groups, contacts=contacts, label=label,
                    root_offset=root_offset, up=up, clip=clip)
    orders = data["rotation_orders"]
    if as_json:
        click.echo(json.dumps(data, indent=2))  # (JSON escapes control characters itself)
        return
    say(f"{label}")
    say(f"  joints      {data['joints']} (+{data['end_sites']} End Sites), root {data['root']}")
    added = " (added to the OFFSET: --root-offset add)" if data["root_offset"] == "add" else ""
    say(f"  channels    {data['channels']}; position channels on "
               f"{', '.join(data['position_channel_joints'][:6]) or 'none'}"
               f"{' ...' if len(data['position_channel_joints']) > 6 else ''}{added}")
    say(f"  rotation    {', '.join(f'{o} x{n}' for o, n in orders.items())}")
    say(f"  frames      {data['frames']} at {data['fps']:g} fps ({data['duration_s']:.3f} s)")
    say(f"  height      {data['height']:g} units along {data['up_axis']} (rest pose)")
    for animation in data.get("animations", []):
        taken = " (this one)" if animation["name"] == data["clip"] else ""
        say(f"  animation   {animation['name']}: {animation['duration_s']:g} s, {animation['keys']} keys, "
                   f"{animation['channels']} channels{taken}")
    if data["rest_frames"]:
        say(f"  rest pose   {data['rest_frames']} leading synthetic frame(s) (see --tpose)")
    if data["loop"]:
        say(f"  loop        a cycle of {data['loop']['period']} frames, its last frame its first: exaggerated as "
            "a loop (see --loop)")
    for warning in data["warnings"]:
        say(f"  warning     {warning}")
    if limbs:
        for name, chain in data["limbs"].items():
            say(f"  {name:<11} {' > '.join(chain)}")
    if contacts:
        floor = data["contacts"]["floor"]
        say(f"  floor       {floor['height']:g} along {floor['up']}{floor['axis']} (the lowest any joint goes)")
        for joint, runs in data["contacts"]["contacts"].items():
            spans = ", ".join(f"{a}-{b}" for a, b in runs) or "none"
            say(f"  contact     {joint}: {spans}")
    if groups:
        say(f"  sub-joints  {data['subjoints'] - data['joints']}: the default output's {data['subjoints']} joints "
            "(4 sub-links per link)")
        for chain in data["groups"]:
            say(f"  group       {chain[0]} | {' > '.join(chain[1:])}")
        rigid = data["rigid"]
        if rigid:
            shown = ", ".join(rigid[:8]) + (f", ... ({len(rigid)} in all)" if len(rigid) > 8 else "")
            say(f"  rigid       {shown}")


def say(line: str) -> None:
    """One line of the report, names in it escaped (`printable`): a joint called ESC[2J shows, not clears."""
    click.echo(printable(line))
