"""Compiled kernels (Cython) of the detector's per-pixel and per-point loops.

Each module here is the inner loop of one step of the paper, called from the pure-Python module
of the same name in :mod:`labauto.vision`, which holds the documentation and input checks. They
are built when the package is installed (``pip install .`` needs a C compiler); see setup.py.

Threads: the long loops (per pixel, per contour) are shared among :func:`threads` OpenMP threads,
by default one per CPU this process may run on, or ``LABAUTO_THREADS`` when set. OpenMP's thread
pool does not survive ``fork``: a forked child (``multiprocessing`` with the fork start method)
that entered a parallel loop would hang, so a child runs the kernels on one thread.

Between parallel loops OpenMP's idle threads would by default spin for milliseconds, taking a
core from OpenCV's own threads (Canny ran 1.7x slower right after the gradient kernel, and a
plain OpenCV pipeline run after ``detect`` 1.4x slower). So unless ``OMP_WAIT_POLICY`` is set,
labauto sets it to ``PASSIVE`` (idle threads sleep) before the first kernel loads OpenMP.

CPU: on x86-64 the kernels are compiled for the CPU of the machine that built them (setup.py). A
build copied to a CPU without the vector extensions it uses would die on an illegal instruction,
so importing this package first checks them (:func:`check_cpu`) and names what is missing.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # read once, when OpenMP is loaded


def cpu_flags(cpuinfo: str = "/proc/cpuinfo") -> set[str] | None:
    """The CPU's feature flags from ``cpuinfo`` (Linux), or None where it cannot be read."""
    try:
        with open(cpuinfo, encoding="ascii", errors="replace") as lines:
            for line in lines:
                if line.startswith("flags"):
                    return set(line.partition(":")[2].split())
    except OSError:
        pass
    return None


def check_cpu(required: tuple[str, ...], flags: set[str] | None, march: str) -> None:
    """Raise ImportError if the CPU (its ``flags``) lacks a vector extension the kernels use.

    Parameters
    ----------
    required : tuple of str
        Extensions the build target uses, as /proc/cpuinfo names them (``kernels/_build.py``).
    flags : set of str or None
        The CPU's flags (:func:`cpu_flags`); None (unknown) passes.
    march : str
        The build's ``-march`` target, for the message.
    """
    missing = [name for name in required if flags is not None and name not in flags]
    if missing:
        raise ImportError(
            f"labauto's compiled kernels were built for -march={march} and use "
            f"{', '.join(missing)}, which this CPU lacks; reinstall labauto on this machine "
            "(pip install --force-reinstall --no-deps --no-binary labauto ...), or build it "
            "for any x86-64 CPU with LABAUTO_MARCH=x86-64-v2"
        )


try:
    from labauto.vision.kernels._build import CPU_FEATURES, MARCH
except ImportError:  # kernels built by hand (cythonize), not by setup.py
    pass
else:
    check_cpu(CPU_FEATURES, cpu_flags(), MARCH)


def _default_threads() -> int:
    configured = os.environ.get("LABAUTO_THREADS", "").strip()
    if configured:
        try:
            value = int(configured)
        except ValueError:
            raise ValueError(
                f"LABAUTO_THREADS must be a whole number >= 1, got {configured!r}"
            ) from None
        if value < 1:
            raise ValueError(f"LABAUTO_THREADS must be a whole number >= 1, got {configured!r}")
        return value
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


_threads = _default_threads()


def threads() -> int:
    """Number of threads the kernels use for their parallel loops."""
    return _threads


def set_threads(count: int) -> None:
    """Use ``count`` (>= 1) threads in the kernels' parallel loops from now on."""
    global _threads
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise ValueError(f"thread count must be a whole number >= 1, got {count!r}")
    _threads = count


def threads_for(count: int, min_count: int = 16) -> int:
    """Threads for a loop over ``count`` independent items: one for fewer than ``min_count``.

    Waking a second thread costs tens of microseconds; a short loop is faster on one.
    """
    return _threads if count >= min_count else 1


os.register_at_fork(after_in_child=lambda: set_threads(1))
