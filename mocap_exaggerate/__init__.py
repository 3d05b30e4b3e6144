"""mocap_exaggerate: turn realistic motion capture into cartoon-style motion.

Example::

    from mocap_exaggerate import load_bvh, exaggerate, save_bvh
    save_bvh(exaggerate(load_bvh("walk.bvh"), preset="looney"), "walk_looney.bvh")
"""

__version__ = "0.1.0"

from .errors import ConfigError, InputError, MocapError  # noqa: E402
from .io.bvh import load_bvh, read_bvh, save_bvh  # noqa: E402
from .motion import Motion  # noqa: E402
from .pipeline import PipelineConfig, exaggerate, load_preset, run  # noqa: E402
from .skeleton import Skeleton  # noqa: E402

__all__ = [
    "ConfigError",
    "InputError",
    "MocapError",
    "Motion",
    "PipelineConfig",
    "Skeleton",
    "exaggerate",
    "load_bvh",
    "load_preset",
    "read_bvh",
    "run",
    "save_bvh",
]
