"""mocap_exaggerate: turn realistic motion capture into cartoon-style motion.

Example::

    from mocap_exaggerate import convert, load_bvh, exaggerate, save_bvh
    convert("walk.bvh", "out/")                       # the whole job: BVH, GLB, weights, manifest
    save_bvh(exaggerate(load_bvh("walk.bvh"), preset="looney"), "walk_looney.bvh")

Names are imported on first use, so ``import mocap_exaggerate`` (and the
command line's ``--help``) stays quick.
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

#: Public name -> module that defines it.
_EXPORTS = {
    "ConfigError": "core.errors",
    "InputError": "core.errors",
    "MocapError": "core.errors",
    "Motion": "core.motion",
    "Skeleton": "core.skeleton",
    "PipelineConfig": "config",
    "load_preset": "config",
    "resolve_config": "config",
    "load_bvh": "io.bvh",
    "read_bvh": "io.bvh",
    "save_bvh": "io.bvh",
    "run": "pipeline",
    "exaggerate": "pipeline",
    "convert": "jobs.job",
    "JobRecord": "jobs.job",
    "describe": "jobs.job",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        value = getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(list(globals()) + __all__)
