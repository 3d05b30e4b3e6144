"""Run with a Python that has Blender's ``bpy``: import many BVH files in one launch, write what
Blender sees as JSON (a launch costs seconds; an import of a short clip a fraction of one).

    python read_bvhs.py JOBS.json OUT.json

JOBS.json is a list of {"path": CLIP.bvh, "frames": [frame, ...]}. OUT.json gets
{path: {"bones": N, "frame_range": [start, end], "positions": {frame: {bone: [x, y, z]}}}}
with bone heads in world space, BVH frame numbers counted from 0. Axis conversion is switched
off (forward Y, up Z maps BVH axes onto themselves), so coordinates are the BVH's own.
"""

import json
import sys

import bpy


def read(path: str, frames: list[int]) -> dict:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_anim.bvh(
        filepath=path, axis_forward="Y", axis_up="Z", global_scale=1.0, frame_start=0,
        use_fps_scale=False, update_scene_fps=False, update_scene_duration=True, rotate_mode="NATIVE",
    )
    armature = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
    start, end = armature.animation_data.action.frame_range
    positions = {}
    for frame in frames:
        bpy.context.scene.frame_set(int(start) + frame)  # the first key is BVH frame 0
        positions[frame] = {bone.name: list(armature.matrix_world @ bone.head) for bone in armature.pose.bones}
    return {"bones": len(armature.pose.bones), "frame_range": [start, end], "positions": positions}


def main() -> None:
    with open(sys.argv[1], encoding="utf-8") as file:
        jobs = json.load(file)
    seen = {job["path"]: read(job["path"], [int(f) for f in job["frames"]]) for job in jobs}
    with open(sys.argv[2], "w", encoding="utf-8") as file:
        json.dump(seen, file)


main()
