"""Compiled kernels (Cython) of the detector's per-pixel and per-point loops.

Each module here is the inner loop of one step of the paper, called from the pure-Python module
of the same name in :mod:`labauto.vision`, which holds the documentation and input checks. They
are built when the package is installed (``pip install .`` needs a C compiler); see setup.py.
"""
