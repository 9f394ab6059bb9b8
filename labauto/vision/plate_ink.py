"""Printed and written ink (labels on the lid or the dish's bottom) among the bodies on a plate.

Plate photos show the lid's printed label (often dot-matrix: lot, date, medium) and the lab's
handwriting across the agar. Eq. 1 sees every stroke and dot cluster as a body; the shape tests
catch long strokes, not the compact clusters of a dot-matrix character. Ink differs from the
colonies of the real plates we measured (cream, yellow, brown, olive, white) in colour:

* **Colour.** Black ink takes away a like share of every channel of the agar seen through it,
  blue ink more of red than of blue. Pigmented and turbid colonies take away more blue than red
  (short wavelengths first). A body is ink-coloured when it lets through at least 10 % less
  light than its agar (B + G + R summed) and its relative change in blue is no more negative
  than in red, less 1 % (blue ink on red agar: red falls, blue may even rise).
* **Shape or texture.** An ink-coloured body is ink when it is also a stroke (its area over 3.5
  inscribed discs; or narrower than 1.6 mm and over two discs; or narrower than 1.3 mm, a dot or
  a pen line) or dotted: fewer than 75 % of its pixels take at least half its mean darkening
  (the agar between printed dots; a colony is dark all over, dome shading included) and those
  dark pixels lie in two or more pieces (the dots; a dark colony with a pale sector of a second
  species is one dark piece). Measured on the AGAR photographs: requiring the pieces changes
  nothing there (precision 0.907 either way; three pieces: 0.903).
* **Faint print.** On a dark plate a dot-matrix character seen through the lid darkens its
  dots by a fifth to a quarter, too little for eq. 1 but enough for the faint-colony pass
  (:mod:`labauto.vision.plate_faint`), whose smoothing blurs the character into one round
  body: 5-14 % darker on average, with agar between the dots. A dotted body therefore needs
  only ``INK_DOTTED_DARKER`` (5 %) of darkening, strokes and coarse frames' blobs still 10 %.
  The bodies of the AGAR photographs with an ink hue and 1.3-23 % of darkening held no boxed
  colony (11 bodies counted 13, on the dark plates 13895, 13938 and 14618; the boxed colonies
  with an ink hue were darkened by at most 1.3 % or at least 23 %); 8 of those counts go.
  Measured (``benchmarks/bench_real_plates.py``): AGAR reported 1651 -> 1643, matched 1582
  either way (F1 0.895 -> 0.897), median count error 12.3 -> 9.1 %, plates over 15 % 14 ->
  13 (14618: 46 -> 42 for 40 boxed); phone-counts unchanged; at 7 px/mm F1 0.885 -> 0.886
  (one matched colony less), 11.1 % either way, plates over 15 % 14 -> 13; at 4.5 px/mm
  0.870 either way.
  The same 5 % for every ink body took two dark grey colonies of the generator's webcam-scale
  plate for print (``tests/plate/test_plate_real_cases.py``).

**Ink across a colony.** A printed character touching a colony is one body with it. Its
colour is then mostly the colony's, so the body is not ink, and the character's dots read as a
row of colonies in the merged count (AGAR plate 735: a printed "2" beside one colony counted
12). A pixel that lets through at least 25 % less light than its agar and is no more
blue-absorbing than red-absorbing is ink-coloured; a merged body at least 30 % of which is such
pixels is counted without them (:func:`without_ink`), and not as a pair by its outline, when
the rest of it has a pigmented colony's colour and the ink pixels are strokes or dots. Without
those two conditions, pairs of the generator's plates with a dark grey or a green colony lost
one (bench_plate: 33 of 36 merged counts exact, not 34). Measured on the AGAR photographs:
reported 1565 -> 1547 (735: 67 -> 57, 12028: 38 -> 32), matched 1485 either way, F1 0.861 ->
0.865; a share of 50 % gives 1556, darkening 0.2 or 0.3 the same as 0.25; phone-counts
unchanged; at 7 px/mm F1 0.821 -> 0.823. The median count error moves 10.0 -> 11.4 %: on 735
and 12028 those counts had made up for colonies missed.

**Coarse frames.** Below ``PlateParams.min_analysis_px_per_mm`` (8 px/mm, a webcam's frame,
resampled up for the analysis) the dots of a dot-matrix character (~0.4 mm, as far apart) have
merged into one blob: neither a stroke nor dotted, it was counted as a merged body of 2-10
colonies. There an ink-coloured body that has no single colony's shape (a DES, round, no waist)
is ink, unless half or more of the plate's single colonies are ink-coloured themselves (a plate
of dark grey colonies, whose pairs this rule would drop). Measured on the AGAR photographs
resampled to 4.5 px/mm: 96 such bodies held no boxed colony (204 colonies counted) and 4 held
one; reported 1716 -> 1526, matched 1383 -> 1374, F1 0.768 -> 0.805, median count error 17.6
-> 16.7 %; at 7 px/mm reported 1602 -> 1529, matched 1454 -> 1448, F1 0.834 -> 0.848;
phone-counts unchanged at both scales. At the native scale the rule would drop 5 matched
colonies for 10 false ones, and frames as fine as 8 px/mm resolve the dots, so it is kept to
coarse frames. A plate with fewer than ``MIN_SINGLES`` (3) single colonies gives no evidence
either way and the rule applies: sparse plates are where a label's blobs outnumber the
colonies (AGAR 11955 at 4.5 px/mm: 20 counted for 4 boxed, now 11; 11773 at 7 px/mm: 9 for 5,
now 5). Before, such plates were left out: at 7 px/mm AGAR reported 1684 -> 1680 (F1 0.886
-> 0.887, median count error 11.1 -> 9.3 %), at 4.5 px/mm 1687 -> 1673 (F1 0.870 -> 0.874),
matched the same; phone-counts unchanged.

Limit: a dark grey or blue colony (some chromogenic media) that is small or stroke-shaped
reads as ink; ``PlateParams.reject_ink`` turns the test off for such plates.

Limit: a dot-matrix character whose dots the faint pass joins into one filled body (an "0" or a
"D" on the dark plates 13895, 13938 and 14618: 4 of the 18 AGAR bodies that hold no boxed
colony) is darkened evenly, 8-14 %, with too few pixels 25 % darker to read as dots, so it is
neither dotted nor a stroke. Counting the dots by a black top-hat (discs of 0.6 and 1 mm,
levels of 0.75-1.5 times the body's mean darkening): at no setting did all four hold two or
more dots (13938's held 1 or 2, 14618's smaller one 1 or 3, 13895's 2-31). Not kept.
"""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np

