"""The tracker's searches: what a frame, or a set of windows of it, shows.

A search gives *observations* (:class:`Obs`) in frame pixels: coded markers (an ``id``) or,
by default, centre candidates (``id`` None: the DES of a centre circle's size, from contours
and the shape angle only, :func:`labauto.vision.marker_candidates.centre_candidates`). Windows
are packed into one mosaic and searched at once (:mod:`labauto.vision.roi_mosaic`); codes are
read only at given candidates, in small windows
(:func:`labauto.vision.marker_candidates.read_markers_at`). Which observation continues which
track is decided elsewhere (:mod:`labauto.vision.tracking_assoc`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from labauto.vision.marker_candidates import centre_candidates, read_markers_at
from labauto.vision.marker_codes import QUIET_RADIUS
from labauto.vision.markers import MarkerParams
from labauto.vision.roi_mosaic import Rect, build_mosaic, clip_rect, merge_overlapping
from labauto.vision.tracking_types import MarkerLike

__all__ = ["Detect", "MarkerSearch", "Obs", "holds"]

#: A detector: ``detect(image) -> markers`` (see :class:`~labauto.vision.tracking_types.
#: MarkerLike`); it must work on any sub-image.
Detect = Callable[[np.ndarray], Sequence[MarkerLike]]


@dataclass(frozen=True)
class Obs:
    """A detection in frame pixels: a coded marker (``id``) or a centre candidate (``None``).

    Attributes
    ----------
    id : int or None
        The decoded id; None for a centre candidate.
    position : ndarray
        Centre (frame pixels).
    radius : float
        Centre-circle radius (pixels): the fitted major semi-axis of a coded marker, the
        area-equivalent radius of a candidate.
    whole : bool
        For a candidate: centrally symmetric (not cut by an occluder or a border).
    """

    id: int | None
    position: np.ndarray
    radius: float
    whole: bool = True


@dataclass(frozen=True)
class MarkerSearch:
    """How the tracker searches pixels.

    Parameters
    ----------
    detect : Detect
        The whole detector (codes read), run on searched images when ``candidates`` is False
        and where codes must be read.
    params : MarkerParams
        Of the built-in detector (centre candidates and code reads).
    candidates : bool
        Search by centre candidates (DES centroids) instead of running ``detect``.
    fit : bool
        Take a coded marker's fitted, bias-corrected centre instead of its DES centroid.
    """

    detect: Detect
    params: MarkerParams
    candidates: bool
    fit: bool

    def observe(self, image: np.ndarray) -> list[Obs]:
        """Centre candidates (default) or coded markers of ``image`` (its pixels)."""
        if self.candidates:
            found = centre_candidates(image, self.params)
            whole = found.asymmetry <= 0.45 + 0.02 * found.radii
            return [
                Obs(None, found.centroids[i].copy(), float(found.radii[i]), bool(whole[i]))
                for i in range(len(found))
            ]
        return present(self.coded(marker) for marker in self.detect(image))

    def in_windows(
        self, frame: np.ndarray, windows: Iterable[Rect], extent_factor: float
    ) -> tuple[list[Obs], int]:
        """Observations in ``windows`` of ``frame`` (frame pixels) and the mosaic's pixels.

        Overlapping windows are merged, all are packed into one mosaic and searched at once;
        what lies in a tile's padding (a piece of an object cut by its window) is dropped. A
        coded marker whose window does not hold ``extent_factor`` of its centre radii around
        it (it moved further than its window allowed for, so its code ring and quiet zone run
        into the tile's padding and its ring fits are off) is searched again, once, in a
        window of its own (:meth:`around`); there is no such limit at the frame's border, as
        in a full-frame search.
        """
        observed, cut, pixels = self._in_mosaic(frame, list(windows), extent_factor)
        if cut:
            again = [w for w in (self.around(c, extent_factor, frame.shape) for c in cut) if w]
            more, _, extra = self._in_mosaic(frame, again, extent_factor)
            ids = {c.id for c in cut}
            observed += [o for o in more if o.id in ids]
            pixels += extra
        return observed, pixels

    def _in_mosaic(
        self, frame: np.ndarray, windows: list[Rect], extent_factor: float
    ) -> tuple[list[Obs], list[Obs], int]:
        """Observations held by their windows, coded ones cut by them, and the mosaic's pixels."""
        if not windows:
            return [], [], 0
        mosaic = build_mosaic(frame, merge_overlapping(windows))
        inside = self.observe(mosaic.image)
        tiles = mosaic.owners(np.array([o.position for o in inside]).reshape(-1, 2))
        height, width = frame.shape[:2]
        observed: list[Obs] = []
        cut: list[Obs] = []
        for o, t in zip(inside, tiles.tolist(), strict=True):
            if t < 0:
                continue
            obs = Obs(o.id, o.position - mosaic.offsets[t], o.radius, o.whole)
            held = o.id is None or holds(
                mosaic.rects[t], obs.position, extent_factor * obs.radius, width, height
            )
            (observed if held else cut).append(obs)
        return observed, cut, int(mosaic.image.shape[0] * mosaic.image.shape[1])

    @staticmethod
    def around(obs: Obs, extent_factor: float, shape: tuple[int, ...]) -> Rect | None:
        """A window centred on ``obs`` holding its extent with room to spare (clipped)."""
        half = 1.3 * extent_factor * obs.radius + 4.0
        x, y = float(obs.position[0]), float(obs.position[1])
        rect = (math.floor(x - half), math.floor(y - half), math.ceil(x + half) + 1,
                math.ceil(y + half) + 1)  # fmt: skip
        return clip_rect(rect, shape[1], shape[0])

    def read_codes(self, frame: np.ndarray, candidates: list[Obs]) -> list[Obs]:
        """The coded markers at ``candidates`` of ``frame`` (the whole detector, frame pixels)."""
        window_area = sum((2.6 * QUIET_RADIUS * c.radius + 8) ** 2 for c in candidates)
        if window_area > 0.5 * frame.shape[0] * frame.shape[1]:  # e.g. the first frame
            return present(self.coded(m) for m in self.detect(frame))
        markers = read_markers_at(
            frame,
            np.array([c.position for c in candidates]),
            np.array([c.radius for c in candidates]),
            self.params,
        )
        return present(self.coded(m) for m in markers)

    def coded(self, marker: MarkerLike) -> Obs | None:
        """The observation of a coded marker; ``None`` for a centre circle cut off in part.

        The centroid of a whole (projected) circle's contour is the centre of its ellipse; an
        occluder or the frame edge cutting the circle moves the two apart. With ``fit``, a
        bias-corrected centre further from the ellipse's centre than 0.25 px + 0.02 radii (more
        than perspective can move it at these sizes) is not trusted: the ellipse's centre is
        taken instead.
        """
        point = marker.center if self.fit else marker.centroid
        ellipse = marker.ellipse
        axes = getattr(ellipse, "axes", None)
        if axes is None and isinstance(ellipse, dict):
            axes = ellipse.get("axes")
        radius = float(axes[0]) if axes is not None else 5.0
        centre = getattr(ellipse, "center", None)
        if centre is not None:
            apart = math.hypot(centre[0] - marker.centroid[0], centre[1] - marker.centroid[1])
            if apart > 0.3 + 0.02 * radius:
                return None
            if self.fit and math.hypot(point[0] - centre[0], point[1] - centre[1]) > (
                0.25 + 0.02 * radius
            ):  # a perspective correction larger than any perspective bias: not trusted
                point = centre
        return Obs(int(marker.id), np.array([float(point[0]), float(point[1])]), radius)


def holds(rect: Rect, point: np.ndarray, reach: float, width: int, height: int) -> bool:
    """True when ``rect`` holds the disc of radius ``reach`` about ``point`` in a frame of
    ``width`` x ``height`` pixels (a side of ``rect`` on the frame's border holds anything)."""
    x0, y0, x1, y1 = rect
    x, y = float(point[0]), float(point[1])
    return (
        (x0 == 0 or x - reach >= x0 - 0.5)
        and (y0 == 0 or y - reach >= y0 - 0.5)
        and (x1 == width or x + reach <= x1 - 0.5)
        and (y1 == height or y + reach <= y1 - 0.5)
    )


def present(observations: Iterable[Obs | None]) -> list[Obs]:
    """The observations that are not None."""
    return [o for o in observations if o is not None]
