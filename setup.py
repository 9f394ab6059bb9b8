"""Build the compiled kernels of :mod:`labauto.vision.kernels` (everything else is pyproject.toml).

Every ``labauto/vision/kernels/*.pyx`` becomes one C extension. On Linux the kernels are built
with OpenMP so their ``prange`` loops use all cores; elsewhere they run on one core, same result.
"""

import platform
import sys
from pathlib import Path

from Cython.Build import cythonize
from setuptools import Extension, setup

OPENMP = ["-fopenmp"] if sys.platform.startswith("linux") else []
# SSE4.2 (every x86-64 CPU since about 2009) lets the compiler vectorise the per-pixel loops.
SIMD = ["-march=x86-64-v2"] if platform.machine().lower() in ("x86_64", "amd64") else []

extensions = [
    Extension(
        f"labauto.vision.kernels.{pyx.stem}",
        [str(pyx)],
        extra_compile_args=["-O3", *SIMD, *OPENMP],
        extra_link_args=OPENMP,
    )
    for pyx in sorted(Path("labauto/vision/kernels").glob("*.pyx"))
]

setup(ext_modules=cythonize(extensions, language_level=3, quiet=True))
