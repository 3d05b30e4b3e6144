"""Shared test helpers: where the test clips are (the shipped samples and the real data beside
the checkout), the malformed BVH inputs, and skinning a GLB by its own data."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pygltflib
import pytest

from mocap_exaggerate.core.rotations import quat_rotate

ROOT = Path(__file__).resolve().parent.parent
SAMPLE_DIR = ROOT / "sample_data"
SHARED_BVH = ROOT.parent / "shared" / "data" / "bvh"

SAMPLE_CLIPS = sorted(SAMPLE_DIR.glob("*.bvh"))
SHARED_CLIPS = sorted(SHARED_BVH.glob("*.bvh")) if SHARED_BVH.is_dir() else []
SHARED_REASON = f"real-data clips not found at {SHARED_BVH} (CI has ../shared beside the checkout)"


def shared_clip_params(wide: bool = False):
    """Parametrize over every shared clip (and, with ``wide``, the wider corpus in ``wide/``), or one
    skipped case that says why."""
    if not SHARED_CLIPS:
        return [pytest.param(None, marks=pytest.mark.skip(reason=SHARED_REASON), id="no-shared-data")]
    more = sorted((SHARED_BVH / "wide").glob("*.bvh")) if wide else []
    return [pytest.param(p, id=p.stem) for p in SHARED_CLIPS] + [pytest.param(p, id=f"wide-{p.stem}") for p in more]


def all_clip_params():
    """Sample clips always; shared clips where present."""
    params = [pytest.param(p, id=f"sample-{p.stem}") for p in SAMPLE_CLIPS]
    return params + (shared_clip_params() if SHARED_CLIPS else [])


def shared(name: str) -> Path:
    """A shared clip by file name; skips the test, saying why, when the folder is absent."""
    path = SHARED_BVH / name
    if not path.exists():
        pytest.skip(SHARED_REASON)
    return path


def make_bvh(body: str, motion: str = "Frames: 2\nFrame Time: 0.1\n0 0 0 0 0 0 0 0 0\n1 2 3 10 20 30 5 6 7\n") -> bytes:
    return f"HIERARCHY\n{body}MOTION\n{motion}".encode()


SIMPLE = """ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Spine
  {
    OFFSET 0 1 0
    CHANNELS 3 Xrotation Yrotation Zrotation
    End Site
    {
      OFFSET 0 1 0
    }
  }
}
"""


MALFORMED = {
    "empty": (b"", 1, "empty"),
    "not bvh": (b"{\"json\": true}\n", 1, "HIERARCHY"),
    "binary": (b"\x00\x01\x02HIERARCHY", 1, "binary"),
    "no root": (b"HIERARCHY\nJOINT x\n", 2, "ROOT"),
    "no motion": (make_bvh(SIMPLE, "")[: -len(b"MOTION\n")], 15, "MOTION"),
    "unknown channel": (make_bvh(SIMPLE.replace("Zrotation Xrotation", "Wrotation Xrotation")), 5, "Wrotation"),
    "channel count too big": (make_bvh(SIMPLE.replace("CHANNELS 3", "CHANNELS 4")), 9, "CHANNELS"),
    "channel count not a number": (make_bvh(SIMPLE.replace("CHANNELS 3", "CHANNELS three")), 9, "three"),
    "offset not a number": (make_bvh(SIMPLE.replace("OFFSET 0 1 0\n    CHANNELS", "OFFSET 0 x 0\n    CHANNELS")), 8, "OFFSET"),
    "missing brace": (make_bvh(SIMPLE.replace("  JOINT Spine\n  {", "  JOINT Spine\n")), 8, "{"),
    "unbalanced": (make_bvh(SIMPLE + "}\n"), 16, "unbalanced"),
    "two roots": (make_bvh(SIMPLE + SIMPLE), 16, "ROOT"),
    "duplicate name": (make_bvh(SIMPLE.replace("JOINT Spine", "JOINT Hips")), 6, "twice"),
    "frames missing": (make_bvh(SIMPLE, "Frame Time: 0.1\n1 2 3 4 5 6 7 8 9\n"), 17, "Frames"),
    "frames not number": (make_bvh(SIMPLE, "Frames: many\nFrame Time: 0.1\n"), 17, "many"),
    "zero frames": (make_bvh(SIMPLE, "Frames: 0\nFrame Time: 0.1\n"), 17, "no frames"),
    "negative frame time": (make_bvh(SIMPLE, "Frames: 1\nFrame Time: -0.1\n1 2 3 4 5 6 7 8 9\n"), 18, "frame time"),
    "frame time missing": (make_bvh(SIMPLE, "Frames: 1\n1 2 3 4 5 6 7 8 9\n"), 18, "Frame Time"),
    "too few lines": (make_bvh(SIMPLE, "Frames: 3\nFrame Time: 0.1\n1 2 3 4 5 6 7 8 9\n1 2 3 4 5 6 7 8 9\n"),
                      20, "only 2 complete"),
    "truncated line": (make_bvh(SIMPLE, "Frames: 2\nFrame Time: 0.1\n1 2 3 4 5 6 7 8 9\n1 2 3 4 5\n"), 20, "truncated"),
    "short line inside": (make_bvh(SIMPLE, "Frames: 2\nFrame Time: 0.1\n1 2 3 4\n1 2 3 4 5 6 7 8 9\n"), 19, "4 values"),
    "bad number": (make_bvh(SIMPLE, "Frames: 2\nFrame Time: 0.1\n1 2 3 4 5 6 7 8 9\n1 2 3 4 five 6 7 8 9\n"), 20, "five"),
    "nan value": (make_bvh(SIMPLE, "Frames: 1\nFrame Time: 0.1\n1 2 nan 4 5 6 7 8 9\n"), 19, "nan"),
    "end site without offset": (make_bvh(SIMPLE.replace("      OFFSET 0 1 0\n    }", "    }")), 12, "OFFSET"),
    "joint without offset": (make_bvh(SIMPLE.replace("    OFFSET 0 1 0\n    CHANNELS 3", "    CHANNELS 3")), 13, "OFFSET"),
    # Plain decimals only, as every other number in a file (Python's int() and float() take these too).
    "frames with an underscore": (make_bvh(SIMPLE, "Frames: 1_0\nFrame Time: 0.1\n"), 17, "'1_0' is not a whole"),
    "frames in another script's digits": (make_bvh(SIMPLE, "Frames: \u0661\nFrame Time: 0.1\n"), 17,
                                          "'\u0661' is not a whole"),
    "frame time with an underscore": (make_bvh(SIMPLE, "Frames: 1\nFrame Time: 0.008_333\n1 2 3 4 5 6 7 8 9\n"), 18,
                                      "'0.008_333' is not a number"),
    "a channel count with an underscore": (make_bvh(SIMPLE.replace("CHANNELS 3", "CHANNELS 0_3")), 9,
                                           "'0_3' is not a whole"),
    "a channel count of 5,000 digits": (make_bvh(SIMPLE.replace("CHANNELS 3", "CHANNELS " + "9" * 5000)), 9,
                                        "not between 0 and 6"),
    "an offset in another script's digits": (make_bvh(SIMPLE.replace("OFFSET 0 1 0\n    CHANNELS",
                                                                     "OFFSET 0 \u0661 0\n    CHANNELS")), 8, "OFFSET"),
}


def skinned_vertices(glb: bytes, frame: int, result, meters: float):
    """Linear blend skinning of the GLB's own mesh, weights and bind matrices with the run's
    world transforms at ``frame`` (in metres)."""
    gltf = pygltflib.GLTF2.load_from_bytes(glb)
    blob = gltf.binary_blob()

    def read(index, dtype, width):
        accessor = gltf.accessors[index]
        view = gltf.bufferViews[accessor.bufferView]
        data = np.frombuffer(blob, dtype=dtype, count=accessor.count * width, offset=view.byteOffset)
        return data.reshape(accessor.count, width)

    primitive = gltf.meshes[0].primitives[0]
    positions = read(primitive.attributes.POSITION, np.float32, 3).astype(np.float64)
    small = gltf.accessors[primitive.attributes.JOINTS_0].componentType == pygltflib.UNSIGNED_BYTE
    joints = read(primitive.attributes.JOINTS_0, np.uint8 if small else np.uint16, 4).astype(np.int64)
    weights = read(primitive.attributes.WEIGHTS_0, np.float32, 4).astype(np.float64)
    ibm = read(gltf.skins[0].inverseBindMatrices, np.float32, 16).reshape(-1, 4, 4).transpose(0, 2, 1)
    # Bind matrices are pure translations: v' = sum_j w_j (s_j R_j (v + t_j) + p_j), with s_j the
    # joint's world scale where the GLB keeps a stretched link's volume (output_thickness).
    from mocap_exaggerate.jobs.outputs import output_thickness

    local = positions[:, None, :] + ibm[joints, :3, 3]
    turned = quat_rotate(result.world_rotations[frame][joints], local)
    thickness = output_thickness(result) if any(c.target.path == "scale" for c in gltf.animations[0].channels) else None
    if thickness is not None:
        turned = turned * thickness[frame][joints][..., None]
    moved = turned + result.world_positions[frame][joints] * meters
    return np.sum(weights[..., None] * moved, axis=1), weights


def glb_joint_positions(glb: bytes, frame: int) -> dict[str, np.ndarray]:
    """Every joint node's world position at ``frame`` in the GLB's own frame (Y up, metres),
    by walking its nodes' rest transforms and animation keys: what any glTF viewer computes."""
    from mocap_exaggerate.core.rotations import quat_mul

    gltf = pygltflib.GLTF2.load_from_bytes(glb)
    blob = gltf.binary_blob()

    def read(index):
        accessor = gltf.accessors[index]
        view = gltf.bufferViews[accessor.bufferView]
        width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}[accessor.type]
        return np.frombuffer(blob, np.float32, accessor.count * width, view.byteOffset).reshape(accessor.count, width)

    nodes = gltf.nodes
    trs = {k: [np.array(n.translation or [0, 0, 0], float), np.array(n.rotation or [0, 0, 0, 1], float),
               np.array(n.scale or [1, 1, 1], float)] for k, n in enumerate(nodes)}
    for channel in gltf.animations[0].channels:
        values = read(gltf.animations[0].samplers[channel.sampler].output)[frame].astype(float)
        slot = {"translation": 0, "rotation": 1, "scale": 2}[channel.target.path]
        trs[channel.target.node][slot] = values
    parent = {child: k for k, n in enumerate(nodes) for child in (n.children or [])}
    world: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    def place(k):
        if k not in world:
            t, r, s = trs[k]
            if k in parent:
                pt, pr, ps = place(parent[k])
                world[k] = (pt + quat_rotate(pr, ps * t), quat_mul(pr, r), ps * s)
            else:
                world[k] = (t, r, s)
        return world[k]

    joints = gltf.skins[0].joints
    return {nodes[k].name: place(k)[0] for k in joints}


