"""Run with a Python that has Blender's ``bpy``: import an FBX, print what Blender sees as JSON.

    python read_fbx.py FILE.fbx FPS FRAME [FRAME ...]

Prints {"bones": N, "names": [...], "frame_range": [a, b], "vertices": V, "unit_scale": s,
"heads": {frame: {bone: [x, y, z]}}, "leaf_bones": n} with the bones' heads in world space in
glTF's Y-up axes and metres, frames counted from the action's first.
"""

import json
import sys

import bpy


def main() -> None:
    path = sys.argv[1]
    fps = float(sys.argv[2])
    frames = [int(f) for f in sys.argv[3:]]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = int(round(fps))
    scene.render.fps_base = round(fps) / fps
    bpy.ops.import_scene.fbx(filepath=path)
    armature = next(o for o in scene.objects if o.type == "ARMATURE")
    mesh = next(o for o in scene.objects if o.type == "MESH")
    start, end = armature.animation_data.action.frame_range
    heads = {}
    for frame in frames:
        scene.frame_set(int(round(start)) + frame)
        heads[frame] = {}
        for bone in armature.pose.bones:
            p = armature.matrix_world @ bone.head
            heads[frame][bone.name] = [p.x, p.z, -p.y]
    names = [bone.name for bone in armature.data.bones]
    print("JSON:" + json.dumps({"bones": len(names), "names": names, "frame_range": [start, end],
                                 "vertices": len(mesh.data.vertices), "heads": heads,
                                 "leaf_bones": sum(name.endswith("_end") for name in names)}))


main()
