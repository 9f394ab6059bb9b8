"""A simulated camera over the deck that sees the picking head's coded marker.

It renders, at every :meth:`SimulatedHeadCamera.capture`, an image of the deck with the head's
marker where the head *really* is: ``position()`` is normally
:attr:`labauto.drivers.grbl_sim.SimulatedGantry.position`, which a ``lost_steps`` fault makes
differ from what the controller reports. Deck millimetres go to pixels through ``to_image``
(e.g. the inverse of the run's pixel-to-deck homography), so a head that is where it was sent
is seen there to the detector's precision, and one that lost steps is seen where it stopped.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from labauto.synthetic.grey_look import GreyLook
from labauto.synthetic.markers import PlaneToImage, draw_marker, homography_map

__all__ = ["HEAD_CAMERA_LOOK", "SimulatedHeadCamera", "deck_to_image"]

#: The deck, the marker's ink, a slight blur and some sensor noise.
HEAD_CAMERA_LOOK = GreyLook(ground=215.0, ink=25.0, blur_sigma=0.6, noise_sigma=1.0)


def deck_to_image(pixel_to_deck: np.ndarray) -> PlaneToImage:
    """The deck-to-pixel map of a 3x3 pixel-to-deck homography."""
    return homography_map(np.linalg.inv(np.asarray(pixel_to_deck, np.float64)))


class SimulatedHeadCamera:
    """Render the deck with the head's marker at ``position()`` (see the module docstring).

    Parameters
    ----------
    position : callable
        ``position() -> (x, y, ...)``: where the head really is, deck mm.
    to_image : PlaneToImage
        Deck mm to pixels.
    marker_id : int
        The code on the head.
    radius_mm : float
        Radius of the marker's centre circle on the head (the marker is 7.2 radii across).
    size : (width, height)
        Image size, pixels.
    look : GreyLook
        Grey levels of the deck around the marker and of the ink, blur and sensor noise.
    seed : int
        Of the noise.
    """

    def __init__(
        self,
        position: Callable[[], Sequence[float]],
        to_image: PlaneToImage,
        marker_id: int,
        radius_mm: float = 1.0,
        *,
        size: tuple[int, int] = (1280, 1024),
        look: GreyLook = HEAD_CAMERA_LOOK,
        seed: int = 0,
    ) -> None:
        self.position = position
        self.to_image = to_image
        self.marker_id = int(marker_id)
        self.radius_mm = float(radius_mm)
        self.size = size
        self.look = look
        self._rng = np.random.default_rng(seed)
        self.captures = 0

    def capture(self) -> np.ndarray:
        """A grey ``uint8`` image of the deck with the head's marker where the head is."""
        image = self.look.canvas(self.size)
        x, y = (float(v) for v in self.position()[:2])
        ink = self.look.ink
        draw_marker(image, self.marker_id, (x, y), self.radius_mm, to_image=self.to_image, ink=ink)
        self.captures += 1
        return self.look.develop(image, self._rng)
