"""The compiled loops, where setup.py built them.

``kernels`` is ``core/_kernels.c`` (`io/bvh.py` takes ``io/_formatting.c`` itself, by `compiled`),
None where it was not built or where ``MOCAP_EXAGGERATE_NUMPY_ONLY`` is set in the environment (to
anything but 0 or nothing). Every module with a compiled loop runs its NumPy code where the loop is
None: the same bits, which the tests check loop by loop and, for whole jobs, by running the command
with the variable set (`tests/test_native.py`). The variable runs the NumPy code as an install
without a C compiler does: to check it, or to tell whether a fault is in the compiled code.
"""

from __future__ import annotations

import os

__all__ = ["ENABLED", "NUMPY_ONLY", "kernels"]

#: The environment variable that turns the compiled loops off for a process (read at import).
NUMPY_ONLY = "MOCAP_EXAGGERATE_NUMPY_ONLY"
#: Whether the compiled loops may be used (the variable is not set).
ENABLED = os.environ.get(NUMPY_ONLY, "") in ("", "0")

kernels = None
if ENABLED:
    try:
        from . import _kernels as kernels
    except ImportError:  # pragma: no cover - an install without a C compiler
        kernels = None
