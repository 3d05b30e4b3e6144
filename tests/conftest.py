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


# Test kinds, as markers (`pytest -m unit` is the quick loop; CI runs everything):
#   unit      in-process library code on the shipped samples
#   cli       the command line (click's runner or a real process)
#   process   starts other processes (the CLI as users run it, worker pools, Dask)
#   realdata  reads the clips, skins and characters in ../shared/data
#   external  drives a tool outside Python (Blender, the Khronos validator, Chromium)
# A test's kinds are read from its code and the module-level helpers it calls, so a new test is
# marked without anyone remembering to.
_KINDS = {
    "external": ("MOCAP_BPY_PYTHON", "blender", "validator", "validate_glb", "playwright", "chromium"),
    "process": ("subprocess", "sys.executable", "Popen", "ProcessPool", "LocalCluster", "scheduler", "jobs=2",
                "\"-j\"", "'-j'", "run_cli", "signal."),
    "cli": ("CliRunner", "invoke(", "cli.main", "mocap_exaggerate_cli", "run_cli"),
    "realdata": ("shared(", "SHARED", "shared_clip_params", "all_clip_params", "makehuman", "MakeHuman",
                 "data/gltf", "data/skin", "SHARED_BVH / \"wide\"", "\"wide/"),
}


def _source_with_helpers(function, namespace: dict) -> str:
    import inspect
    import re

    try:
        text = inspect.getsource(function)
    except (OSError, TypeError):
        return ""
    seen = {function.__name__}
    for name in re.findall(r"\b(_?[a-z]\w*)\(", text):
        helper = namespace.get(name)
        if name not in seen and inspect.isfunction(helper) and helper.__module__ == function.__module__:
            seen.add(name)
            try:
                text += inspect.getsource(helper)
            except (OSError, TypeError):
                pass
    return text


def pytest_collection_modifyitems(config, items):
    for item in items:
        function = getattr(item, "function", None)
        if function is None:  # a doctest: library code, in process
            item.add_marker(pytest.mark.unit)
            continue
        text = _source_with_helpers(function, vars(item.module))
        params = getattr(getattr(item, "callspec", None), "params", {})
        text += " ".join(str(v) for v in params.values())
        kinds = [kind for kind, signs in _KINDS.items() if any(sign in text for sign in signs)]
        if any("/shared/" in str(v) for v in params.values()):
            kinds.append("realdata")
        for kind in dict.fromkeys(kinds) or ["unit"]:
            item.add_marker(getattr(pytest.mark, kind))
