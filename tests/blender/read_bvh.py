"""Run with a Python that has Blender's ``bpy``: import a BVH, print what Blender sees as JSON.

    python read_bvh.py CLIP.bvh FRAME [FRAME ...]

Prints {"bones": N, "frame_range": [start, end], "positions": {frame: {bone: [x, y, z]}}}
with bone heads in world space, BVH frame numbers counted from 0. Axis conversion is
switched off (forward Y, up Z maps BVH axes onto themselves), so coordinates are the BVH's own.
"""

import json
import sys

import bpy


def main() -> None:
    path = sys.argv[1]
    frames = [int(f) for f in sys.argv[2:]]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_anim.bvh(
        filepath=path, axis_forward="Y", axis_up="Z", global_scale=1.0, frame_start=0,
        use_fps_scale=False, update_scene_fps=False, update_scene_duration=True, rotate_mode="NATIVE",
    )
    armature = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
    action = armature.animation_data.action
    start, end = action.frame_range
    positions = {}
    for frame in frames:
        bpy.context.scene.frame_set(int(start) + frame)  # the first key is BVH frame 0
        positions[frame] = {
            bone.name: list(armature.matrix_world @ bone.head) for bone in armature.pose.bones
        }
    print("JSON:" + json.dumps({"bones": len(armature.pose.bones), "frame_range": [start, end],
                                 "positions": positions}))


main()
