"""Optional compiled kernels (Cython) of the detector's hot loops, and the choice of backend.

Every algorithm of :mod:`labauto.vision` is written in plain numpy/OpenCV in its own module;
that is the reference and what runs when no kernel is built. A compiled kernel is an
accelerator for one measured hot loop: it gives the same results as the plain path (the tests
run on both) and is kept only where ``benchmarks/bench_kernels.py`` shows it saves a real share
of a user-visible time. Installing without a C compiler gives the plain path (see setup.py).

Backend
    ``"compiled"`` uses every kernel that is built; ``"plain"`` none. The default is
    ``"compiled"`` when the kernels are built, else ``"plain"``; ``LABAUTO_KERNELS=off`` (read
    once, when a kernel is first asked for) chooses ``"plain"``, ``LABAUTO_KERNELS=on``
    requires the kernels (an ImportError names what is missing). The compiled modules (and
    with them OpenMP) are loaded then too, not on import, so that a program can set
    ``OMP_WAIT_POLICY`` and the like first. :func:`use` switches at run time; :func:`backend`
    says which runs. A vision module asks :func:`compiled` for its kernel at each call and runs
    its plain code when it gets None.
Threads
    The kernels' parallel loops use :func:`threads` OpenMP threads, 1 unless the caller chose
    more with :func:`set_threads` (the ``labauto`` command line uses one per CPU). Nothing here
    touches the process: no environment variable is set and no fork hook is installed. A
    program that forks after running kernels on several threads must call ``set_threads(1)``
    in the child (OpenMP's thread pool does not survive ``fork``); on one thread no pool
    exists.
"""

from __future__ import annotations

import contextlib
import functools
import importlib
import importlib.util
import os
from collections.abc import Iterator
from types import ModuleType

#: The kernels this version of labauto has, by module name (``labauto.vision.kernels.<name>``).
KERNELS = ("edges", "ellipse_fit", "gradient", "shape")

BACKENDS = ("compiled", "plain")


@functools.cache
def level() -> str:
    """The build of the kernels this CPU runs: ``"v3"`` (x86-64-v3, AVX2) or ``"generic"``."""
    try:
        from labauto.vision.kernels import _cpu
    except ImportError:
        return "generic"
    return (
        "v3"
        if _cpu.x86_64_v3() and importlib.util.find_spec(f"{__name__}.v3.gradient")
        else ("generic")
    )


@functools.cache
def _load() -> dict[str, ModuleType]:
    """The built kernels, by name (an empty dict when none is built); loaded once, from the
    build for this CPU's vector level (:func:`level`)."""
    package = f"{__name__}.v3" if level() == "v3" else __name__
    found = {}
    for name in KERNELS:
        try:
            found[name] = importlib.import_module(f"{package}.{name}")
        except ImportError:
            continue
    return found


def built() -> tuple[str, ...]:
    """Names of the kernels that are built and importable."""
    return tuple(_load())


def _initial_backend(setting: str) -> str:
    setting = setting.strip().lower()
    found = _load()
    if setting in ("off", "plain", "0", "no"):
        return "plain"
    if setting in ("on", "compiled", "1", "yes"):
        missing = [name for name in KERNELS if name not in found]
        if missing:
            raise ImportError(
                f"LABAUTO_KERNELS={setting} but these kernels are not built: "
                f"{', '.join(missing)} (reinstall labauto with a C compiler, or unset it)"
            )
        return "compiled"
    if setting not in ("", "auto"):
        raise ImportError(f"LABAUTO_KERNELS must be on, off or auto, got {setting!r}")
    return "compiled" if found else "plain"


_backend: str | None = None  # chosen when first asked for
_threads = 1


def backend() -> str:
    """The backend that runs: ``"compiled"`` or ``"plain"``."""
    global _backend
    if _backend is None:
        _backend = _initial_backend(os.environ.get("LABAUTO_KERNELS", ""))
    return _backend


def describe() -> str:
    """One line saying which backend runs, e.g. for ``labauto --version``."""
    if backend() == "plain":
        reason = "LABAUTO_KERNELS=off" if _load() else "no compiled kernels installed"
        return f"vision backend: plain numpy/OpenCV ({reason})"
    extra = " -march=x86-64-v3" if level() == "v3" else ""
    return (
        f"vision backend: compiled kernels ({', '.join(built())}; "
        f"built with {' '.join(build_flags())}{extra})"
    )


def build_flags() -> tuple[str, ...]:
    """The compiler flags the kernels were built with (setup.py records them), or ()."""
    try:
        from labauto.vision.kernels import _build
    except ImportError:  # kernels compiled by hand (cythonize), not by setup.py
        return ()
    return tuple(_build.COMPILE_ARGS)


def use(name: str) -> None:
    """Switch the backend to ``name`` (``"compiled"`` or ``"plain"``) from now on.

    Raises
    ------
    ValueError
        An unknown name, or ``"compiled"`` when no kernel is built.
    """
    global _backend
    if name not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {name!r}")
    if name == "compiled" and not _load():
        raise ValueError("no compiled kernels are installed: only the plain backend runs")
    _backend = name


@contextlib.contextmanager
def using(name: str) -> Iterator[None]:
    """Run the ``with`` block on the backend ``name``, then switch back (see :func:`use`)."""
    before = backend()
    use(name)
    try:
        yield
    finally:
        use(before)


def compiled(name: str) -> ModuleType | None:
    """The compiled kernel ``name`` if it is built and the compiled backend runs, else None."""
    if backend() != "compiled":
        return None
    return _load().get(name)


def threads() -> int:
    """Number of threads the kernels use for their parallel loops (1 unless set)."""
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
