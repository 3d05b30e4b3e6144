"""Hashes of every output file of every clip and preset: a refactor that changes a byte shows here.

    python bench/golden.py --write before.json          # on the old tree
    python bench/golden.py --check before.json          # on the new one: lists every file that differs

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


def hashes(job: tuple[str, str]) -> dict[str, str]:
    from mocap_exaggerate import convert

    clip, preset = job
    with tempfile.TemporaryDirectory() as out:
        convert(clip, out, preset=None if preset == "default" else preset)
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


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    mode = parser.add_mutually_exclusive_group(required=True)
    mode.add_argument("--write", type=Path)
    mode.add_argument("--check", type=Path)
    parser.add_argument("--data", type=Path, default=SHARED, help="the shared clips (bvh/ beside the checkout)")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--presets", default=",".join(PRESETS))
    args = parser.parse_args()
    jobs = [(str(c), p) for c in clips(args.data) for p in args.presets.split(",")]
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
