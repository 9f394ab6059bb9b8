"""The kernels built a second time for x86-64-v3 CPUs (AVX2; setup.py), loaded where they run.

The same sources as :mod:`labauto.vision.kernels`, compiled with ``-march=x86-64-v3`` so that
the compiler's vectorised loops use 256-bit vectors; the same results (``-ffp-contract=off``).
"""
