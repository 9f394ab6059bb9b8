"""What the ``labauto`` command sets up for its whole process (the library sets nothing).

Before any kernel runs: OpenMP's idle threads sleep between parallel loops instead of spinning
for milliseconds (``OMP_WAIT_POLICY=PASSIVE`` unless already set; a spinning thread takes a
core from OpenCV's own threads: Canny ran 1.7x slower right after the gradient kernel), and the
kernels use one thread per CPU this process may run on, or ``LABAUTO_THREADS``.
"""

from __future__ import annotations

import os
from collections.abc import MutableMapping

from labauto.vision import kernels


def configure(environ: MutableMapping[str, str] = os.environ) -> None:
    """Set the process-wide options of the module docstring.

    Raises
    ------
    ValueError
        ``LABAUTO_THREADS`` is not a whole number >= 1.
    """
    environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # read once, when OpenMP is loaded
    kernels.set_threads(default_threads(environ))


def default_threads(environ: MutableMapping[str, str] = os.environ) -> int:
    """``LABAUTO_THREADS`` if set, else the number of CPUs this process may run on."""
    configured = environ.get("LABAUTO_THREADS", "").strip()
    if configured:
        try:
            value = int(configured)
        except ValueError:
            value = 0
        if value < 1:
            raise ValueError(f"LABAUTO_THREADS must be a whole number >= 1, got {configured!r}")
        return value
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1