def mesh_pieces(skin) -> np.ndarray:
    """(V,) the connected piece of the mesh each vertex of ``skin`` is on (numbered from 0)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    edges = np.concatenate([skin.faces[:, [0, 1]], skin.faces[:, [1, 2]], skin.faces[:, [2, 0]]])
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(skin.num_vertices,) * 2)
    return connected_components(graph, directed=False)[1]


def no_glb(preset: str):
    """A shipped preset's config with the GLB switched off (``[glb] enabled = false``): the BVH alone."""
    from mocap_exaggerate.config import resolve_config

    return resolve_config(preset, overrides={"glb": {"enabled": False}})


def chromium() -> str | None:
    """The Chromium the browser tests drive (``MOCAP_CHROMIUM``, else one on PATH), None without one."""
    import os
    import shutil

    for path in (os.environ.get("MOCAP_CHROMIUM"), shutil.which("chromium"), shutil.which("chromium-browser"),
                 shutil.which("google-chrome")):
        if path and Path(path).exists():
            return path
    return None


def ended(pid: int, timeout: float = 10.0) -> bool:
    """Whether process ``pid`` ends (or is a zombie) within ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            if Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z":
                return True
        except OSError:
            return True
        time.sleep(0.05)
    return False


def numpy_sine_is_libm() -> bool:
    """Whether NumPy's float64 sine and cosine are the C library's on this machine (its own vector loops,
    where a build has them for a CPU, may differ in the last bit; the compiled kernels call the C library)."""
    import math

    x = np.linspace(-40.0, 40.0, 20001)
    return (np.array_equal(np.sin(x), [math.sin(v) for v in x])
            and np.array_equal(np.cos(x), [math.cos(v) for v in x]))


def assert_same_bits_or_ulps(fast: np.ndarray, slow: np.ndarray) -> None:
    """The compiled result against NumPy's: the same bits where NumPy's sine is the C library's (as where
    CI runs), else within a few units in the last place."""
    if numpy_sine_is_libm():
        assert np.array_equal(fast, slow)
    else:  # pragma: no cover - a NumPy build with its own sine for this CPU
        np.testing.assert_allclose(fast, slow, rtol=1e-13, atol=1e-13)
