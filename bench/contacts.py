"""Foot contact quality of the pipeline's output: skating, floor penetration, what survives.

Measures the figures of issue 10's acceptance criteria on every clip, for each preset,
with the "contacts" stage (foot planting, floor clamp) on and off. Before that stage
exists (no ``config.contacts``) only the "off" run is made. Definitions (h = skeleton
height, dt = frame time; leading rest frames are left out of every figure):

- up axis u = ``skeleton.up_axis()``; height = sign * coordinate u, sign +1 if the head
  (the neck limb's end and below) is on average above the feet in the capture, else -1;
  horizontal = the other two axes.
- foot points: the end joint of ``left_leg`` / ``right_leg`` (``find_limbs``) and every
  joint below it whose rest link is longer than 1e-4 h (toes).
- captured floor: the lowest height any captured joint reaches.
- planted (per foot point and frame, on the capture): horizontal speed (central
  differences) < 0.25 h/s and height within 0.04 h of that point's 2nd-percentile height.
- skating (h/s): mean horizontal speed over the planted (point, frame) pairs, on the
  capture and on the output positions of the same joints.
- deepest (h): largest (floor - height) / h over every output joint (0 if none below);
  frames below: frames where some output joint is more than 0.01 h below the floor.
- exaggeration kept (both runs only): mean |output - captured| over the original joints,
  leaving out a leg's joints (its limb chain and foot points) within 0.15 s of a planted
  frame of that leg; on-run mean / off-run mean.
- accel (h/s^2): largest |second difference| / dt^2 / h over every output joint; ratio on/off.

Acceptance (issue 10): skating on <= 1.5x captured + 0.01 h/s; no foot more than 1 % of h
below the floor; exaggeration kept >= 80 %; accel ratio <= 2.

Not a test: run it by hand (``python bench/contacts.py``) and quote the figures.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np
from common import FPS, cell, preset_config, run_bench

from mocap_exaggerate import load_bvh
from mocap_exaggerate.analysis.limbs import find_limbs
from mocap_exaggerate.pipeline import run

LEGS = ("left_leg", "right_leg")


def foot_points(skeleton, limbs, h: float) -> dict[str, np.ndarray]:
    lengths = skeleton.link_lengths()
    out = {}
    for leg in LEGS:
        if leg in limbs:
            below = skeleton.descendants(limbs[leg].end)
            out[leg] = np.array([j for j in below if j == limbs[leg].end or lengths[j] > 1e-4 * h])
    return out


def hspeed(points: np.ndarray, horizontal: list[int], dt: float, h: float) -> np.ndarray:
    """(F, K) horizontal speed in h/s, central differences (one-sided at the ends)."""
    return np.linalg.norm(np.gradient(points[..., horizontal], dt, axis=0), axis=-1) / h


def near(flags: np.ndarray, w: int) -> np.ndarray:
    """(F,) True where some flag is set within +-w frames."""
    count = np.concatenate([[0], np.cumsum(flags)])
    t = np.arange(len(flags))
    return count[np.minimum(t + w + 1, len(flags))] - count[np.maximum(t - w, 0)] > 0


def measure(result, cap: np.ndarray, ctx: dict, seconds: float) -> dict:
    first = result.first
    out = result.world_positions[first:]
    height = ctx["sign"] * out[..., ctx["u"]]
    below = ctx["floor"] - height
    h, dt = ctx["h"], ctx["dt"]
    planted, feet = ctx["planted"], ctx["feet"]
    skating = float(hspeed(out[:, result.original_index[feet]], ctx["horizontal"], dt, h)[planted].mean()) \
        if planted.any() else None
    accel = np.linalg.norm(out[2:] - 2 * out[1:-1] + out[:-2], axis=-1) / dt**2 / h
    worst = np.unravel_index(np.argmax(below), below.shape)
    return {"skating": skating, "deepest": max(float(below.max()) / h, 0.0),
            "deepest_joint": result.motion.skeleton.names[worst[1]],
            "frames_below": int((below > 0.01 * h).any(axis=1).sum()),
            "accel": float(accel.max()) if len(accel) else 0.0, "seconds": seconds,
            "displacement": np.linalg.norm(out[:, result.original_index] - cap, axis=-1)}


def clip_figures(path: Path, preset: str) -> dict:
    fps = FPS.get(path.name)
    config = preset_config(preset)
    motion = load_bvh(path, fps=fps)
    configs = {"off": config}
    if hasattr(config, "contacts"):
        configs = {"on": config, "off": dataclasses.replace(
            config, contacts=dataclasses.replace(config.contacts, enabled=False))}
    results = {}
    for name, cfg in configs.items():
        start = time.perf_counter()
        results[name] = (run(motion, cfg), time.perf_counter() - start)

    skeleton = motion.skeleton
    first = next(iter(results.values()))[0].rest_frames
    cap = motion.world_positions()[first:]
    h, u, dt = skeleton.height(), skeleton.up_axis(), motion.frame_time
    limbs = find_limbs(skeleton)
    points = foot_points(skeleton, limbs, h)
    feet = np.concatenate(list(points.values())) if points else np.zeros(0, int)
    head = skeleton.descendants(limbs["neck"].end) if "neck" in limbs else \
        np.setdiff1d(np.arange(skeleton.num_joints), feet)
    foot_mean = cap[:, feet, u].mean() if len(feet) else cap[..., u].min()
    sign = 1.0 if cap[:, head, u].mean() > foot_mean else -1.0
    height = sign * cap[..., u]
    floor = float(height.min())
    horizontal = [a for a in range(3) if a != u]
    foot_h = height[:, feet]
    planted = (hspeed(cap[:, feet], horizontal, dt, h) < 0.25) & \
        (foot_h - np.percentile(foot_h, 2, axis=0) < 0.04 * h)
    ctx = dict(h=h, u=u, dt=dt, sign=sign, floor=floor, horizontal=horizontal, planted=planted, feet=feet)
    runs = {name: measure(res, cap, ctx, seconds) for name, (res, seconds) in results.items()}

    keep = np.ones(cap.shape[:2], bool)
    column = 0
    for leg, joints in points.items():
        leg_planted = planted[:, column:column + len(joints)].any(axis=1)
        column += len(joints)
        moving = np.union1d(joints, limbs[leg].joints)
        keep[:, moving] &= ~near(leg_planted, int(round(0.15 / dt)))[:, None]
    figures = {"clip": path.name, "frames": len(cap), "rest_frames": first, "height": h, "up": [u, sign],
               "legs": list(points), "foot_points": [skeleton.names[j] for j in feet],
               "floor_joint": skeleton.names[int(np.argmin(height.min(axis=0)))],
               "planted_pairs": int(planted.sum()),
               "accel_captured": float((np.linalg.norm(np.diff(cap, 2, axis=0), axis=-1) / dt**2 / h).max()),
               "skating_captured": float(hspeed(cap[:, feet], horizontal, dt, h)[planted].mean())
               if planted.any() else None}
    if "on" in runs and keep.any():
        figures["exaggeration_kept"] = float(runs["on"]["displacement"][keep].mean()
                                             / runs["off"]["displacement"][keep].mean())
        figures["accel_ratio"] = runs["on"]["accel"] / runs["off"]["accel"]
    for run_figures in runs.values():
        del run_figures["displacement"]
    figures["runs"] = runs
    return figures


def table(preset: str, rows: list[dict]) -> None:
    print(f"\n### {preset}\n")
    print("| clip | frames | skating captured | skating off | skating on | deepest off (h) | frames below off "
          "| deepest on | frames below on | exaggeration kept | accel off | accel on | ratio | wall off / on (s) |")
    print("|---" * 14 + "|")
    for r in rows:
        off, on = r["runs"]["off"], r["runs"].get("on", {})
        print(f"| {r['clip']} | {r['frames']} | {cell(r['skating_captured'], '.3f')} | {cell(off['skating'], '.3f')} "
              f"| {cell(on.get('skating'), '.3f')} | {off['deepest']:.4f} | {off['frames_below']} "
              f"| {cell(on.get('deepest'), '.4f')} | {cell(on.get('frames_below'), 'd')} "
              f"| {cell(r.get('exaggeration_kept'), '.1%')} | {off['accel']:.0f} | {cell(on.get('accel'), '.0f')} "
              f"| {cell(r.get('accel_ratio'), '.2f')} | {off['seconds']:.2f} / {cell(on.get('seconds'), '.2f')} |")
    for r in rows:
        if len(r["legs"]) < 2:
            print(f"- {r['clip']}: legs found: {r['legs'] or 'none'}")
        if r["floor_joint"] not in r["foot_points"]:
            print(f"- {r['clip']}: the captured floor is set by {r['floor_joint']}, not a foot point")
        if not r["planted_pairs"]:
            print(f"- {r['clip']}: no planted frames found")


def main() -> None:
    run_bench(__doc__.splitlines()[0], clip_figures, table, presets="cartoon,looney")


if __name__ == "__main__":
    main()
