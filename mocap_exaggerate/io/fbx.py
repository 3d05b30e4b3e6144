"""FBX output through Blender: our GLB imported and exported as FBX, headless.

No library writes FBX well from Python (Autodesk's SDK is not on PyPI for current Pythons; the
pure writers drop skinning or animation), and Blender's exporter is what studios already trust,
so the GLB we write is handed to Blender in a separate process: imported with its glTF importer
and exported with the options game and DCC pipelines set:

- Y up, -Z forward (FBX's and Maya's, Unity's and Unreal's importers turn it as they expect);
- no leaf bones (Blender would add a ``_end`` bone to every chain);
- bones along their own +Y (Blender's convention: an FBX bone's local +Y points to its child;
  the joints stay where they are, each bone's rest orientation is what changes);
- the animation baked at every frame with no key reduction, so every joint is where the BVH
  puts it at every frame;
- metres: Blender's unit scale written as FBX's ``UnitScaleFactor`` (100: centimetres), so Maya,
  Unity and Unreal read a figure of the right size.

Blender is found as, in order: ``MOCAP_BPY_PYTHON`` (a Python whose ``import bpy`` works: the
``bpy`` module needs Python 3.11 and numpy < 2, so it often lives in its own virtualenv), this
Python when it has ``bpy`` (``pip install 'mocap-exaggerate[fbx]'`` on Python 3.11), or a
``blender`` executable on ``PATH``.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from ..core.errors import ConfigError, MocapError

__all__ = ["FBX_HELP", "blender_command", "require_blender", "glb_to_fbx"]

FBX_HELP = ("FBX output needs Blender: pip install 'mocap-exaggerate[fbx]' (Blender's bpy, Python 3.11), or "
            "MOCAP_BPY_PYTHON=/path/to/a/python/with/bpy, or blender on PATH")

#: Seconds Blender may take to turn one GLB into FBX (a long clip's bake is most of it).
TIMEOUT = 1800

_SCRIPT = r'''
import sys
import bpy

argv = sys.argv[sys.argv.index("--") + 1:]
glb, fbx, fps = argv[0], argv[1], float(argv[2])
# The same input, the same bytes: the header's creation time is the exporter's only clock.
import datetime
import io_scene_fbx.export_fbx_bin as fbx_bin
_header = fbx_bin.fbx_header_elements
fbx_bin.fbx_header_elements = lambda root, scene_data, time=None: _header(root, scene_data,
                                                                          datetime.datetime(2000, 1, 1))
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
scene.render.fps = int(round(fps))
scene.render.fps_base = round(fps) / fps
bpy.ops.import_scene.gltf(filepath=glb)
armature = next(o for o in scene.objects if o.type == "ARMATURE")
start, end = armature.animation_data.action.frame_range
scene.frame_start, scene.frame_end = int(round(start)), int(round(end))
bpy.ops.export_scene.fbx(
    filepath=fbx, use_selection=False, object_types={"ARMATURE", "MESH"},
    apply_unit_scale=True, apply_scale_options="FBX_SCALE_NONE", global_scale=1.0,
    axis_forward="-Z", axis_up="Y", add_leaf_bones=False, primary_bone_axis="Y", secondary_bone_axis="X",
    use_armature_deform_only=False, mesh_smooth_type="FACE",
    bake_anim=True, bake_anim_use_all_bones=True, bake_anim_use_nla_strips=False, bake_anim_use_all_actions=False,
    bake_anim_force_startend_keying=True, bake_anim_step=1.0, bake_anim_simplify_factor=0.0)
print("mocap_exaggerate: FBX written")
'''


def blender_command() -> list[str] | None:
    """The command that runs a Blender Python script given after it (``-c``-style), or None."""
    explicit = os.environ.get("MOCAP_BPY_PYTHON")
    if explicit:
        return [explicit, "-c"] if Path(explicit).exists() else None
    if importlib.util.find_spec("bpy") is not None:
        return [sys.executable, "-c"]
    blender = shutil.which("blender")
    if blender:
        return [blender, "-b", "--factory-startup", "--python-exit-code", "1", "--python-expr"]
    return None


def require_blender() -> list[str]:
    """`blender_command`, or a one-line `ConfigError` saying what to install."""
    command = blender_command()
    if command is None:
        raise ConfigError(FBX_HELP)
    return command


def glb_to_fbx(glb: bytes, *, fps: float, command: list[str] | None = None, timeout: float = TIMEOUT) -> bytes:
    """The FBX of a GLB's skinned, animated character (see the module's notes), by Blender."""
    command = command or require_blender()
    with tempfile.TemporaryDirectory(prefix="mocap_fbx_") as folder:
        source, target = Path(folder) / "in.glb", Path(folder) / "out.fbx"
        source.write_bytes(glb)
        try:
            # Blender numbers the FBX's objects through Python's hashing: one seed, one file.
            done = subprocess.run([*command, _SCRIPT, "--", str(source), str(target), repr(float(fps))],
                                  capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL,
                                  env={**os.environ, "PYTHONHASHSEED": "0"})
        except subprocess.TimeoutExpired:
            raise MocapError(f"Blender took more than {timeout:g} s to write the FBX") from None
        except OSError as error:
            raise ConfigError(f"could not start Blender ({command[0]}: {error.strerror or error}); {FBX_HELP}") from None
        if done.returncode != 0 or not target.exists():
            said = (done.stderr or done.stdout).strip().splitlines()
            last = said[-1][:300] if said else f"exit code {done.returncode}"
            raise MocapError(f"Blender could not write the FBX: {last}")
        return target.read_bytes()
