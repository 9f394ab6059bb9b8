"""The median of a large 1-D array, as ``np.median`` gives it, in a tenth of the time.

``np.median`` partitions a floating-point array at three places (the two middle elements and the
last one, to find NaNs), and numpy's partition at several places is several times slower than at
one: on 100 000 float32 values 0.7 ms against 0.08 ms. Plate analysis takes the median of the
agar's noise over hundreds of thousands of pixels several times per plate, so this module
partitions once, at the upper middle element; for an even count the lower middle element is the
largest of the lower half. The value is ``np.median``'s to the bit: the mean of the two middle
elements in the array's own type, as ``np.mean`` takes it. Inputs must be finite (image data):
NaNs are not looked for.
"""

from __future__ import annotations

import numpy as np

__all__ = ["median"]


def median(values: np.ndarray) -> float:
    """The median of a non-empty 1-D array of finite values (``np.median``'s value).

    Parameters
    ----------
    values : ndarray
        1-D array of finite numbers; not changed.

    Returns
    -------
    float
        The middle element, or the mean of the two middle elements for an even count.

    Raises
    ------
    ValueError
        If ``values`` is empty or not 1-D.
    """
    values = np.asarray(values)
    if values.ndim != 1 or values.size == 0:
        raise ValueError(f"median needs a non-empty 1-D array, got shape {values.shape}")
    n = values.size
    mid = n // 2
    part = np.partition(values, mid)
    if n % 2:
        return float(part[mid])
    middle = np.array([part[:mid].max(), part[mid]], dtype=values.dtype)
    return float(np.mean(middle))
