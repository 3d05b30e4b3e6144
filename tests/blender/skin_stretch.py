"""Run with a Python that has Blender's ``bpy``: import GLBs, deform their meshes at frames, save what Blender sees.

    python skin_stretch.py JOBS.json

JOBS.json is a list of ``{"glb": PATH, "fps": F, "frames": [f, ...], "out": PATH.npz, "keep": [f, ...]}``:
each GLB is imported alone (factory settings, the scene at the clip's rate so key times land on
frames), and at every frame (counted from 0) its mesh is evaluated through the armature modifier.
The edges are Blender's own (from its imported topology), their rest lengths those of the
un-deformed mesh. Saved to ``out`` (NumPy, glTF's Y-up axes, metres):

    rest (V, 3), edges (E, 2), rest_heads (B, 3), bones (B,) names, frames (N,),
    ratio (E,) the largest length / rest length of each edge over the frames,
    frame_worst (N,) each frame's largest edge ratio, frame_over_2 (N,) its edges past 2x,
    heads (N, B, 3) the bones' heads (the joints) per frame,
    kept (K,) and meshes (K, V, 3): the deformed vertices at the frames ``keep`` asks for.

Prints one line ``JSON:`` with, per GLB, its vertex, edge and bone counts, frame range and seconds.
"""

import json
import sys
import time

import bpy
import numpy as np


def gltf_axes(points: np.ndarray) -> np.ndarray:
    """Blender's Z up back to glTF's Y up (the importer turned +Y into +Z and +Z into -Y)."""
    return np.stack([points[:, 0], points[:, 2], -points[:, 1]], axis=1)


def world(matrix, points: np.ndarray) -> np.ndarray:
    m = np.array(matrix)
    return points @ m[:3, :3].T + m[:3, 3]


def coordinates(mesh) -> np.ndarray:
    flat = np.empty(3 * len(mesh.vertices), dtype=np.float32)
    mesh.vertices.foreach_get("co", flat)
    return flat.reshape(-1, 3).astype(np.float64)


def measure(job: dict) -> dict:
    started = time.perf_counter()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    # The importer puts a key at time t on frame t * fps * fps_base (Blender 5.0's animation_node.py):
    # so that frame f of the clip (time f / rate) lands on frame f, fps * fps_base is the clip's rate.
    rate = float(job["fps"])
    scene.render.fps = max(int(round(rate)), 1)
    scene.render.fps_base = rate / scene.render.fps
    bpy.ops.import_scene.gltf(filepath=job["glb"])
    imported = time.perf_counter()
    armature = next(o for o in scene.objects if o.type == "ARMATURE")
    mesh = next(o for o in scene.objects if o.type == "MESH")
    start, end = armature.animation_data.action.frame_range
    data = mesh.data
    edges = np.empty(2 * len(data.edges), dtype=np.int64)
    data.edges.foreach_get("vertices", edges)
    edges = edges.reshape(-1, 2)
    rest = gltf_axes(world(mesh.matrix_world, coordinates(data)))
    rest_length = np.linalg.norm(rest[edges[:, 1]] - rest[edges[:, 0]], axis=1)
    bones = [bone.name for bone in armature.data.bones]
    rest_heads = gltf_axes(world(armature.matrix_world, np.array([armature.data.bones[n].head_local for n in bones])))
    frames = [int(f) for f in job["frames"]]
    keep = set(int(f) for f in job.get("keep", []))
    ratio = np.zeros(len(edges))
    frame_worst = np.zeros(len(frames))
    frame_over_2 = np.zeros(len(frames), dtype=np.int64)
    heads = np.zeros((len(frames), len(bones), 3))
    kept, meshes = [], []
    safe = np.where(rest_length > 0, rest_length, 1.0)
    for i, frame in enumerate(frames):
        scene.frame_set(int(round(start)) + frame)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        evaluated = mesh.evaluated_get(depsgraph)
        deformed = evaluated.to_mesh()
        points = gltf_axes(world(evaluated.matrix_world, coordinates(deformed)))
        evaluated.to_mesh_clear()
        if len(points) != len(rest):
            raise SystemExit(f"{job['glb']}: the deformed mesh has {len(points)} vertices, the rest one {len(rest)}")
        stretch = np.where(rest_length > 0, np.linalg.norm(points[edges[:, 1]] - points[edges[:, 0]], axis=1) / safe, 0)
        np.maximum(ratio, stretch, out=ratio)
        frame_worst[i] = stretch.max()
        frame_over_2[i] = np.count_nonzero(stretch > 2.0)
        heads[i] = gltf_axes(world(armature.matrix_world, np.array([armature.pose.bones[n].head for n in bones])))
        if frame in keep:
            kept.append(frame)
            meshes.append(points.astype(np.float32))
    np.savez(job["out"], rest=rest, edges=edges, rest_heads=rest_heads, bones=np.array(bones),
             frames=np.array(frames), ratio=ratio, frame_worst=frame_worst, frame_over_2=frame_over_2, heads=heads,
             kept=np.array(kept, dtype=np.int64), meshes=np.array(meshes, dtype=np.float32).reshape(len(kept), -1, 3))
    seconds = {"import": imported - started, "total": time.perf_counter() - started}
    return {"glb": job["glb"], "vertices": len(rest), "edges": len(edges), "bones": len(bones),
            "frame_range": [start, end], "seconds": seconds}


def main() -> None:
    with open(sys.argv[1]) as handle:
        jobs = json.load(handle)
    print("JSON:" + json.dumps([measure(job) for job in jobs]))


main()
