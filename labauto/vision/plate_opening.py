"""Thin lines opened away, and the small colonies the opening erased put back (plate analysis,
step 2).

Eq. 1's foreground (:mod:`labauto.vision.plate_background`) holds the lid's and the wall's
edges, scratches and hairs as well as the colonies; a colony touching a line is one body with
it. :func:`open_thin_lines` opens the foreground with a disc of ``PlateParams.open_mm`` (0.75 mm),
so that lines go and colonies come apart from them, and drops the fragments a thick stroke
leaves (not the hued ones: pigmented colonies the strokes run into). The opening also erases
whole colonies narrower than its disc: :func:`with_erased_colonies` puts back those that look
like small colonies (hued, or lone and translucent dots).

At the agar's edge (ninth session, 2026-12-07): of the 48 boxed AGAR colonies within 4 mm of the
dish's edge that are not matched, 10 are eq. 1's foreground that the opening erased (small
olive colonies beside the wall's lines, so not lone; 518 has 7), 12 have their centre beyond
the usable area (up to 2 mm), 19 are faint colonies in the faint pass's margin and 7 lie in
reported bodies. An opening that takes the pixels beyond the usable area for foreground in its
erosion (so that a colony cut by the area's border is opened as if whole) changed nothing:
AGAR reported +2, matched +0; the erased ones are smaller than the disc on their own.
"""

from __future__ import annotations

import cv2
import numpy as np

from labauto.vision.plate_ink import INK_PIXEL_DARKER

_FRAGMENT_RATIO = 0.5  # a piece is a fragment when the opening took this much around it


def open_thin_lines(
    fg: np.ndarray,
    size: int,
    image: np.ndarray | None = None,
    background: np.ndarray | None = None,
) -> np.ndarray:
    """``fg`` opened with a disc of ``size`` px, without the fragments of thick strokes.

    The opening removes what is thinner than the disc: the lid's and the wall's edges, hairs,
    scratches, so that colonies touching them come apart from them. A thick pen stroke or a
    label's bar is not removed whole: the opening leaves pieces where it is widest. A piece is
    such a fragment when the pixels the opening removed within ``size`` px around it outnumber
    ``_FRAGMENT_RATIO`` of its own area (a colony that a line crossed loses a few line pixels
    around it; a piece of a stroke is flanked by the rest of the stroke) and is dropped.
    Limit: a stroke nearly as wide as the disc, or a blot on it wider than ~1.3 times the
    stroke, leaves pieces this rule keeps; black and blue ones are caught later as ink
    (:mod:`labauto.vision.plate_ink`).

    With ``image`` and ``background`` (the agar's colour behind it), a fragment whose departure
    from the agar is mostly hue (:func:`hued`) is kept: a pigmented colony that the lid's
    lines or a label's print run into is flanked by them as a stroke's piece is, but lines and
    print are grey or black. On the AGAR photographs 21 of 475 fragments held a boxed colony,
    10 of them yellow; the 11 others are olive (7 on plate 518) and are still dropped. With
    hued fragments kept, matched 1590 -> 1596, reported 1646 -> 1653 (F1 0.900 -> 0.902,
    median count error 8.8 -> 7.3 %); at 7 px/mm matched 1584 -> 1590 (F1 0.890 -> 0.892), at
    4.5 px/mm 1562 -> 1563; phone-counts unchanged at all three scales. Keeping every fragment
    found 28 more for 72 more reported (F1 0.898, phone-counts 2.5 -> 3.2 %); a ratio of 1.0
    in place of 0.5, 20 for 43 (F1 0.901); keeping also the fragments whose colour is at least
    0.4 of their departure away from the stroke's around them, 6 more for 15 (F1 0.902). Over
    8 one-pixel shifts of the photos (``bench_real_plates.py --shifts 8``, whose spread of F1
    is 0.008) the gain is smaller but the same way: AGAR F1 0.900 -> 0.901, median count error
    9.4 -> 8.4 %; at 7 and 4.5 px/mm F1 +0.001; phone-counts the same.
    """
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))
    opened = cv2.morphologyEx(fg, cv2.MORPH_OPEN, disc)
    removed = cv2.compare(fg, opened, cv2.CMP_GT)
    if not removed.any():
        return opened
    # labels without statistics, the areas counted at the pieces' own pixels: several times
    # quicker than connectedComponentsWithStats over the whole image
    n, labels = cv2.connectedComponents(opened, connectivity=8)
    if n <= 1 or n > np.iinfo(np.uint16).max:
        return opened
    xs, ys = cv2.findNonZero(opened).reshape(-1, 2).T
    piece = labels[ys, xs]
    area = np.bincount(piece, minlength=n)
    # the piece within ``size`` px of every removed pixel (16-bit dilation of the labels)
    around = cv2.dilate(labels.astype(np.uint16), disc)
    rx, ry = cv2.findNonZero(removed).reshape(-1, 2).T
    near = np.bincount(around[ry, rx], minlength=n)
    fragment = near > _FRAGMENT_RATIO * area
    fragment[0] = False
    if fragment.any() and image is not None and background is not None:
        mine = fragment[piece]  # the colours of the fragments' pixels alone
        fx, fy, fp = xs[mine], ys[mine], piece[mine]
        colour, agar = (_label_means(im, fx, fy, fp, n) for im in (image, background))
        fragment &= ~hued(colour, agar)
    if fragment.any():
        dropped = fragment[piece]
        opened[ys[dropped], xs[dropped]] = 0
    return opened


