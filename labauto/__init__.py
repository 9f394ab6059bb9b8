"""labauto: an open workcell controller for automated colony picking.

The detector implements Teutsch et al., "Real-time detection of elliptic shapes for automated
object recognition and object tracking": contours, the shape angle D_alpha, shape descriptors,
a harmonic analysis and geometric ellipse fitting.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("labauto")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0"

from labauto.api import analyze_plate, detect, detect_markers
from labauto.calibration.camera import calibrate_camera

__all__ = ["__version__", "analyze_plate", "calibrate_camera", "detect", "detect_markers"]

from labauto.vision.tracking import MarkerTracker

__all__ += ["MarkerTracker"]
