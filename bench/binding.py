"""Binding the MakeHuman body to every shared clip: how long it takes and how well the mesh holds.

For each clip: the binding's time (best of 3), the joints paired, the clip joints turned to pose its
limbs like the body (``Skin.pose``), and the share of the body's faces whose longest edge stretches
past 2x its length on the character itself (scaled by the binding's scale) at some of 12 evenly
spaced frames, in the captured motion and on the cartoon preset's rubber skeleton (the GLB's), with
the largest stretch of any edge. Prints figures; run by hand: python bench/binding.py [--data ../shared/data]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from common import FPS  # same folder: run as python bench/binding.py
from throughput import best_of

from mocap_exaggerate.config import load_preset
from mocap_exaggerate.io.bvh import read_bvh
from mocap_exaggerate.io.skin import load_skin
from mocap_exaggerate.jobs.outputs import at_bind_pose, output_skin
from mocap_exaggerate.pipeline import run
from mocap_exaggerate.rig.binding import bind_skin
from mocap_exaggerate.rig.skinning import pose_skin

ROOT = Path(__file__).resolve().parent.parent


def stretched(skin, reference, bind, rotations, positions, index, frames) -> tuple[float, float]:
    """Share of faces whose longest edge passes 2x its length on ``reference`` (the character's own
    vertices, scaled as bound) at some of ``frames``, and the largest stretch of any edge."""
    edges = np.concatenate([skin.faces[:, [0, 1]], skin.faces[:, [1, 2]], skin.faces[:, [2, 0]]])
    own = np.linalg.norm(np.diff(reference[edges], axis=1)[:, 0], axis=1)
    worst = np.zeros(len(skin.faces))
    for frame in frames:
        posed = pose_skin(skin, bind, rotations[frame], positions[frame], index)
        ratio = np.linalg.norm(np.diff(posed[edges], axis=1)[:, 0], axis=1) / np.maximum(own, 1e-12)
        worst = np.maximum(worst, ratio.reshape(3, -1).max(axis=0))
    return float(np.mean(worst > 2.0)), float(worst.max())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data")
    args = parser.parse_args()
    body = load_skin(args.data / "skin" / "makehuman_base.obj")
    clips = sorted((args.data / "bvh").glob("*.bvh")) + [args.data / "skin" / "makehuman_default_tpose.bvh"]
    print(f"MakeHuman body: {body.num_vertices} vertices, {len(body.joint_names)} weighted bones")
    print(f"{'clip':44s} {'ms':>5s} {'pairs':>5s} {'posed':>5s} {'captured >2x':>13s} {'worst':>6s} "
          f"{'cartoon >2x':>12s} {'worst':>6s}")
    for path in clips:
        motion, _ = read_bvh(path, fps=FPS.get(path.name))
        skeleton = motion.skeleton
        seconds = best_of(lambda skeleton=skeleton: bind_skin(body, skeleton), 3)
        bound, binding = bind_skin(body, skeleton)
        reference = body.vertices * binding.scale
        result = run(motion, load_preset("cartoon"))
        motion, result, bound = at_bind_pose(motion, result, bound)  # the pose it is bound in, as the GLB's rest
        skeleton = motion.skeleton
        frames = np.linspace(0, motion.num_frames - 1, min(12, motion.num_frames)).astype(int)
        rotations, positions = motion.forward_kinematics()
        index = np.array([skeleton.index(n) for n in bound.joint_names])
        captured = stretched(bound, reference, skeleton.rest_positions(), rotations, positions, index, frames)
        rubber = output_skin(motion, result, bound)
        out = result.motion.skeleton
        index = np.array([out.index(n) for n in rubber.joint_names])
        frames = np.linspace(0, result.motion.num_frames - 1, min(12, result.motion.num_frames)).astype(int)
        cartoon = stretched(rubber, reference, out.rest_positions(), result.world_rotations, result.world_positions,
                            index, frames)
        print(f"{path.name[:44]:44s} {seconds * 1e3:5.0f} {len(binding.pairs):5d} {binding.posed:5d} "
              f"{captured[0]:12.2%} {captured[1]:6.2f} {cartoon[0]:11.2%} {cartoon[1]:6.2f}")


if __name__ == "__main__":
    main()
