"""Fixtures shared by the tests."""

from pathlib import Path

import pytest

from .helpers import SAMPLE_DIR


@pytest.fixture
def sample_clip() -> Path:
    """A short real clip shipped in sample_data/ (Daz-friendly CMU run, with a T-pose start)."""
    return SAMPLE_DIR / "cmu_09_01_run_daz.bvh"

# Scripts run by other interpreters (Blender's), not test modules.
collect_ignore = ["blender"]
