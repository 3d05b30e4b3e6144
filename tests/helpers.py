"""Where the test clips are: the shipped sample clips and the wider real data beside the checkout."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SAMPLE_DIR = ROOT / "sample_data"
SHARED_BVH = ROOT.parent / "shared" / "data" / "bvh"

SAMPLE_CLIPS = sorted(SAMPLE_DIR.glob("*.bvh"))
SHARED_CLIPS = sorted(SHARED_BVH.glob("*.bvh")) if SHARED_BVH.is_dir() else []
SHARED_REASON = f"real-data clips not found at {SHARED_BVH} (CI has ../shared beside the checkout)"


def shared_clip_params():
    """Parametrize over every shared clip, or one skipped case that says why."""
    if not SHARED_CLIPS:
        return [pytest.param(None, marks=pytest.mark.skip(reason=SHARED_REASON), id="no-shared-data")]
    return [pytest.param(p, id=p.stem) for p in SHARED_CLIPS]


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
