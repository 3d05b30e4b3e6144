"""Does the output read as animation or as noise? Jerk, pops, twist flips, stretch, drift.

Runs every shared clip through each preset and prints, per clip and preset, the figures of
issue 11 (h = skeleton height, dt = frame time; every frame counts, rest frames included,
so a pop where the rest pose ends shows):

- jerk p99 ratio: the 99th percentile over (frame, original joint) of |third difference of
  world position| on the output, over the same on the capture.
- jump ratio: per original joint, the largest one-frame move |p(t+1) - p(t)| on the output
  over the largest on the capture; the worst joint and its ratio (joints whose captured
  largest move is under 0.1 % h are left out).
- twist flips: (sub-)joint frames whose written local rotation turns more than 60 degrees
  in one frame while the captured joints at both ends of its link (or the joint itself)
  turn less than 30 degrees.
- stretch per limb: the limb's length along the output skeleton (through its sub-joints)
  over its rest length: the peak, the 95th percentile and the share of frames above 1.5x;
  "links" is the largest ratio of any original link's straight length to its rest length.
- drift (h/s): the mean speed of the root on frames where the captured root moves slower
  than 0.1 h/s for at least 0.5 s, on the output and on the capture.

Not a test: run it by hand (``python bench/quality.py``) and quote the figures.
``--json`` writes every figure; ``--clips``, ``--presets`` choose what runs.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

from mocap_exaggerate import load_bvh, load_preset
from mocap_exaggerate.limbs import find_limbs
from mocap_exaggerate.pipeline import run
from mocap_exaggerate.rotations import quat_inv, quat_mul

ROOT = Path(__file__).resolve().parent.parent
SHARED = ROOT.parent / "shared" / "data" / "bvh"
#: Clips whose header states the wrong frame rate (amc2bvh writes 30 fps for 120 Hz captures).
FPS = {"cmu_16_01_jump_amc2bvh.bvh": 120.0}
STRETCHED = 1.5


def turn_degrees(local: np.ndarray) -> np.ndarray:
    """(F-1, J) angle in degrees each joint's local rotation turns from one frame to the next."""
    relative = quat_mul(quat_inv(local[:-1]), local[1:])
    w = np.clip(np.abs(relative[..., 3]), 0.0, 1.0)
    return np.degrees(2.0 * np.arccos(w))


def still_frames(cap: np.ndarray, dt: float, h: float) -> np.ndarray:
    """(F,) frames inside a run of at least 0.5 s where the captured root is slower than 0.1 h/s."""
    speed = np.linalg.norm(np.gradient(cap[:, 0], dt, axis=0), axis=-1) / h
    still = speed < 0.1
    shortest = int(round(0.5 / dt))
    out = np.zeros_like(still)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], still.astype(int), [0]])))
    for start, end in zip(edges[::2], edges[1::2]):
        if end - start >= shortest:
            out[start:end] = True
    return out


def path_to(parents: np.ndarray, base: int, end: int) -> list[int]:
    """Joints from ``end`` up to (not including) ``base`` in a parent array: each ends one link of the path."""
    path, joint = [], end
    while joint != base and joint >= 0:
        path.append(joint)
        joint = int(parents[joint])
    if joint != base:
        raise ValueError("base is not above end")
    return path