from labauto.vision.plate_bodies import MIN_SINGLES, holes_filled

INK_DARKER = -0.10  # least mean relative darkening of an ink body ...
INK_DOTTED_DARKER = -0.05  # ... or of a dotted one
INK_BLUE_MARGIN = -0.01  # ink's relative change in blue minus that in red is at least this
INK_FILL = 3.5  # a stroke: area over this many inscribed discs ...
INK_STROKE_MM = 1.6  # ... or narrower than this and over two discs ...
INK_DOT_MM = 1.3  # ... or narrower than this, whatever its shape
INK_SOLID = 0.75  # a dotted body has fewer of its pixels this dark (relative to its mean)
INK_DOTS = 2  # ... and its dark pixels lie in at least this many pieces
INK_PIXEL_DARKER = 0.25  # an ink pixel lets through at least this much less light ...
INK_SHARE = 0.3  # ... and a merged body of which this share is ink is counted without it
INK_SINGLES = 0.5  # a coarse frame: below this share of ink-coloured single colonies, any
# ink-coloured body that is no single colony's shape is ink
_PIXEL = np.dtype((np.void, 3))  # one BGR uint8 pixel as a single item


def ink_bodies(
    roi: np.ndarray,
    background: np.ndarray,
    bodies: Any,
    which: np.ndarray,
    px_per_mm: float,
    shaped: np.ndarray | None = None,
) -> np.ndarray:
    """True for the bodies (where ``which`` is true) that are printed or written ink.

    Parameters
    ----------
    roi, background : ndarray
        The plate's BGR pixels and the agar's colour behind them (same shape).
    bodies : labauto.vision.plate_bodies.Bodies
        The measured bodies (crops on a shared canvas: ``top``, ``left``, ``height``,
        ``width``, ``row``, ``mask``, ``area``, ``r_in``).
    which : ndarray of bool
        Bodies to test.
    px_per_mm : float
        Pixels per millimetre of ``roi``.
    shaped : ndarray of bool, optional
        On a coarse frame (resampled up for the analysis), which bodies have a single
        colony's shape (a DES, round, no waist); see "Coarse frames" in the module docstring.
    """
    n = len(bodies.index)
    out = np.zeros(n, bool)
    fill = bodies.area / np.maximum(math.pi * bodies.r_in**2, 1.0)
    thin = bodies.r_in < INK_STROKE_MM / 2 * px_per_mm
    dot = bodies.r_in < INK_DOT_MM / 2 * px_per_mm
    strokelike = (fill > INK_FILL) | (thin & (fill > 2.0)) | dot
    pixels = _body_pixels(roi, background, bodies, which)
    if pixels is None:
        return out
    cx, cy, body, colour, agar, darkening = pixels
    present, start, size = np.unique(body, return_index=True, return_counts=True)

    def means(values: np.ndarray) -> np.ndarray:  # per present body
        return np.add.reduceat(values, start, axis=0) / size.reshape(-1, *[1] * (values.ndim - 1))

    rel = means(colour) / means(agar) - 1.0  # the mean relative change in B, G, R
    dark = means(darkening)
    inky = rel[:, 0] - rel[:, 2] >= INK_BLUE_MARGIN
    coloured = (dark >= -INK_DARKER) & inky
    dark_px = darkening >= 0.5 * np.repeat(dark, size)
    out[present] = coloured & strokelike[present]
    solid = means(dark_px.astype(np.float64)) >= INK_SOLID
    dotted_colour = (dark >= -INK_DOTTED_DARKER) & inky
    for i in np.flatnonzero(dotted_colour & ~strokelike[present] & ~solid).tolist():
        b, mine = int(present[i]), slice(start[i], start[i] + size[i])
        canvas = np.zeros((int(bodies.height[b]), int(bodies.width[b])), np.uint8)
        canvas[cy[mine] - bodies.row[b], cx[mine]] = dark_px[mine]
        out[b] = _pieces(canvas) >= INK_DOTS
    if shaped is not None:  # a coarse frame: print's dots have merged into blobs
        singles = shaped[present]
        if singles.sum() < MIN_SINGLES or coloured[singles].mean() < INK_SINGLES:
            out[present] |= coloured & ~singles
    return out


