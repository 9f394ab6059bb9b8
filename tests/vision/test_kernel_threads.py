"""Threads: chosen by the caller, same results on any number, and no process-wide side effects."""

from __future__ import annotations

import multiprocessing
import os
import subprocess
import sys

import numpy as np
import pytest

from labauto.cli import process
from labauto.synthetic.shapes import make_scene
from labauto.vision import kernels
from labauto.vision.detector import detect


@pytest.fixture(scope="module")
def scene() -> np.ndarray:
    return make_scene(np.random.default_rng(7))[0]


def _summary(image: np.ndarray) -> list[tuple]:
    return [
        (o.n_points, o.centroid, o.d_alpha_median, o.shape, o.ellipse and o.ellipse.to_dict())
        for o in detect(image).objects
    ]


@pytest.fixture
def restore_threads():
    before = kernels.threads()
    yield
    kernels.set_threads(before)


def test_results_do_not_depend_on_the_thread_count(scene, restore_threads) -> None:
    kernels.set_threads(1)
    serial = _summary(scene)
    kernels.set_threads(2)
    assert _summary(scene) == serial
    kernels.set_threads(3)  # more threads than this machine's cores
    assert _summary(scene) == serial


def test_the_library_sets_nothing_for_the_process() -> None:
    """Importing labauto and detecting sets no environment variable and uses one thread."""
    code = (
        "import os, numpy as np, labauto\n"
        "from labauto.vision import kernels\n"
        "labauto.detect(np.zeros((64, 64), np.uint8))\n"
        "print(os.environ.get('OMP_WAIT_POLICY'), kernels.threads())\n"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("OMP_WAIT_POLICY", "LABAUTO_THREADS")}
    done = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60
    )
    assert done.stdout.split() == ["None", "1"], done.stderr


def _detect_in_child(image: np.ndarray) -> list[tuple]:
    return _summary(image)


@pytest.mark.skipif(not hasattr(os, "fork"), reason="fork start method needs os.fork")
def test_forked_children_detect_without_any_fork_hook(scene, restore_threads) -> None:
    kernels.set_threads(1)  # the library's default: no OpenMP thread pool to lose in a fork
    parent = _summary(scene)
    with multiprocessing.get_context("fork").Pool(2) as pool:
        children = pool.map_async(_detect_in_child, [scene, scene]).get(timeout=60)
    assert children == [parent, parent]


@pytest.mark.parametrize("bad", [0, -1, 1.5, True, "2"])
def test_set_threads_names_a_bad_count(bad, restore_threads) -> None:
    with pytest.raises(ValueError, match="thread count"):
        kernels.set_threads(bad)


def test_the_command_line_sets_wait_policy_and_threads(restore_threads) -> None:
    environ: dict[str, str] = {"LABAUTO_THREADS": "3"}
    process.configure(environ)
    assert environ["OMP_WAIT_POLICY"] == "PASSIVE" and kernels.threads() == 3
    environ = {"OMP_WAIT_POLICY": "ACTIVE"}
    process.configure(environ)
    assert environ["OMP_WAIT_POLICY"] == "ACTIVE"
    assert kernels.threads() == len(os.sched_getaffinity(0))


@pytest.mark.parametrize("value", ["zero", "0", "-2"])
def test_a_bad_labauto_threads_is_named(value: str, restore_threads) -> None:
    with pytest.raises(ValueError, match="LABAUTO_THREADS must be a whole number"):
        process.configure({"LABAUTO_THREADS": value})
