"""Hashes of every output file of every clip and preset: a refactor that changes a byte shows here.

    python bench/golden.py --write before.json          # on the old tree
    python bench/golden.py --check before.json          # on the new one: lists every file that differs

    python bench/golden.py --write before.json --keep old/   # each run's files kept, then
    python bench/golden.py --check before.json --keep new/
    python bench/golden.py --compare old/ new/               # how far each BVH's and GLB's numbers moved

Runs `mocap_exaggerate.convert` (BVH, GLB, weights, manifest) on the shipped samples and, where
present, the shared clips beside the checkout, at each preset, and records each file's SHA-256
(the manifest without its timing and version fields). The tests' golden arrays
(`tests/golden/`) hold the same check with a tolerance on three clips; this one is exact, for a
move that must not change a number.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from common import ROOT, SHARED  # same folder: run as python bench/golden.py

PRESETS = ("default", "subtle", "cartoon", "looney")
#: What a manifest may change between identical runs (jobs/outputs.py: the timings; the version across releases).
VOLATILE = {"timings", "version"}


def clips(data: Path) -> list[Path]:
    found = sorted((ROOT / "sample_data").glob("*.bvh"))
    for folder in (data, data / "wide"):
        found += sorted(folder.glob("*.bvh")) if folder.is_dir() else []
    return found


def _scrub(value):
    if isinstance(value, dict):
        return {k: _scrub(v) for k, v in value.items() if k not in VOLATILE}
    if isinstance(value, list):
        return [_scrub(v) for v in value]
    return value


def hashes(job: tuple[str, str, str | None]) -> dict[str, str]:
    from mocap_exaggerate import convert

    clip, preset, keep = job
    with tempfile.TemporaryDirectory() as scratch:
        out = Path(keep) / f"{Path(clip).parent.name}__{Path(clip).stem}__{preset}" if keep else Path(scratch)
        convert(clip, out, preset=None if preset == "default" else preset, overwrite=True)
        result = {}
        for path in sorted(Path(out).iterdir()):
            data = path.read_bytes()
            if path.name.endswith(".json"):
                try:
                    data = json.dumps(_scrub(json.loads(data)), sort_keys=True).encode()
                except ValueError:
                    pass
            key = f"{Path(clip).parent.name}/{Path(clip).name}:{preset}:{path.name.replace(Path(clip).stem, '<clip>')}"
            result[key] = hashlib.sha256(data).hexdigest()
        return result


def _motion_values(path: Path):
    import numpy as np

    text = path.read_bytes()
    body = text[text.index(b"Frame Time:"):].split(b"\n", 1)[1]
    return np.array(body.split(), dtype=np.float64)


def _glb_floats(path: Path):
    """Every float accessor of a GLB, in order, as one float64 array."""
    import numpy as np
    import pygltflib

    glb = pygltflib.GLTF2.load_binary(str(path))
    blob = glb.binary_blob()
    parts = []
    for accessor in glb.accessors:
        if accessor.componentType != pygltflib.FLOAT:
            continue
        view = glb.bufferViews[accessor.bufferView]
        width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}[accessor.type]
        start = (view.byteOffset or 0) + (accessor.byteOffset or 0)
        parts.append(np.frombuffer(blob, np.float32, accessor.count * width, start).astype(np.float64))
    return np.concatenate(parts) if parts else np.zeros(0)


def compare(old: Path, new: Path) -> int:
    """How far the numbers of each BVH and GLB kept by two runs moved: values that differ, the largest move."""
    import numpy as np

    worst = {".bvh": 0.0, ".glb": 0.0}
    counts = {".bvh": [0, 0, 0], ".glb": [0, 0, 0]}  # files that differ, values that differ, values
    kept = {path.relative_to(old) for path in old.rglob("*") if path.suffix in worst}
    made = {path.relative_to(new) for path in new.rglob("*") if path.suffix in worst}
    unlike = sorted(kept ^ made)
    for name in unlike:
        print(f"{name}: only in {old if name in kept else new}")
    for name in sorted(kept & made):
        a, b = old / name, new / name
        if a.read_bytes() == b.read_bytes():
            continue
        x, y = (_motion_values(a), _motion_values(b)) if a.suffix == ".bvh" else (_glb_floats(a), _glb_floats(b))
        if x.shape != y.shape:
            print(f"{name}: a different number of values ({len(x)} -> {len(y)})")
            unlike.append(name)
            continue
        moved = np.abs(x - y)
        counts[a.suffix][0] += 1
        counts[a.suffix][1] += int(np.count_nonzero(moved))
        counts[a.suffix][2] += len(x)
        worst[a.suffix] = max(worst[a.suffix], float(moved.max()))
    for suffix, (files, values, total) in counts.items():
        print(f"{suffix}: {files} files differ; in them {values:,} of {total:,} values, the largest move "
              f"{worst[suffix]:.3g}")
    return 1 if unlike else 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    mode = parser.add_mutually_exclusive_group(required=True)
    mode.add_argument("--write", type=Path)
    mode.add_argument("--check", type=Path)
    mode.add_argument("--compare", type=Path, nargs=2, metavar=("OLD", "NEW"),
                      help="two folders kept by --keep: how far each BVH's and GLB's numbers moved")
    parser.add_argument("--keep", type=Path, help="keep every job's files in this folder")
    parser.add_argument("--data", type=Path, default=SHARED, help="the shared clips (bvh/ beside the checkout)")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--presets", default=",".join(PRESETS))
    args = parser.parse_args()
    if args.compare:
        return compare(*args.compare)
    keep = str(args.keep.resolve()) if args.keep else None
    jobs = [(str(c), p, keep) for c in clips(args.data) for p in args.presets.split(",")]
    start = time.perf_counter()
    found: dict[str, str] = {}
    with ProcessPoolExecutor(args.jobs) as pool:
        for part in pool.map(hashes, jobs):
            found.update(part)
    print(f"{len(found)} files from {len(jobs)} jobs in {time.perf_counter() - start:.0f} s")
    if args.write:
        args.write.write_text(json.dumps(found, indent=1, sort_keys=True) + "\n")
        return 0
    expected = json.loads(args.check.read_text())
    differ = sorted(k for k in expected.keys() & found.keys() if expected[k] != found[k])
    missing, extra = sorted(expected.keys() - found.keys()), sorted(found.keys() - expected.keys())
    for title, keys in (("differ", differ), ("missing", missing), ("new", extra)):
        for key in keys:
            print(f"{title}: {key}")
    print(f"{len(differ)} differ, {len(missing)} missing, {len(extra)} new")
    return 1 if differ or missing else 0


if __name__ == "__main__":
    sys.exit(main())