_HUE_SHARE = 0.5  # a body is hued when its departure is at least this much hue
_DOT_SPAN = 1.5  # a lone dot is at most this many opening discs across ...
_DOT_CLEAR = 2.5  # ... with no other foreground within this many discs of its centre


def with_erased_colonies(
    fg: np.ndarray, opened: np.ndarray, image: np.ndarray, background: np.ndarray, disc_px: int
) -> tuple[np.ndarray, np.ndarray | None]:
    """``opened`` with the bodies of ``fg`` that the opening erased whole and that look like
    small colonies put back: those whose colour departs from the agar mostly in hue, and lone
    dots; and a mask (uint8 0 / 255) of the lone dots without a hue of their own, or None when
    none came back.

    The opening (:func:`open_thin_lines`, a disc of ``disc_px``) also erases colonies narrower
    than its disc (under ~0.8 mm), and a small colony whose core alone passes eq. 1 is narrower
    still. Lines and printed dots are erased with them. A body erased whole touches nothing
    the opening kept, so putting it back joins nothing; the size, shape and ink tests then
    judge it as any other body.

    * **Hued.** Lines and printed dots are mostly grey or black: they take a like share of
      every channel away, while a pigmented colony shifts the agar's hue. The mean departure
      (B, G, R) of an erased body from the agar's colour behind it is split into its part along
      the grey axis and the rest (each channel minus the mean of the three); the body comes
      back when the rest is at least ``_HUE_SHARE`` of the whole. Measured on the AGAR
      photographs: matched 1501 -> 1539, reported 1558 -> 1599 (on nine plates; 11761 +11,
      11924 +9, 12031 +6, 12028 +4), F1 0.872 -> 0.883, plates over 15 % count error 16 -> 15;
      at 7 px/mm F1 0.848 -> 0.859, at 4.5 px/mm 0.805 -> 0.816; phone-counts unchanged. Hue
      shares of 0.3 and 0.7 gave F1 0.881 and 0.882.
    * **Lone dots.** A grey or white colony under a millimetre is a dot: at most
      ``_DOT_SPAN`` discs across, no more than twice as long as wide, filling at least half of
      its bounding box. Printed dots come in rows of characters, a line's pieces along it:
      a dot comes back only when the foreground within ``_DOT_CLEAR`` discs of its centre
      (a square window) holds no more than half its own area besides it. Putting back every
      erased compact body (no colour, no neighbours) found 80 more colonies but let hundreds of
      printed dots through (precision 0.69). A colony under a millimetre is thin and lets
      light through; a dot that lets through ``INK_PIXEL_DARKER`` (25 %) less light than
      its agar or more is opaque, dust or a full stop, and stays erased (the AGAR dots
      holding a boxed colony let through 9-18 % less; the generator's dust specks 23-40 %,
      those under 25 % smaller than the least colony). Measured
      (``benchmarks/bench_real_plates.py``, with the dots not offered as below): AGAR matched
      1553 -> 1567, reported 1621 -> 1643 (F1 0.886 -> 0.888; 734 +8, 518 +2), median count
      error 10.5 -> 11.5 % (plates over 15 %: 13 -> 14); phone-counts median 3.4 -> 3.0 %;
      at 7 px/mm F1 0.857 -> 0.860, phone-counts 5.3 -> 4.8 %; at 4.5 px/mm F1 0.847 ->
      0.853, phone-counts 6.6 -> 7.2 %. Clearances of 1.5-4 discs gave F1 0.887-0.888
      (measured before the opacity test). Putting back also the dots that are not lone but
      lighter than their agar (5 or 15 %; print is darker): on the generator's crowds of
      400 colonies of 0.3-0.8 mm 299 -> 347 found on amber agar and 287 -> 395 on chocolate,
      none false; but phone-counts 1.9 -> 6.2 % with 7 plates over 15 % (light specks its lab
      did not count) and AGAR F1 0.910 -> 0.908 (2026-12-07, eighth session).

    A lone grey or white dot is a doubtful colony: plate analysis counts it but never offers it
    for picking (:func:`labauto.vision.plate.analyze_plate`). Offered, such dots had added 4
    offers holding no boxed colony at 7 px/mm (7 -> 11 of 838) and 1 at 4.5 px/mm; not
    offered, the offers are as before at all three scales (874, 832 and 821).
    """
    removed = cv2.compare(fg, opened, cv2.CMP_GT)
    points = cv2.findNonZero(removed)
    if points is None:
        return opened, None
    n, labels = cv2.connectedComponents(fg, connectivity=8)
    survived = np.zeros(n, bool)
    kept = cv2.findNonZero(opened)
    if kept is not None:
        kx, ky = kept.reshape(-1, 2).T
        survived[labels[ky, kx]] = True
    x, y = points.reshape(-1, 2).T
    label = labels[y, x]
    erased = ~survived[label]
    if not erased.any():
        return opened, None
    x, y, label = x[erased], y[erased], label[erased]
    colour, agar = (_label_means(im, x, y, label, n) for im in (image, background))
    coloured = hued(colour, agar)
    # a colony under a millimetre is thin and lets light through; dust and printed dots are
    # opaque: they let through as little light as ink does
    opaque = colour.sum(axis=1) <= (1.0 - INK_PIXEL_DARKER) * agar.sum(axis=1)
    dot = _lone_dots(fg, x, y, label, disc_px, n) & ~opaque & ~coloured
    keep = (coloured | dot)[label]
    if not keep.any():
        return opened, None
    out = opened.copy()
    out[y[keep], x[keep]] = 255
    dots = None
    if dot.any():
        dots = np.zeros_like(fg)
        mine = dot[label]
        dots[y[mine], x[mine]] = 255
    return out, dots


