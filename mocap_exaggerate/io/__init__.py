"""File formats: one module per format, no algorithms."""

from .bvh import BVHReport, format_bvh, load_bvh, read_bvh, save_bvh
from .files import OutputExistsError, atomic_write

__all__ = ["BVHReport", "format_bvh", "load_bvh", "read_bvh", "save_bvh", "OutputExistsError", "atomic_write"]
