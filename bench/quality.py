"""Does the output read as animation or as noise? Jerk, pops, twist flips, stretch, drift.

Runs every shared clip through each preset and prints, per clip and preset, the figures of
`mocap_exaggerate.analysis.quality.motion_quality` (issue 11; h = skeleton height): jerk p99 ratio
(output over capture), the worst joint's largest one-frame move over its captured largest,
twist flips (a written joint turning > 60 degrees in a frame where the capture turns < 30),
limb stretch along the output skeleton (peak / 95th percentile / share of frames above
1.5x; arms and legs the worse of the pair), the largest original link stretch, and drift
(root speed where the captured root stands still, h/s), frames with a hand, forearm, foot or shin
inside the body, output and capture (issue 25), and knee and elbow frames bent backwards.

Not a test: run it by hand (``python bench/quality.py``) and quote the figures.
``--json`` writes every figure; ``--clips``, ``--presets`` choose what runs; ``--set KEY=VALUE`` lays a
setting over each preset (``--set subjoints.enabled=false``: the knees of the two-bone solve, issue 25).
"""

from __future__ import annotations

import time
from pathlib import Path

from common import FPS, cell, preset_config, run_bench

from mocap_exaggerate import load_bvh
from mocap_exaggerate.analysis.quality import motion_quality
from mocap_exaggerate.pipeline import run


def measure(path: Path, preset: str, config=None) -> dict:
    fps = FPS.get(path.name)
    config = config or preset_config(preset)
    motion = load_bvh(path, fps=fps)
    start = time.perf_counter()
    result = run(motion, config)
    seconds = time.perf_counter() - start
    return {"clip": path.name, "preset": preset, "frames": motion.num_frames, "seconds": seconds,
            "rest_frames": result.rest_frames, **motion_quality(motion, result)}


def table(preset: str, rows: list[dict]) -> None:
    print(f"\n### {preset}\n")
    print("| clip | jerk p99 ratio | worst jump ratio (joint, frame) | twist flips | arms peak / p95 / >1.5x "
          "| legs peak / p95 / >1.5x | spine peak | neck peak | links max | drift / captured (h/s) "
          "| frames a limb is inside the body / captured | knees, elbows backwards |")
    print("|---" * 12 + "|")
    for r in rows:
        s = r["stretch"]

        def limb_pair(a, b, s=s):
            parts = [s[k] for k in (a, b) if k in s]
            if not parts:
                return "-"
            return (f"{max(p['peak'] for p in parts):.2f} / {max(p['p95'] for p in parts):.2f} / "
                    f"{max(p['above'] for p in parts):.0%}")

        print(f"| {r['clip'].removesuffix('.bvh')} | {r['jerk_ratio']:.2f} | {r['jump_ratio']:.2f} "
              f"({r['jump_joint']}, {r['jump_frame']}) | {r['flips']} | {limb_pair('left_arm', 'right_arm')} "
              f"| {limb_pair('left_leg', 'right_leg')} | {cell(s.get('spine', {}).get('peak'))} "
              f"| {cell(s.get('neck', {}).get('peak'))} | {r['links']:.2f} "
              f"| {cell(r['drift'])} / {cell(r['drift_captured'])} | {r['inside']} / {r['inside_captured']} "
              f"| {r['backwards']} |")
    worst = max(rows, key=lambda r: r["jerk_ratio"])
    print(f"\nworst jerk ratio {worst['jerk_ratio']:.2f} ({worst['clip']}); worst jump ratio "
          f"{max(r['jump_ratio'] for r in rows):.2f}; twist flips {sum(r['flips'] for r in rows)}; "
          f"torso above a limb on {sum(r['torso_within_limbs'] is False for r in rows)} clip(s); "
          f"limbs inside the body {sum(r['inside'] for r in rows)} frames (captured "
          f"{sum(r['inside_captured'] for r in rows)}; more than captured on "
          f"{sum(r['inside'] > r['inside_captured'] for r in rows)} clip(s)); knees and elbows backwards "
          f"{sum(r['backwards'] for r in rows)}; "
          f"{sum(r['seconds'] for r in rows):.1f} s of pipeline")


def main() -> None:
    run_bench(__doc__.splitlines()[0], measure, table, presets="subtle,cartoon,looney")


if __name__ == "__main__":
    main()
