"""Fixtures shared by every test folder."""

from __future__ import annotations

import pytest

from labauto.vision import kernels


@pytest.fixture(params=kernels.BACKENDS)
def backend(request: pytest.FixtureRequest) -> str:
    """Run the test once on each vision backend: the compiled kernels and the plain path.

    Folders whose tests exercise vision code make it autouse (``tests/vision``,
    ``tests/plate``). Where no kernel is built (an install without a C compiler) the compiled
    run is skipped, saying so.
    """
    if request.param == "compiled" and not kernels.built():
        pytest.skip("no compiled kernels are built in this install")
    with kernels.using(request.param):
        yield request.param
