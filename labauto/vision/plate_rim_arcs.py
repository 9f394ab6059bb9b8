"""Arcs along the rim: pieces of the lid's and the wall's ring lines (plate analysis, step 3).

A lid seen from above draws thin ring lines a few millimetres inside the agar's edge (its own
wall, seen with parallax), and the wall and the meniscus draw more. The opening of step 2 removes
such a line where it is thinner than ``open_mm``; where two lines lie close together, or the
image is coarse (a webcam frame resampled up), they blur into one band that survives it and
breaks into pieces along the rim. Such a piece is no colony. What tells it apart is its shape
in the dish's own polar coordinates: it runs along the rim, a colony is round. Choices made:

* **Near the rim.** Only bodies lying wholly within ``BAND_MM`` (10 mm) of the usable circle's
  edge are tested: the ring lines of the AGAR photographs lie 0-9 mm inside it.
* **A short piece** is radially thin (its points' distances from the centre span at most
  ``PIECE_RADIAL_MM``, 1.5 mm) and at least ``PIECE_RATIO`` (2) times as long along the rim.
  A round colony spans as much both ways; two colonies touching along the rim are at least
  as wide as one of them and are kept when wider than 1.5 mm.
* **A long arc** is at least ``ARC_RATIO`` (8) times as long along the rim as its mean width
  (``2 * area / perimeter``, which a parallax-tilted line keeps while it drifts in radius), with
  that mean width at most ``ARC_WIDTH_MM`` (2 mm). Seen as "stroke-shaped but as wide as a
  colony", such an arc was counted as a chain of colonies: up to 95 on one phone photo at
  4.5 px/mm, and the chain count took seconds.
* An arc is an artefact (``rejected["rim_arc"]``), never a chain of colonies.
* **A piece of a band** (:func:`on_ring_lines`). The meniscus, the wall's inner side or a
  lid's double line can make a band of foreground along the rim that is speckled with agar
  (a phone photo's meniscus) or only now and then wider than the opening's disc (a webcam
  frame); the opening then breaks it into small pieces, some of them as round as a colony.
  What tells such a piece apart is what lies beyond it: the band goes on past both its ends.
  On the arcs of ``LINE_BEYOND_MM`` (1.5 mm) along the rim just past each end, at every
  radius the piece spans, the foreground before the opening must cover at least
  ``LINE_SHARE`` (0.6) of the samples on both sides (``rejected["ring_line"]``). A colony
  on a thin line is wider than the line (a 2 mm colony on a 0.3 mm line: 0.15 of its span),
  and one alone at the rim has agar beyond it; a colony lying inside such a band cannot be
  told from it and goes with it.
  Measured (``benchmarks/bench_real_plates.py``), without against with: AGAR reported 1653 ->
  1651, matched 1582 either way (F1 0.894 -> 0.895; the median count error 11.1 -> 12.3 %,
  as two under-counted plates lost a body holding no boxed colony); phone-counts 2.3 ->
  2.0 %, IMG_2528 24 -> 14 colonies (12 by hand), the sum of the plates' absolute count
  errors 196 -> 182. At 7 px/mm AGAR reported 1693 -> 1688, matched 1582 either way;
  phone-counts 4.2 -> 3.5 % (plates over 15 % 5 -> 4, absolute errors 203 -> 182). At
  4.5 px/mm AGAR reported 1719 -> 1693, matched 1557 -> 1556 (F1 0.864 -> 0.870);
  phone-counts 4.5 -> 4.1 %. Beyond 2 mm with a share of 0.5, or 3 mm with 0.7: the same
  on AGAR within 3 matched, phone-counts 1.9-2.0 %, at 7 px/mm 3.5-4.1 %.

Measured on the real plates of ``benchmarks/bench_real_plates.py`` (with the dish of
:func:`labauto.vision.dish.find_dish`), against no arc test: AGAR reported 1660 -> 1646,
matched 1579 -> 1575 (F1 0.891 -> 0.892), median count error 12.2 -> 11.1 %; phone-counts
3.3 -> 2.3 %, plates over 15 % 6 -> 4. At 7 px/mm F1 0.880 -> 0.882, phone-counts 4.8 ->
4.2 %; at 4.5 px/mm F1 0.854 -> 0.861, 4.7 -> 4.3 %. The slowest phone photo took 1.85 s
without the long-arc rule (a crescent of the meniscus counted as a chain), 0.17 s with it.
The short-piece rule is the less certain one: the pieces it drops are 2-3 times as long as
wide, as two small colonies touching along the rim are, and with ``PIECE_RATIO`` 2.5 or 3 its
gain was gone (measured with the former dish search). Without it phone-counts reads 3.3 % with
6 plates over 15 %, and the median count error at 7 px/mm 9.0 % instead of 11.1 %.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from labauto.vision.plate_params import Circle

BAND_MM = 10.0
PIECE_RADIAL_MM = 1.5
PIECE_RATIO = 2.0
ARC_RATIO = 8.0
ARC_WIDTH_MM = 2.0
LINE_BEYOND_MM = 1.5
LINE_SHARE = 0.6


@dataclass(frozen=True)
class RimPolar:
    """The bodies' outline points in the dish's polar coordinates, body after body.

    ``rho`` is each point's distance from the usable circle's centre ``(cx, cy)``; per body,
    ``inmost`` and ``outmost`` are its least and largest ``rho``, ``mean`` its mean direction
    and ``first`` and ``last`` its points' least and largest angle from that direction
    (radians, in -pi..pi: no wrap at +-pi for a body); ``starts`` and ``lengths`` give each
    body's run of points. Both rim tests read it: :func:`rim_arcs` and :func:`on_ring_lines`.
    """

    points: np.ndarray
    rho: np.ndarray
    starts: np.ndarray
    lengths: np.ndarray
    rim: tuple[float, float, float]
    inmost: np.ndarray
    outmost: np.ndarray
    mean: np.ndarray
    first: np.ndarray
    last: np.ndarray

    @classmethod
    def of(cls, contours: list[np.ndarray], index: np.ndarray, rim: Circle) -> RimPolar:
        """The outlines of the bodies (``contours[index]``, Nx1x2 int, ROI pixels) round the
        usable circle ``rim = (cx, cy, r)`` (ROI pixels)."""
        cx, cy, r = (float(v) for v in rim)
        kept = [contours[k] for k in index.tolist()]
        lengths = np.array([len(c) for c in kept], np.intp)
        starts = np.cumsum(lengths) - lengths
        points = (
            np.concatenate(kept).reshape(-1, 2).astype(np.float64) if kept else np.zeros((0, 2))
        )
        dx, dy = points[:, 0] - cx, points[:, 1] - cy
        rho = np.hypot(dx, dy)
        if not kept:
            none = np.zeros(0)
            return cls(points, rho, starts, lengths, (cx, cy, r), none, none, none, none, none)
        phi = np.arctan2(dy, dx)
        mean = np.arctan2(
            np.add.reduceat(np.sin(phi), starts), np.add.reduceat(np.cos(phi), starts)
        )
        turn = np.angle(np.exp(1j * (phi - np.repeat(mean, lengths))))
        return cls(
            points,
            rho,
            starts,
            lengths,
            (cx, cy, r),
            inmost=np.minimum.reduceat(rho, starts),
            outmost=np.maximum.reduceat(rho, starts),
            mean=mean,
            first=np.minimum.reduceat(turn, starts),
            last=np.maximum.reduceat(turn, starts),
        )

    def __len__(self) -> int:
        return len(self.lengths)

    def near(self, px_per_mm: float) -> np.ndarray:
        """Per body: it lies wholly within ``BAND_MM`` of the rim."""
        return self.inmost >= self.rim[2] - BAND_MM * px_per_mm


def rim_arcs(polar: RimPolar, area: np.ndarray, px_per_mm: float) -> np.ndarray:
    """True for every body that is an arc along the rim (see the module docstring).

    Parameters
    ----------
    polar : RimPolar
        The bodies' outlines round the usable circle.
    area : ndarray of float
        Each body's area (pixels).
    px_per_mm : float
        Scale of the ROI.

    Returns
    -------
    ndarray of bool
        One entry per body.
    """
    if len(polar) == 0:
        return np.zeros(0, bool)
    rho, starts, lengths = polar.rho, polar.starts, polar.lengths
    near = polar.near(px_per_mm)
    radial = polar.outmost - polar.inmost
    along = (polar.last - polar.first) * np.add.reduceat(rho, starts) / lengths  # along the rim, px
    # perimeter of each closed outline: every point to the next, the last to the first
    points = polar.points
    following = np.arange(len(points)) + 1
    following[starts + lengths - 1] = starts
    steps = np.hypot(*(points[following] - points).T)
    width = 2.0 * area / np.maximum(np.add.reduceat(steps, starts), 1.0)
    piece = (radial <= PIECE_RADIAL_MM * px_per_mm) & (along >= PIECE_RATIO * radial)
    arc = (width <= ARC_WIDTH_MM * px_per_mm) & (along >= ARC_RATIO * np.maximum(width, 1.0))
    return near & (piece | arc)


def on_ring_lines(
    polar: RimPolar, which: np.ndarray, px_per_mm: float, unopened: np.ndarray
) -> np.ndarray:
    """True for every body (of those where ``which`` is true) that is a piece of a ring line.

    Such a body lies near the rim and the line it is a piece of goes on beyond it on both
    sides: on the arcs of ``LINE_BEYOND_MM`` along the rim just past each of its ends, at the
    radii it spans, ``unopened`` (the foreground before the opening) covers at least
    ``LINE_SHARE`` of the samples (module docstring).

    Parameters
    ----------
    polar, px_per_mm
        As for :func:`rim_arcs`.
    which : ndarray of bool
        The bodies to test (one entry per body).
    unopened : ndarray
        HxW uint8 mask (ROI pixels): eq. 1's foreground before thin lines were opened away.

    Returns
    -------
    ndarray of bool
        One entry per body.
    """
    online = np.zeros(len(polar), bool)
    if len(polar) == 0 or not which.any():
        return online
    tested = np.flatnonzero(which & polar.near(px_per_mm))
    if tested.size == 0:
        return online
    cx, cy, _ = polar.rim
    h, w = unopened.shape
    # every radius each tested body spans (whole pixels), body after body
    inner, outer = np.floor(polar.inmost[tested]), np.ceil(polar.outmost[tested])
    spans = (outer - inner).astype(np.intp) + 1
    first = np.cumsum(spans) - spans
    body = np.repeat(np.arange(tested.size), spans)
    radii = (inner[body] + np.arange(spans.sum()) - first[body])[:, None]
    beyond = np.arange(1.0, max(LINE_BEYOND_MM * px_per_mm, 2.0) + 1.0)  # px along the arc
    covered = []
    for turn, side in ((polar.last, 1.0), (polar.first, -1.0)):
        end = polar.mean[tested] + turn[tested]
        angle = end[body][:, None] + side * beyond / np.maximum(radii, 1.0)
        x = np.clip(np.rint(cx + radii * np.cos(angle)).astype(np.intp), 0, w - 1)
        y = np.clip(np.rint(cy + radii * np.sin(angle)).astype(np.intp), 0, h - 1)
        hits = np.count_nonzero(unopened[y, x], axis=1)
        covered.append(np.add.reduceat(hits, first) / (spans * beyond.size))
    online[tested] = np.minimum(*covered) >= LINE_SHARE
    return online
