"""Colonies in each merged body: the distance transform's peaks and waists (plate analysis,
step 5).

A merged body is counted by the peaks of its distance transform that a waist parts
(:func:`merged_counts`); two colonies that overlap so far that no waist is left are told by the
body's length (:func:`pair_counts`). The cores of a clump without waists are counted by
:mod:`labauto.vision.plate_cores`. :mod:`labauto.vision.plate` gives the rules and their
measured figures.
"""

from __future__ import annotations

import itertools

import cv2
import numpy as np

from labauto.vision.plate_bodies import MIN_SINGLES, Bodies, holes_filled

MIN_MERGED_COUNT = 1  # a body that is not a DES but shows one peak: one colony, not pickable
_DISC5 = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))  # a peak's neighbourhood


def merged_counts(
    bodies: Bodies,
    which: np.ndarray,
    valley_ratio: float,
    least_peak: float = 0.0,
    round_outline: np.ndarray | None = None,
    count_mask: np.ndarray | None = None,
) -> np.ndarray:
    """Colonies in each merged body (where ``which`` is true; 1 elsewhere), all at once.

    Step 5: one peak per plateau of the distance transform's local maxima (5x5), above
    ``max(2, least_peak, 0.3 r_in)``, at its highest pixel (the first in raster order on a
    tie); peaks are taken greedily from the highest (plateaus of equal height in the order
    OpenCV labels a crop: by their first 2x2 block in raster order), and a peak is kept when
    the straight segment to every peak kept before it dips below ``valley_ratio`` times the
    lower of the two. At least ``MIN_MERGED_COUNT`` (1). The segments between all pairs of
    peaks of a body are sampled at once. ``least_peak`` (px) is the plate's yardstick for a
    colony's centre (:attr:`PlateParams.peak_floor_ratio`); 0 leaves it out.

    The bodies where ``round_outline`` is true (their outline is a DES: centroid inside, small
    D_alpha) are counted with all their holes filled: round a hole the distance transform has
    a ring of peaks, and a round outline with a hole is one colony with a translucent part or a
    reflection across it (AGAR plates 14130 and 14627 had such colonies counted 4-6). A chain of
    colonies closed round a patch of agar has no round outline, and keeps its hole. Measured on
    the AGAR photographs: reported 1575 -> 1565, matched 1485 either way (F1 0.858 -> 0.861);
    filling the holes of every body also took 5 matched colonies of such chains. An open ring
    (a C: phone photo IMG_2525's ring about 1.7 mm across counted 3) is no DES either.
    Counting 1 every body of two or more that surrounds its centroid (the centroid outside
    it, its outline in 18 or 22 of 24 directions from it) cost 9 or 2 matched AGAR colonies
    (median count error 5.7 -> 7.3 %): such chains curl round agar as well. Not kept.
    Nor was a waist read along the ridge rather than the straight segment (two peaks one colony
    when a path inside the body joins them without dipping below ``valley_ratio`` times the
    lower: both in one component of the distance transform above that level), which counts a
    C-shaped body one and never counts more than the segment: AGAR reported 1687 -> 1666,
    matched 1626 -> 1617 (F1 0.910 either way), median count error 5.7 -> 9.2 %, phone-counts
    1.9 -> 2.0 % (ninth session). The segments' extra colonies in curved bodies are as often
    real colonies (a bent chain) as not. A clump counted by its area over the plate's median
    single colony's (at least the peaks' count, for the bodies of two or more peaks), read off
    the bodies' boxed colonies: AGAR F1 0.837-0.871 for areas of 1-2 single colonies a colony,
    against 0.900 by the peaks on the same reckoning: colonies differ too much in size.

    ``count_mask`` (a canvas as ``bodies.mask``) replaces the bodies' masks for counting: the
    masks without the printed ink across them (:func:`labauto.vision.plate_ink.without_ink`).
    """
    counts = np.ones(len(bodies.index), np.intp)
    if not which.any():
        return counts
    counts[which] = MIN_MERGED_COUNT
    rows, first_row, width = bodies.slots_of(which)
    dt, row_body = bodies.dt[rows, :width], bodies.row_body[rows]
    r_in = bodies.r_in
    if count_mask is not None or (round_outline is not None and (round_outline & which).any()):
        solid = (bodies.mask if count_mask is None else count_mask)[rows, :width]
        if round_outline is not None:
            solid = holes_filled(solid, row_body, round_outline)
        dt = cv2.distanceTransform(solid, cv2.DIST_L2, 3)
        r_in = np.zeros(len(which))
        r_in[which] = np.maximum.reduceat(dt.max(axis=1), first_row[which])
    floor = np.maximum(max(2.0, least_peak), 0.3 * r_in)
    floor_of_row = np.where(row_body >= 0, floor[np.maximum(row_body, 0)], np.inf)
    cand = (dt >= cv2.dilate(dt, _DISC5)) & (dt >= floor_of_row[:, None])
    n, labels = cv2.connectedComponents(cand.view(np.uint8), connectivity=8)
    if n <= 1:
        return counts
    ys, xs = np.nonzero(cand)  # raster order
    plateau, value = labels[ys, xs], dt[ys, xs]
    order = np.lexsort((-value, plateau))  # by plateau, highest first, raster order on ties
    first = order[np.searchsorted(plateau[order], np.arange(1, n))]
    first_block = np.full(n, np.iinfo(np.intp).max)
    np.minimum.at(first_block, plateau, (ys // 2) * dt.shape[1] + xs // 2)
    peaks = first[np.argsort(first_block[1:], kind="stable")]  # body after body (rows)
    body = row_body[ys[peaks]]
    pv = value[peaks].astype(np.float64)
    peaks = peaks[np.lexsort((-pv, body))]  # per body, highest first (stable on ties)
    body, pv = row_body[ys[peaks]], value[peaks].astype(np.float64)
    px, py = xs[peaks], ys[peaks] - first_row[body]  # crop coordinates
    # every pair (j, i) of peaks of one body with i before j
    bounds = np.flatnonzero(np.diff(body, prepend=-1, append=-1))
    pairs = [
        (j, i)
        for lo, hi in itertools.pairwise(bounds.tolist())
        for j in range(lo + 1, hi)
        for i in range(lo, j)
    ]
    if not pairs:
        return counts
    jj, ii = np.array(pairs, np.intp).T
    # the segment from peak j to peak i, sampled as np.linspace(p_j, p_i, m) in crop pixels
    dx, dy = px[ii] - px[jj], py[ii] - py[jj]
    m = np.sqrt((dx * dx + dy * dy).astype(np.float64)).astype(np.intp) + 2
    seg_start = np.cumsum(m) - m
    pair = np.repeat(np.arange(len(m)), m)
    t = (np.arange(pair.size) - seg_start[pair]).astype(np.float64)
    lx = t * (dx / (m - 1))[pair] + px[jj][pair]
    ly = t * (dy / (m - 1))[pair] + py[jj][pair]
    last = seg_start + m - 1
    lx[last], ly[last] = px[ii], py[ii]
    samples = dt[ly.round().astype(np.intp) + first_row[body[jj]][pair], lx.round().astype(np.intp)]
    valley = np.minimum.reduceat(samples, seg_start)  # lowest point of every segment
    joined = valley >= valley_ratio * np.minimum(pv[jj], pv[ii])  # no waist between j and i
    joined_to: dict[int, set[int]] = {}
    for j, i in zip(jj[joined].tolist(), ii[joined].tolist(), strict=True):
        joined_to.setdefault(j, set()).add(i)
    for lo, hi in itertools.pairwise(bounds.tolist()):
        kept: list[int] = []
        for j in range(lo, hi):
            if not joined_to.get(j, set()).intersection(kept):
                kept.append(j)
        counts[body[lo]] = max(MIN_MERGED_COUNT, len(kept))
    return counts


def pair_counts(
    bodies: Bodies, counts: np.ndarray, authentic: np.ndarray, pair_elongation: float
) -> np.ndarray:
    """``counts`` with the merged bodies of one peak that are two colonies counted 2 (step 5).

    Two colonies that overlap by more than about half their diameter leave no waist for the
    distance transform, so :func:`merged_counts` finds one peak. Such a body is longer than a
    single colony (axis ratio at least ``pair_elongation``; single colonies on the AGAR
    photographs: 1.01-1.21, 5th-95th percentile) and at least as large as the plate's median
    single colony (``authentic``: the authentic and mixed DES, ``MIN_SINGLES`` or more); a
    small or round irregular colony is neither.
    Measured on the AGAR photographs: of the one-peak merged bodies, 36 of the 52 that hold two
    or more boxed colonies and 13 of the 255 that hold one or none pass both.
    Tried and not kept: the axis ratio of the body opened by a disc of 0.5, 0.8 or 1.0 times
    its inscribed radius, so that pieces of the wall's lines stuck to a colony at the rim do
    not make it long (phone photo IMG_2528: one colony counted 2, 14 for 12): AGAR F1 0.911,
    0.909, 0.906 (0.910 without), median count error 5.7 -> 8.6 % at all three.
    """
    if pair_elongation <= 0 or authentic.sum() < MIN_SINGLES:
        return counts
    single = float(np.median(bodies.area[authentic]))
    pair = ~authentic & ~bodies.stroke & (counts == 1)
    pair &= (bodies.elongation >= pair_elongation) & (bodies.area >= single)
    return np.where(pair, 2, counts)
