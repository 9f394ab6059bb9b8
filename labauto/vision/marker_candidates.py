"""The two halves of marker detection a tracker needs apart: centre candidates and code reads.

:func:`labauto.vision.markers.detect_markers` does everything for every DES of an image:
contours, the DES prefilter, a geometric ellipse fit, the code read and the bias correction.
A tracker that already knows where each marker is needs only the first two for most markers:
the DES centroid of the centre circle (the paper's centre for tracking, section 4.3) found near
its prediction. :func:`centre_candidates` gives those (contours and shape angle only, no fits);
:func:`read_markers_at` runs the whole detector only around given places (new markers, or a
window where two candidates compete), on a mosaic of windows cut from the frame.

The candidates are the DES of the image whose area-equivalent radius is within the detector's
radius range (the same prefilter as ``detect_markers``), so a candidate's centroid is the very
``Marker.centroid`` the detector would report for it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from labauto.vision.detector import extract_contours
from labauto.vision.image import as_grey
from labauto.vision.marker_codes import QUIET_RADIUS
from labauto.vision.markers import Marker, MarkerParams, find_markers
from labauto.vision.roi_mosaic import build_mosaic, clip_rect, merge_overlapping
from labauto.vision.shape_angle import shape_angles

__all__ = ["CentreCandidates", "centre_candidates", "grey_image", "read_markers_at"]


@dataclass(frozen=True)
class CentreCandidates:
    """DES that may be a marker's centre circle.

    Attributes
    ----------
    centroids : ndarray
        (n, 2) DES centroids, pixels.
    radii : ndarray
        (n,) area-equivalent radii, pixels.
    asymmetry : ndarray
        (n,) distance between the area centroid and the mean of the contour's points, pixels.
        A whole circle or ellipse (also projected, also blurred) is centrally symmetric, so the
        two agree to the edge noise; a circle cut by an occluder or the frame edge is not.
    """

    centroids: np.ndarray
    radii: np.ndarray
    asymmetry: np.ndarray

    def __len__(self) -> int:
        return len(self.radii)


def grey_image(image: np.ndarray) -> np.ndarray:
    """The uint8 grey image the marker detector works on: read by the rules of
    :func:`labauto.vision.image.as_image`, as :func:`~labauto.vision.markers.detect_markers`
    reads it (so a float 0-1 or a BGRA frame gives the same markers), BGR converted."""
    return as_grey(image, min_side=1)


def centre_candidates(grey: np.ndarray, params: MarkerParams | None = None) -> CentreCandidates:
    """The DES of ``grey`` of a marker centre's size (no ellipse fit, no code read)."""
    params = params or MarkerParams()
    contours = extract_contours(grey, params.detector_params())
    if not len(contours):
        return CentreCandidates(np.zeros((0, 2)), np.zeros(0), np.zeros(0))
    angles = shape_angles(contours.points, contours.gradients, contours.offsets, contours.closed)
    radius = np.sqrt(np.maximum(angles.area, 0.0) / np.pi)
    keep = angles.is_des(params.des_threshold_deg)
    keep &= (radius >= params.min_radius_px * 0.5) & (radius <= params.max_radius_px * 1.2)
    lengths = np.maximum(contours.lengths, 1)
    means = np.add.reduceat(contours.points, contours.offsets[:-1], axis=0) / lengths[:, None]
    centroids = np.asarray(angles.centroid, np.float64)
    asymmetry = np.hypot(*(centroids - means).T)
    return CentreCandidates(centroids[keep], radius[keep], asymmetry[keep])


def read_markers_at(
    grey: np.ndarray,
    places: np.ndarray,
    radii: np.ndarray,
    params: MarkerParams | None = None,
) -> list[Marker]:
    """Run the whole marker detector in windows around ``places`` only.

    Parameters
    ----------
    grey : ndarray
        The frame (uint8 grey).
    places : ndarray
        (n, 2) where markers may be (candidate centroids), frame pixels.
    radii : ndarray
        (n,) their centre radii, pixels; each window holds the marker and its quiet zone.
    params : MarkerParams
        Of the detector.

    Returns
    -------
    list of Marker
        In frame pixels; one per id (the best read).
    """
    params = params or MarkerParams()
    height, width = grey.shape[:2]
    rects = []
    for (x, y), r in zip(np.asarray(places).reshape(-1, 2), np.asarray(radii), strict=True):
        half = 1.3 * QUIET_RADIUS * float(r) + 4.0
        rect = clip_rect(
            (int(x - half), int(y - half), int(x + half) + 2, int(y + half) + 2), width, height
        )
        if rect is not None:
            rects.append(rect)
    if not rects:
        return []
    mosaic = build_mosaic(grey, merge_overlapping(rects))
    best: dict[int, Marker] = {}
    for marker in find_markers(mosaic.image, params).markers:
        tile = mosaic.owner_of(marker.centroid)
        if tile is None:
            continue
        dx, dy = mosaic.offsets[tile]
        moved = marker.shifted(-float(dx), -float(dy))
        if moved.id not in best or moved.score > best[moved.id].score:
            best[moved.id] = moved
    return [best[k] for k in sorted(best)]
