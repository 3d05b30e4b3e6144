"""The compiled pieces: the BVH motion lines read and written (``mocap_exaggerate/io/_formatting.c``)
and the quaternion, Euler and spring loops (``mocap_exaggerate/core/_kernels.c``: forward kinematics,
world to local, frames and twists along rubber links, Euler angles to quaternions and their
continuity back, the springs' time loop).

Optional: where no C compiler is found the install goes on, and the library uses its NumPy
code, which gives the same bytes (tests/test_bvh.py, test_rotations.py, test_rubber_frames.py and
test_springs.py check both; `python bench/golden.py` with the built modules moved away, all 720 files).
Everything else is declared in pyproject.toml.
"""

import sys

from setuptools import Extension, setup

#: No fused multiply-add: ``-ffp-contract=off`` alone is not enough where CFLAGS carry ``-march=native``
#: (or haswell): GCC's straight-line vectoriser then fused quat_mul's products and sums into
#: ``vfmsubadd`` instructions, and forward kinematics differed from NumPy's in the last bit. Without it
#: the loops are scalar, each operation rounded once, as NumPy's are.
NO_FUSING = ["-O2", "-ffp-contract=off", "-fno-tree-slp-vectorize", "-fno-tree-vectorize"]

setup(
    ext_modules=[
        Extension(
            "mocap_exaggerate.io._formatting",
            ["mocap_exaggerate/io/_formatting.c"],
            # No fused multiply-add or fast-math: the rounding is NumPy's, bit for bit (NO_FUSING).
            extra_compile_args=NO_FUSING,
            optional=True,
        ),
        Extension(
            "mocap_exaggerate.core._kernels",
            ["mocap_exaggerate/core/_kernels.c"],
            extra_compile_args=NO_FUSING,  # NumPy's rounding, bit for bit
            libraries=[] if sys.platform == "win32" else ["m"],  # sin, cos: the C library's, as NumPy's
            optional=True,
        ),
    ]
)
