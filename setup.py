"""The one compiled piece: BVH number formatting (``mocap_exaggerate/io/_formatting.c``).

Optional: where no C compiler is found the install goes on, and the writer uses its NumPy
formatter, which writes the same bytes (tests/test_bvh.py checks both). Everything else is
declared in pyproject.toml.
"""

from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension(
            "mocap_exaggerate.io._formatting",
            ["mocap_exaggerate/io/_formatting.c"],
            # No fused multiply-add or fast-math: the rounding is NumPy's, bit for bit.
            extra_compile_args=["-O2", "-ffp-contract=off"],
            optional=True,
        )
    ]
)