def hued(colour: np.ndarray, agar: np.ndarray) -> np.ndarray:
    """Per row of ``colour`` and ``agar`` (n x 3, B, G, R): the departure of the one from the
    other is at least ``_HUE_SHARE`` hue, its part across the grey axis (each channel minus
    the mean of the three), not brightness. Lines, print and dust are grey or black."""
    departure = colour - agar
    hue = departure - departure.mean(axis=1, keepdims=True)
    return np.linalg.norm(hue, axis=1) >= _HUE_SHARE * np.linalg.norm(departure, axis=1)


def _label_means(
    image: np.ndarray, x: np.ndarray, y: np.ndarray, label: np.ndarray, n: int
) -> np.ndarray:
    """Mean B, G, R of ``image`` over the pixels ``(x, y)`` of each of ``n`` labels (n x 3)."""
    values = image[y, x].astype(np.float64)
    count = np.maximum(np.bincount(label, minlength=n), 1)
    sums = [np.bincount(label, values[:, c], minlength=n) for c in range(3)]
    return np.stack(sums, axis=1) / count[:, None]


def _lone_dots(
    fg: np.ndarray, x: np.ndarray, y: np.ndarray, label: np.ndarray, disc_px: int, n: int
) -> np.ndarray:
    """Per label (``n`` of them, ``fg``'s components): its pixels ``(x, y)`` make a lone
    dot (see :func:`with_erased_colonies`)."""
    order = np.argsort(label, kind="stable")
    ids, starts, area = np.unique(label[order], return_index=True, return_counts=True)
    xs, ys = x[order], y[order]
    x0, x1 = np.minimum.reduceat(xs, starts), np.maximum.reduceat(xs, starts)
    y0, y1 = np.minimum.reduceat(ys, starts), np.maximum.reduceat(ys, starts)
    bw, bh = x1 - x0 + 1, y1 - y0 + 1
    long, short = np.maximum(bw, bh), np.minimum(bw, bh)
    dot = (long <= _DOT_SPAN * disc_px) & (2 * short >= long) & (2 * area >= bw * bh)
    # the foreground in a square of 2 * _DOT_CLEAR discs round the dot's centre, by an
    # integral image (rows and columns of the integral are one past the pixel's)
    h, w = fg.shape
    half = int(_DOT_CLEAR * disc_px)
    cx, cy = (x0 + x1) // 2, (y0 + y1) // 2
    ax0, ax1 = np.clip(cx - half, 0, w), np.clip(cx + half + 1, 0, w)
    ay0, ay1 = np.clip(cy - half, 0, h), np.clip(cy + half + 1, 0, h)
    total = cv2.integral(cv2.compare(fg, 0, cv2.CMP_GT) // 255)
    around = total[ay1, ax1] - total[ay0, ax1] - total[ay1, ax0] + total[ay0, ax0] - area
    lone = np.zeros(n, bool)
    lone[ids] = dot & (2 * around <= area)
    return lone