def without_ink(
    roi: np.ndarray, background: np.ndarray, bodies: Any, merged: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """The bodies' canvas mask (as ``bodies.mask``) without the printed ink across the
    ``merged`` bodies, and which bodies had some; None when none had.

    An ink pixel is ``INK_PIXEL_DARKER`` darker than its agar (B + G + R) and no more
    blue-absorbing than red-absorbing (``INK_BLUE_MARGIN``), as the bodies of ink are. A body
    holds ink when (module docstring, "Ink across a colony"): at least ``INK_SHARE`` of its
    pixels are ink; the rest is a pigmented colony's colour (more blue-absorbing than red: a
    dark grey or green colony has many ink-coloured pixels and the rest of the same hue); and
    the ink pixels, holes filled, are a stroke or dots (area over ``INK_FILL`` inscribed discs),
    not a round body (a grey colony touching a yellow one).
    """
    pixels = _body_pixels(roi, background, bodies, merged)
    if pixels is None:
        return None
    cx, cy, body, colour, agar, darkening = pixels
    blue_over_red = colour[:, 0] / agar[:, 0] - colour[:, 2] / agar[:, 2]  # relative changes
    ink = (darkening >= INK_PIXEL_DARKER) & (blue_over_red >= INK_BLUE_MARGIN)
    n = len(merged)
    share = np.bincount(body[ink], minlength=n) / np.maximum(bodies.area, 1.0)
    rest = ~ink
    rest_rel = [
        np.bincount(body[rest], colour[rest, c], n)
        / np.maximum(np.bincount(body[rest], agar[rest, c], n), 1.0)
        for c in (0, 2)
    ]
    pigmented = rest_rel[0] - rest_rel[1] < INK_BLUE_MARGIN
    inked = (share >= INK_SHARE) & pigmented
    ink &= inked[body]
    if not ink.any():
        return None
    canvas = np.zeros_like(bodies.mask)
    canvas[cy[ink], cx[ink]] = 1
    canvas = holes_filled(canvas, bodies.row_body, inked)  # a colony's highlight is no gap
    r_in = np.maximum.reduceat(
        cv2.distanceTransform(canvas, cv2.DIST_L2, 3).max(axis=1), bodies.row
    )
    area = np.add.reduceat(np.count_nonzero(canvas, axis=1), bodies.row)
    inked &= area > INK_FILL * math.pi * np.square(r_in)
    ink &= inked[body]
    if not ink.any():
        return None
    out = bodies.mask.copy()
    out[cy[ink], cx[ink]] = 0
    return out, inked & merged


def _body_pixels(
    roi: np.ndarray, background: np.ndarray, bodies: Any, which: np.ndarray
) -> tuple[np.ndarray, ...] | None:
    """Every pixel of the bodies where ``which`` is true, at once, body after body (one body
    per canvas row): canvas x and y, body, BGR colour and agar colour (float32, the agar at
    least 1), and the darkening ``1 - (B + G + R) / (agar's B + G + R)`` (the light that comes
    through, summed over the channels); None when there is none."""
    points = cv2.findNonZero(bodies.mask)
    if points is None:
        return None
    cx, cy = points.reshape(-1, 2).astype(np.intp).T.copy()
    body = bodies.row_body[cy]
    tested = which[body]
    if not tested.any():
        return None
    cx, cy, body = cx[tested], cy[tested], body[tested]
    at = (cy - bodies.row[body] + bodies.top[body]) * roi.shape[1] + cx + bodies.left[body]
    colour = _pixels(roi, at)
    agar = np.maximum(_pixels(background, at), 1.0)
    darkening = 1.0 - (colour[:, 0] + colour[:, 1] + colour[:, 2]) / (
        agar[:, 0] + agar[:, 1] + agar[:, 2]
    )
    return cx, cy, body, colour, agar, darkening


def _pixels(image: np.ndarray, at: np.ndarray) -> np.ndarray:
    """The BGR pixels of ``image`` (HxWx3 uint8) at flat indices ``at``, as float32 (N x 3)."""
    flat = np.ascontiguousarray(image).reshape(-1).view(_PIXEL)
    return np.take(flat, at).view(np.uint8).reshape(-1, 3).astype(np.float32)


def _pieces(dark: np.ndarray) -> int:
    """Connected pieces (8-neighbourhood) of the nonzero pixels of ``dark`` (uint8)."""
    return cv2.connectedComponents(dark, connectivity=8)[0] - 1
