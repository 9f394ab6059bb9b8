"""Build the compiled kernels of :mod:`labauto.vision.kernels` (everything else is pyproject.toml).

Every ``labauto/vision/kernels/*.pyx`` becomes one C extension. On Linux the kernels are built
with OpenMP so their ``prange`` loops use all cores; elsewhere they run on one core, same result.

CPU target (x86-64): the kernels are compiled for the CPU of the machine that builds them
(``-march=native``), because labauto is installed from source on the machine that runs it and the
per-pixel loops run about 2x faster with that CPU's widest vectors (AVX2 / AVX-512) than with the
SSE4.2 every x86-64 CPU since about 2009 has. ``LABAUTO_MARCH`` sets another target, e.g.
``LABAUTO_MARCH=x86-64-v2 pip wheel .`` for a wheel meant for other machines. The vector
extensions the target uses are written to ``kernels/_build.py``; on import, labauto checks that the
CPU has them and otherwise stops with an error that names them (instead of crashing on an illegal
instruction), see :func:`labauto.vision.kernels.check_cpu`.

Floating point: ``-ffp-contract=off`` keeps the compiler from fusing a multiply and an add into
one FMA instruction where the target has it. Fused and unfused results differ in the last bit, and
the compiler fuses differently where the same code is inlined in two places, so without it the same
ellipse fit could come out 1 ulp apart by path or by target; with it, every target gives the same
numbers and the kernels match their plain-numpy references exactly where the tests say so.
"""

import os
import platform
import shlex
import subprocess
import sys
import sysconfig
from pathlib import Path

from Cython.Build import cythonize
from setuptools import Extension, setup

KERNELS = Path("labauto/vision/kernels")
OPENMP = ["-fopenmp"] if sys.platform.startswith("linux") else []
X86_64 = platform.machine().lower() in ("x86_64", "amd64")
MARCH = os.environ.get("LABAUTO_MARCH", "native").strip() if X86_64 else ""

# compiler macro of each vector extension -> its name in /proc/cpuinfo's flags
VECTOR_EXTENSIONS = {
    "__SSE4_2__": "sse4_2",
    "__AVX__": "avx",
    "__AVX2__": "avx2",
    "__FMA__": "fma",
    "__BMI2__": "bmi2",
    "__AVX512F__": "avx512f",
    "__AVX512BW__": "avx512bw",
    "__AVX512DQ__": "avx512dq",
    "__AVX512VL__": "avx512vl",
    "__AVX512CD__": "avx512cd",
}


def target_features(march: str) -> list[str]:
    """The vector extensions ``-march=march`` lets the compiler use (empty if it cannot say)."""
    if not march:
        return []
    compiler = shlex.split(sysconfig.get_config_var("CC") or "cc")
    try:
        macros = subprocess.run(
            [*compiler, f"-march={march}", "-dM", "-E", "-x", "c", os.devnull],
            capture_output=True,
            text=True,
            check=True,
        ).stdout
    except (OSError, subprocess.CalledProcessError) as exc:
        raise SystemExit(f"the C compiler {compiler[0]!r} rejects -march={march}: {exc}") from None
    defined = {line.split()[1] for line in macros.splitlines() if line.startswith("#define ")}
    return [flag for macro, flag in VECTOR_EXTENSIONS.items() if macro in defined]


features = target_features(MARCH)
(KERNELS / "_build.py").write_text(
    '"""Written by setup.py: the CPU target the kernels were compiled for."""\n\n'
    f"MARCH = {MARCH!r}\n"
    f"CPU_FEATURES = {tuple(features)!r}\n"
)

extensions = [
    Extension(
        f"labauto.vision.kernels.{pyx.stem}",
        [str(pyx)],
        extra_compile_args=[
            "-O3",
            "-ffp-contract=off",
            *([f"-march={MARCH}"] if MARCH else []),
            *OPENMP,
        ],
        extra_link_args=OPENMP,
    )
    for pyx in sorted(KERNELS.glob("*.pyx"))
]

setup(ext_modules=cythonize(extensions, language_level=3, quiet=True))
