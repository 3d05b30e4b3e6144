"""Re-weighting speed: the MakeHuman skin, and a synthetic 50k-vertex skin on a CMU skeleton; the default body's cost.

Prints figures; run by hand: python bench/reweight.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from throughput import best_of as best  # same folder: run as python bench/reweight.py

from mocap_exaggerate.io.bvh import read_bvh
from mocap_exaggerate.io.skin import load_skin
from mocap_exaggerate.rig.body import default_skin
from mocap_exaggerate.rig.skinning import Skin, reweight
from mocap_exaggerate.stages.subjoints import build_hierarchy

ROOT = Path(__file__).resolve().parent.parent
SKIN = ROOT.parent / "shared" / "data" / "skin"


def main() -> None:
    if SKIN.is_dir():
        skin = load_skin(SKIN / "makehuman_base.obj")
        motion, _ = read_bvh(SKIN / "makehuman_default_tpose.bvh")
        hierarchy = build_hierarchy(motion.skeleton)
        seconds = best(lambda: reweight(skin, motion.skeleton, hierarchy))
        print(f"MakeHuman: {skin.num_vertices} vertices, {len(skin.joint_names)} bones -> "
              f"{hierarchy.skeleton.num_joints} sub-joints: {seconds * 1e3:.0f} ms")
    motion, _ = read_bvh(ROOT / "sample_data" / "cmu_09_01_run_daz.bvh")
    hierarchy = build_hierarchy(motion.skeleton)
    body = default_skin(motion.skeleton, hierarchy.rigid)
    seconds = best(lambda: default_skin(motion.skeleton, hierarchy.rigid))
    print(f"default body for the Daz run: {body.num_vertices} vertices in {seconds * 1e3:.1f} ms")
    # 50k vertices: the default body's vertices jittered and repeated, four influences each.
    repeat = int(np.ceil(50_000 / body.num_vertices))
    rng = np.random.default_rng(0)
    vertices = np.repeat(body.vertices, repeat, axis=0)[:50_000]
    vertices = vertices + rng.normal(scale=0.5, size=vertices.shape)
    big = Skin(vertices, body.faces, body.joint_names, np.repeat(body.joints, repeat, axis=0)[:50_000],
               np.repeat(body.weights, repeat, axis=0)[:50_000])
    seconds = best(lambda: reweight(big, motion.skeleton, hierarchy))
    print(f"synthetic: 50000 vertices, 4 influences, {motion.skeleton.num_joints} joints -> "
          f"{hierarchy.skeleton.num_joints} sub-joints: {seconds * 1e3:.0f} ms")


if __name__ == "__main__":
    main()