def measure(path: Path, preset: str, config=None) -> dict:
    fps = FPS.get(path.name)
    config = config or load_preset(preset)
    motion = load_bvh(path, fps=fps)
    start = time.perf_counter()
    result = run(motion, config)
    seconds = time.perf_counter() - start
    skeleton, dt = motion.skeleton, motion.frame_time
    h = skeleton.height()
    cap_rot, cap = motion.forward_kinematics()
    out_all = result.world_positions
    out = out_all[:, result.original_index]

    def jerk(p):
        return np.linalg.norm(np.diff(p, 3, axis=0), axis=-1)

    jerk_ratio = float(np.percentile(jerk(out), 99) / max(np.percentile(jerk(cap), 99), 1e-12))
    cap_jump = np.linalg.norm(np.diff(cap, axis=0), axis=-1).max(axis=0)
    out_jump = np.linalg.norm(np.diff(out, axis=0), axis=-1).max(axis=0)
    moving = cap_jump > 1e-3 * h
    ratios = np.where(moving, out_jump / np.maximum(cap_jump, 1e-12), 0.0)
    worst = int(np.argmax(ratios))
    worst_frame = int(np.argmax(np.linalg.norm(np.diff(out[:, worst], axis=0), axis=-1)))

    # Twist flips on the written skeleton.
    out_skeleton = result.motion.skeleton
    turns = turn_degrees(result.motion.local_rotations)
    cap_turns = turn_degrees(motion.local_rotations)
    if result.hierarchy is not None and out_skeleton.num_joints != skeleton.num_joints:
        ends = np.stack([result.hierarchy.link_parent, result.hierarchy.link_child], axis=1)
        ends = np.where(ends < 0, ends[:, 1:2], ends)
        reference = cap_turns[:, ends].max(axis=2)
    else:
        reference = cap_turns
    flips = (turns > 60.0) & (reference < 30.0)

    limbs = find_limbs(skeleton)
    rest = skeleton.link_lengths()
    stretch = {}
    out_parents = out_skeleton.parents
    for name, limb in limbs.items():
        rest_length = sum(rest[j] for j in path_to(skeleton.parents, limb.base, limb.end))
        if rest_length <= 1e-6 * h:
            continue
        chain = path_to(out_parents, int(result.original_index[limb.base]), int(result.original_index[limb.end]))
        length = np.linalg.norm(out_all[:, chain] - out_all[:, out_parents[chain]], axis=-1).sum(axis=1)
        ratio = length / rest_length
        stretch[name] = {"peak": float(ratio.max()), "p95": float(np.percentile(ratio, 95)),
                         "above": float(np.mean(ratio > STRETCHED))}
    long_links = rest > 1e-3 * h
    long_links[0] = False
    links = np.linalg.norm(out[:, long_links] - out[:, skeleton.parents[long_links]], axis=-1) / rest[long_links]

    still = still_frames(cap, dt, h)
    root = int(result.original_index[0])

    def drift(p):
        return float((np.linalg.norm(np.gradient(p, dt, axis=0), axis=-1)[still] / h).mean()) if still.any() else None

    limb_peaks = [v["peak"] for k, v in stretch.items() if k.endswith(("_arm", "_leg"))]
    torso_peaks = [v["peak"] for k, v in stretch.items() if k in ("spine", "neck")]
    return {
        "clip": path.name, "preset": preset, "frames": motion.num_frames, "seconds": seconds,
        "jerk_ratio": jerk_ratio,
        "jump_ratio": float(ratios[worst]), "jump_joint": skeleton.names[worst], "jump_frame": worst_frame,
        "jump_h": float(out_jump[worst] / h), "jump_captured_h": float(cap_jump[worst] / h),
        "flips": int(flips.sum()), "max_turn": float(turns.max()) if turns.size else 0.0,
        "stretch": stretch, "links": float(links.max()) if links.size else 1.0,
        "torso_le_limbs": (max(torso_peaks) <= max(limb_peaks) + 1e-9) if torso_peaks and limb_peaks else None,
        "drift": drift(out_all[:, root]), "drift_captured": drift(cap[:, 0]),
        "rest_frames": result.rest_frames,
    }


def cell(value, fmt: str = ".2f") -> str:
    return "-" if value is None else format(value, fmt)


def table(preset: str, rows: list[dict]) -> None:
    print(f"\n### {preset}\n")
    print("| clip | jerk p99 ratio | worst jump ratio (joint, frame) | twist flips | arms peak / p95 / >1.5x "
          "| legs peak / p95 / >1.5x | spine peak | neck peak | links max | drift / captured (h/s) |")
    print("|---" * 10 + "|")
    for r in rows:
        s = r["stretch"]

        def limb_pair(a, b):
            parts = [s[k] for k in (a, b) if k in s]
            if not parts:
                return "-"
            return (f"{max(p['peak'] for p in parts):.2f} / {max(p['p95'] for p in parts):.2f} / "
                    f"{max(p['above'] for p in parts):.0%}")

        print(f"| {r['clip'].removesuffix('.bvh')} | {r['jerk_ratio']:.2f} | {r['jump_ratio']:.2f} "
              f"({r['jump_joint']}, {r['jump_frame']}) | {r['flips']} | {limb_pair('left_arm', 'right_arm')} "
              f"| {limb_pair('left_leg', 'right_leg')} | {cell(s.get('spine', {}).get('peak'))} "
              f"| {cell(s.get('neck', {}).get('peak'))} | {r['links']:.2f} "
              f"| {cell(r['drift'])} / {cell(r['drift_captured'])} |")
    worst = max(rows, key=lambda r: r["jerk_ratio"])
    print(f"\nworst jerk ratio {worst['jerk_ratio']:.2f} ({worst['clip']}); worst jump ratio "
          f"{max(r['jump_ratio'] for r in rows):.2f}; twist flips {sum(r['flips'] for r in rows)}; "
          f"torso above limbs on {sum(r['torso_le_limbs'] is False for r in rows)} clip(s); "
          f"{sum(r['seconds'] for r in rows):.1f} s of pipeline")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--presets", default="subtle,cartoon,looney")
    parser.add_argument("--clips", default="", help="comma-separated substrings of clip names")
    parser.add_argument("--data", type=Path, default=SHARED)
    parser.add_argument("--json", type=Path, default=None, help="also write every figure here")
    args = parser.parse_args()
    wanted = [s for s in args.clips.split(",") if s]
    clips = [p for p in sorted(args.data.glob("*.bvh")) if not wanted or any(s in p.name for s in wanted)]
    if not clips:
        sys.exit(f"no clips in {args.data} match {args.clips!r}")
    everything = {}
    for preset in [p for p in args.presets.split(",") if p]:
        everything[preset] = [measure(path, preset) for path in clips]
        table(preset, everything[preset])
    if args.json:
        args.json.write_text(json.dumps(everything, indent=1) + "\n")


if __name__ == "__main__":
    main()
