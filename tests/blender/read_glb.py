"""Run with a Python that has Blender's ``bpy``: import a GLB, print what Blender sees as JSON.

    python read_glb.py FILE.glb FPS FRAME [FRAME ...]

Prints {"bones": N, "frame_range": [a, b], "vertices": V, "fps": f, "meshes": {frame: [[x, y, z], ...]},
"heads": {frame: {bone: [x, y, z]}}} with the deformed (evaluated) mesh and the bones' heads in world
space, in glTF's Y-up axes, frames counted from 0.
"""

import json
import sys

import bpy


def main() -> None:
    path = sys.argv[1]
    fps = float(sys.argv[2])
    frames = [int(f) for f in sys.argv[3:]]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    # The importer turns key times into frames at the scene's rate: match the clip's.
    bpy.context.scene.render.fps = int(round(fps))
    bpy.context.scene.render.fps_base = round(fps) / fps
    bpy.ops.import_scene.gltf(filepath=path)
    scene = bpy.context.scene
    armature = next(o for o in scene.objects if o.type == "ARMATURE")
    mesh = next(o for o in scene.objects if o.type == "MESH")
    action = armature.animation_data.action
    start, end = action.frame_range
    fps = scene.render.fps / scene.render.fps_base
    meshes, heads = {}, {}
    for frame in frames:
        scene.frame_set(int(round(start)) + frame)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        evaluated = mesh.evaluated_get(depsgraph)
        data = evaluated.to_mesh()
        world = evaluated.matrix_world
        # Blender is Z-up; the importer turned glTF's Y-up into it: undo that for comparison.
        points = [world @ v.co for v in data.vertices]
        meshes[frame] = [[p.x, p.z, -p.y] for p in points]
        evaluated.to_mesh_clear()
        heads[frame] = {}
        for bone in armature.pose.bones:
            p = armature.matrix_world @ bone.head
            heads[frame][bone.name] = [p.x, p.z, -p.y]
    print("JSON:" + json.dumps({"bones": len(armature.data.bones), "frame_range": [start, end],
                                 "vertices": len(mesh.data.vertices), "fps": fps, "meshes": meshes,
                                 "heads": heads}))


main()
