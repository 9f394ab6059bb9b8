"""The kernels' thread count: same results on any number of threads, and safe across fork."""

from __future__ import annotations

import multiprocessing
import os
import subprocess
import sys

import numpy as np
import pytest

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


def _detect_in_child(image: np.ndarray) -> tuple[int, list[tuple]]:
    return kernels.threads(), _summary(image)


@pytest.mark.skipif(not hasattr(os, "fork"), reason="fork start method needs os.fork")
def test_forked_children_detect_after_the_parent_used_threads(scene) -> None:
    parent = _summary(scene)  # the parent's OpenMP thread pool now exists
    with multiprocessing.get_context("fork").Pool(2) as pool:
        children = pool.map_async(_detect_in_child, [scene, scene]).get(timeout=60)
    for threads, summary in children:
        assert threads == 1
        assert summary == parent


@pytest.mark.parametrize("bad", [0, -1, 1.5, True, "2"])
def test_set_threads_names_a_bad_count(bad, restore_threads) -> None:
    with pytest.raises(ValueError, match="thread count"):
        kernels.set_threads(bad)


@pytest.mark.parametrize(
    ("value", "expected"), [("3", "3"), ("zero", "LABAUTO_THREADS"), ("0", "LABAUTO_THREADS")]
)
def test_labauto_threads_environment_variable(value: str, expected: str) -> None:
    done = subprocess.run(
        [sys.executable, "-c", "from labauto.vision import kernels; print(kernels.threads())"],
        env={**os.environ, "LABAUTO_THREADS": value},
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert expected in (done.stdout + done.stderr)
