"""Build the optional compiled kernels of :mod:`labauto.vision.kernels` (the rest: pyproject.toml).

Every ``labauto/vision/kernels/*.pyx`` becomes one C extension. They are accelerators only:
every algorithm also runs in plain numpy/OpenCV, so when a kernel cannot be compiled (no C
compiler, no Python headers) the build says so and goes on without it, and labauto runs on the
plain path (``labauto --version`` says which). ``LABAUTO_BUILD_KERNELS=0`` skips them on
purpose.

Portable by default: no ``-march``; the compiler's generic target for the platform (x86-64:
SSE2; aarch64: NEON), so a wheel runs on any CPU of its architecture. On x86-64 the kernels are
built a second time for ``x86-64-v3`` (AVX2: 256-bit vectors, which the per-pixel loops use
for up to 3x their speed) into ``labauto.vision.kernels.v3``; labauto loads those where the CPU
runs them (``kernels/_cpu.pyx``) and the generic ones elsewhere. ``LABAUTO_MARCH`` instead
builds one CPU-specific set (e.g. ``LABAUTO_MARCH=native`` on the machine that runs it). The
flags used are written to ``kernels/_build.py`` and shown by ``labauto --version``.

On Linux the kernels are built with OpenMP so their ``prange`` loops can use several threads
(the caller chooses how many: :func:`labauto.vision.kernels.set_threads`).

Floating point: ``-ffp-contract=off`` keeps the compiler from fusing a multiply and an add into
one FMA instruction where the target has it, so every target gives the same numbers and the
kernels match the plain path exactly where the tests say so.
"""

import os
import platform
import sys
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

KERNELS = Path("labauto/vision/kernels")
OPENMP = ["-fopenmp"] if sys.platform.startswith("linux") else []
MARCH = os.environ.get("LABAUTO_MARCH", "").strip()
COMPILE_ARGS = [
    "-O3",
    "-ffp-contract=off",
    "-frecord-gcc-switches",  # the command line in the binary, for the tests to read
    *([f"-march={MARCH}"] if MARCH else []),
    *OPENMP,
]
WANTED = os.environ.get("LABAUTO_BUILD_KERNELS", "1").strip() not in ("0", "no", "off")
X86_64 = platform.machine().lower() in ("x86_64", "amd64")
#: extra builds for wider vectors, picked at run time: (subpackage, -march)
LEVELS = [("v3", "x86-64-v3")] if X86_64 and not MARCH else []


def record(built: list[str]) -> None:
    """Write ``kernels/_build.py``: the flags and the kernels this build compiled."""
    (KERNELS / "_build.py").write_text(
        '"""Written by setup.py: how the compiled kernels were built."""\n\n'
        f"COMPILE_ARGS = {tuple(COMPILE_ARGS)!r}\n"
        f"LINK_ARGS = {tuple(OPENMP)!r}\n"
        f"LEVELS = {tuple(LEVELS)!r}\n"
        f"BUILT = {tuple(sorted(built))!r}\n"
    )


class OptionalKernels(build_ext):
    """build_ext that skips a kernel it cannot compile instead of failing the install."""

    def run(self) -> None:
        self.compiled: list[str] = []
        try:
            super().run()
        except Exception as exc:  # no compiler at all (e.g. DistutilsPlatformError)
            self.warn(f"labauto: compiled kernels skipped ({exc}); the plain path will run")
        record(self.compiled)
        if self.inplace:
            return
        # a regular (wheel) build: the _build.py next to the built modules
        target = Path(self.build_lib) / KERNELS / "_build.py"
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text((KERNELS / "_build.py").read_text())

    def build_extension(self, ext: Extension) -> None:
        try:
            super().build_extension(ext)
        except Exception as exc:  # CompileError, LinkError, a missing header
            self.warn(f"labauto: kernel {ext.name} skipped ({exc}); the plain path will run")
        else:
            self.compiled.append(ext.name.removeprefix("labauto.vision.kernels."))


def extensions() -> list[Extension]:
    if not WANTED:
        return []
    try:
        from Cython.Build import cythonize
    except ImportError:
        print("labauto: Cython is missing: compiled kernels skipped", file=sys.stderr)
        return []
    modules = [
        Extension(
            f"labauto.vision.kernels.{pyx.stem}",
            [str(pyx)],
            extra_compile_args=COMPILE_ARGS,
            extra_link_args=OPENMP,
        )
        for pyx in sorted(KERNELS.glob("*.pyx"))
    ]
    modules = cythonize(modules, language_level=3, quiet=True)
    for level, march in LEVELS:  # the same sources again, as modules of their own name
        again = [
            Extension(
                f"labauto.vision.kernels.{level}.{pyx.stem}",
                [str(pyx)],
                extra_compile_args=[*COMPILE_ARGS, f"-march={march}"],
                extra_link_args=OPENMP,
            )
            for pyx in sorted(KERNELS.glob("*.pyx"))
            if not pyx.stem.startswith("_")
        ]
        build_dir = str(Path("build") / "levels" / level)
        modules += cythonize(again, language_level=3, quiet=True, build_dir=build_dir)
    return modules


record([])  # until build_ext says otherwise (a source tree, a build without kernels)
setup(ext_modules=extensions(), cmdclass={"build_ext": OptionalKernels})
