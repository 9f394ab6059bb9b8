"""The ellipse value shared by fitting, detection and the JSON output.

Conventions (DESIGN.md): pixel coordinates with the origin at the centre of the top-left pixel,
x to the right, y down. Semi-axes ``a >= b``; the major axis is turned ``angle`` degrees from +x
toward +y (the sense of ``cv2.ellipse``), normalised to [0, 180).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Ellipse:
    """A geometric ellipse.

    Parameters
    ----------
    center : tuple of float
        Centre ``(x, y)`` in pixels.
    axes : tuple of float
        Semi-axes ``(a, b)`` in pixels with ``a >= b``.
    angle : float
        Direction of the major axis in degrees from +x toward +y, in [0, 180).
    """

    center: tuple[float, float]
    axes: tuple[float, float]
    angle: float

    @classmethod
    def normalised(cls, cx: float, cy: float, a: float, b: float, angle_deg: float) -> Ellipse:
        """Build an ellipse from any axis order and angle, enforcing ``a >= b`` and [0, 180)."""
        a, b = abs(float(a)), abs(float(b))
        if b > a:
            a, b = b, a
            angle_deg += 90.0
        return cls((float(cx), float(cy)), (a, b), float(angle_deg) % 180.0)

    def sample(self, n: int, t0: float = 0.0, t1: float = 2.0 * np.pi) -> np.ndarray:
        """Return ``n`` points ``(x, y)`` on the ellipse for parameters t in ``[t0, t1)``."""
        t = np.linspace(t0, t1, n, endpoint=False)
        theta = np.deg2rad(self.angle)
        c, s = np.cos(theta), np.sin(theta)
        a, b = self.axes
        x = a * np.cos(t)
        y = b * np.sin(t)
        return np.column_stack((self.center[0] + c * x - s * y, self.center[1] + s * x + c * y))

    def to_dict(self) -> dict:
        """Return the JSON form ``{"center": [x, y], "axes": [a, b], "angle": deg}``."""
        return {
            "center": [float(self.center[0]), float(self.center[1])],
            "axes": [float(self.axes[0]), float(self.axes[1])],
            "angle": float(self.angle),
        }
