"""Plate analysis: from a petri-dish image to colonies worth picking (Teutsch et al., 4.1).

``analyze_plate(image)`` finds the dish, segments every object on the agar without knowing the
agar's colour, drops artefacts, and sorts the rest into authentic colonies (a deformed elliptic
shape, DES), merged colonies (touching colonies, not a DES) and mixed colonies (a DES holding two
species). Pure functions on arrays: no I/O.

Pipeline and the choices it makes where the paper leaves room:

0. **Scale.** Every size is in millimetres (``PlateParams``) and is turned into pixels from the
   dish found (its diameter is ``dish_diameter_mm``) or a calibrated ``px_per_mm``; images finer
   than ``analysis_px_per_mm`` are analysed on a resampled copy and the results mapped back
   (:mod:`labauto.vision.plate_scale`). Below, "px" means pixels of that working copy.
1. **Dish.** :func:`labauto.vision.dish.find_dish`: a Hough circle on a subsampled grey image
   as a first guess, moved to the dish's strongest circular edge (the same whatever the guess),
   then refined along rays where the colour leaves the agar's for about a millimetre and does
   not come back (the meniscus or the wall, not a line of the lid with agar beyond it), with a
   robust circle fit. On 24 synthetic plates its radius is 1.9 px short to 1.4 px long of the
   drawn agar edge, its centre within 1.9 px. A dish with over a quarter of its rim outside the
   image is refused (``detect_dish=False`` analyses the whole image). The usable area is the
   dish shrunk by ``rim_margin_mm`` (negative grows it), or a configured circle
   (``PlateParams.region``, also shrunk) or polygon (used as is). Bodies touching the usable
   area's border are kept (colonies at the meniscus), unless ``drop_at_border``.
2. **Objects** (paper eq. 1, with no knowledge of the agar's colour). The background is
   estimated from the dish itself (:mod:`labauto.vision.plate_background`): medians over cells
   of ~0.8 mm (a ~25 mm and a ~4 mm window) mark what is not agar, a normalised Gaussian
   convolution of the rest gives the local agar colour, and the outer ``rim_band_mm`` follow the
   dish's radial profile (the meniscus). A pixel is foreground when its summed squared deviation
   from the background over B, G, R (optionally weighted) exceeds ``t`` (``color_threshold``, or
   a multiple of the agar's noise). Faint colonies (a smoothed departure from a coarse
   background, :mod:`labauto.vision.plate_faint`) and ring colonies (a round edge with little
   body inside, by the circular Hough transform, :mod:`labauto.vision.plate_rings`) are added to
   that foreground. Lines thinner than ``open_mm`` are opened away so colonies touching them
   come apart, and fragments of thick strokes are dropped (not a hued one: a colony they run
   into); small colonies the opening erased whole come back when hued, or lone and translucent
   (:mod:`labauto.vision.plate_opening`).
   Outer contours of all bodies, also those lying in another's hole, are traced in the
   8-neighbourhood (OpenCV). The gradient at each contour point is a 5x5 Sobel of the deviation
   image: it points into every object, whatever its colour. D_alpha, the centroid and the
   centroid-inside test come from :func:`labauto.vision.shape_angle.shape_angles`, vectorised
   over all contours.
   ``method="detector"`` uses :func:`labauto.vision.detector.detect` instead (slower). The
   rim's radial profile and the ring colonies' circle search need only the image: they run in
   a thread beside the rest of this step (:func:`labauto.vision.plate_objects.start_beside`),
   with the same results as in sequence (:mod:`labauto.vision.plate_objects`).
3. **Artefacts** are dropped, in this order: ``area < min_colony_area_px`` (dust) or
   ``> max_colony_area_px``; mean width ``2 * area / perimeter < min_width_px`` (scratches, thin
   pen strokes: a disc of radius r gives r, a strip of width w gives w); elongation
   ``sqrt(l1 / l2)`` of the second moments above ``max_elongation`` (glare streaks, straight
   strokes; the paper's DES limit is about 1:4); area above ``max_fill_ratio`` times the largest
   inscribed disc (curved or closed pen writing), unless it is as wide as the plate's colonies
   (``chain_ratio``: a chain of colonies along a streak, counted as a merged body); arcs
   along the rim, pieces of the lid's and the wall's ring lines, and pieces the opening left
   of a band along the rim that goes on past both their ends (never a chain:
   :mod:`labauto.vision.plate_rim_arcs`); printed or written ink (black or blue,
   stroke-shaped, dot-sized or dotted: :mod:`labauto.vision.plate_ink`). The body's mask is
   its filled contour restricted to the foreground (a loop of ink is not solid) and closed
   with a 5x5 disc; holes under a tenth of it are filled (translucent centres,
   ``plate_bodies.HOLE_SHARE``).
4. **Classes.** Authentic: a DES, i.e. centroid inside and D_alpha (median by default) below
   ``des_threshold_deg``, and no waist: the deepest concavity (distance from the convex hull) is
   below ``max_concavity`` times the inscribed radius. D_alpha alone does not separate a merged
   pair of unequal colonies (they read 14-46 degrees, single colonies 2-21), the waist does
   (generator: singles <= 0.12, merged >= 0.22; ``max_concavity`` 0.2). Real colonies are round, so
   an authentic colony's axis ratio is at most ``max_authentic_elongation`` (1.2), and its distance
   transform has one peak (step 5 counts every body): two colonies that meet in a shallow waist
   pass the DES tests, and picking one would take a mix of two. A lone grey or white dot that
   the opening had erased and that came back (step 2) is doubtful and no DES: counted, never
   offered. Merged: every other object. Mixed:
   a DES whose colours do not follow one species' dome. Its pixels at least ``edge_skip_px`` inside
   the boundary are fitted per channel by a quadratic in the normalised distance to the boundary
   (the dome shading of one species); a pixel farther than ``mix_residual`` grey levels (Euclidean,
   BGR) from the fit is an outlier, and the colony is mixed when the fraction of outliers
   (``mix_score``) is at least ``mix_fraction``: a sector or speckles of a second species of
   another colour or brightness. A DES whose outliers hold one round spot of 0.4 mm or more
   (a small colony sitting on a large one, too small a share for the fraction) is mixed too
   (:func:`labauto.vision.plate_mixed.mix_scores`). The rule is absolute, not relative to the
   plate's other colonies, so a plate of only mixed colonies is still read right.
5. **Merged count.** Peaks of the merged body's distance transform (one per plateau), kept
   greedily from the highest; a peak is a new colony when the distance transform along the
   straight segment to every peak already kept dips below ``valley_ratio`` times the lower peak
   (a waist). At least 1: a body that is not a DES yet shows a single peak is one colony whose
   shape cannot be read as a DES (small colonies of a few pixels, irregular edges on real
   plates). It stays in the class ``merged`` (never offered for picking) with
   ``estimated_count`` 1; forcing 2 here over-counted small colonies on real plates by up to a
   third. A peak lower than ``peak_floor_ratio`` (0.3) times the median inscribed radius of
   the plate's DES bodies is no colony's centre (thin crescents of a large colony); a body with
   no point that deep that is also long (axis ratio ``sliver_elongation``, 1.5) is a sliver and
   is not reported (crescents of a large colony's pale rim, pieces of the wall). A body whose
   outline is a DES is counted with its holes filled (a translucent part or a reflection
   across one colony is no waist). A one-peak
   body longer than ``pair_elongation`` (1.3) and at least as large as the plate's median
   authentic colony counts two (two colonies overlapping too deeply for a waist): on the AGAR
   photographs F1 0.817 -> 0.827 and median count error 20.0 -> 17.9 %, on the phone photos
   (not used to choose it) 5.5 -> 3.1 %. Compact clumps of three whose members overlap deeply
   are the usual miss (counted 2). Small colonies sitting on a large one leave no peak of
   their own: a body counted one that is ``LARGE_BODY_RATIO`` (1.5) times as wide (inscribed
   radius) as the plate's single colonies counts one more colony for every round spot off its
   dome (the mixed rule's spots, step 4; a DES with one is mixed as before). On the AGAR
   photographs 7 more colonies matched and none more unmatched (F1 0.892 -> 0.894; plate
   14581: 12 -> 6 boxes missed); at 7 and 4.5 px/mm +8 and +10 matched of +8 and +13
   reported. A spot in a DES of ordinary size stays a mix, not a count: counting those too
   reported 28 more colonies for 1 more matched. Tried for clumps of small colonies (518: five
   boxed colonies in a 1.9 mm body counted 1), not kept: a body counted 2 or more counting at
   least its area over 1.0-1.4 times the median single colony's (F1 0.858-0.868), the most
   cores over 12 levels of its smoothed deviation (F1 0.875-0.883: a colony's own texture
   gives cores), and analysis at 16 or 20 px/mm (F1 0.892).
   **Cores** (:mod:`labauto.vision.plate_cores`). Colonies are domes, so a clump that leaves
   the distance transform no waist falls apart, above some level of its departure, into one
   round core per colony (OpenCFU's multi-threshold idea). A merged body that is no inked
   print counts the larger of its count above and its most round cores at any of 12 levels
   (a core at least 0.35 of the plate's single-colony radius, filling 0.85 of the ellipse in
   its bounding box); a body whose departure rises by less than half of eq. 1's threshold
   has no dome and is not cut. Unlike the count of cores over the deviation tried before,
   the levels are each body's own percentiles and the cores must be round and of a colony's
   size. Measured (``benchmarks/bench_real_plates.py``), with against without: AGAR reported
   1678 -> 1689, matched 1615 -> 1626 (F1 0.906 -> 0.910; 518 242 -> 251 of 298 boxed),
   boxes inside bodies counted short 95 -> 84; phone-counts median 2.5 -> 1.9 % (IMG_2532
   658 -> 667 for 680, IMG_2534 689 -> 707 for 721; IMG_2535 545 -> 549 for 539). At 7 px/mm
   AGAR F1 0.896 -> 0.897 (median count error 6.5 -> 7.3 %), phone-counts 3.9 -> 3.4 %; at
   4.5 px/mm 0.882 -> 0.884, phone-counts 4.1 -> 4.3 %. 8 or 16 levels gave F1 0.909 and
   phone-counts 2.5 / 2.3 %; without the rise test the large faint colonies of AGAR plates
   11761, 11764 and 12028 read as 3-4 cores at 7 px/mm (11 colonies more, none boxed). The
   generator's plates keep 0 false colonies and 34 of 36 merged counts right. Tried, not kept:
   a DES with two cores made merged (one two-colony body fewer offered on AGAR, one single
   colony of the generator's lost), and counting the circles fitted to a body's outline
   between its concave points (on AGAR as many counts made wrong as right).
   **How far counting can go.** With every merged body's count set to the boxed colonies
   whose centres it holds (at least 1), the AGAR photographs would give reported 1724,
   matched 1702 (F1 0.943, against 0.910): the rest of the way to the goal is in colonies
   found in no body. A learned count (a random forest, scikit-learn, on 11 features of each
   merged body's outline: its area over the plate's median single colony, solidity,
   elongation, compactness, concave points deeper than a quarter of a single colony's
   radius, the count above, ...), trained on the boxes and scored plate-wise (5 folds, each
   fold's plates counted by the model of the others), did not pay: as the count, F1
   0.900-0.906 (depths 4 and 8, leaves of 3 and 10); only raising the count, 0.906-0.909
   (2026-12-07, seventh session). 526 merged bodies are too few, and 518 holds most of the
   bodies counted short.

Coordinates: pixels, origin at the centre of the top-left pixel, x right, y down.
"""

from __future__ import annotations

import math
import time

import cv2
import numpy as np

from labauto.vision.dish import Dish, find_dish
from labauto.vision.image import as_image
from labauto.vision.plate_area import prepare_plate
from labauto.vision.plate_bodies import MIN_SINGLES, PAD, measure_bodies
from labauto.vision.plate_cores import core_counts
from labauto.vision.plate_counts import merged_counts, pair_counts
from labauto.vision.plate_ink import ink_bodies, without_ink
from labauto.vision.plate_mixed import LARGE_BODY_RATIO, mix_scores
from labauto.vision.plate_objects import (
    agar_background,
    objects_by_detector,
    objects_by_segmentation,
    start_beside,
)
from labauto.vision.plate_params import PlateParams
from labauto.vision.plate_result import Colony, PlateResult
from labauto.vision.plate_rim_arcs import RimPolar, on_ring_lines, rim_arcs

__all__ = [
    "Colony",
    "Dish",
    "PlateParams",
    "PlateResult",
    "analyze_plate",
    "find_dish",
    "prepare_plate",
]


def analyze_plate(image: np.ndarray, params: PlateParams | None = None) -> PlateResult:
    """Find and classify the colonies on a petri-dish image.

    Parameters
    ----------
    image : ndarray
        HxWx3 BGR image (as ``cv2.imread`` gives), uint8 or a real type on a 0-255 scale; HxW
        grey and HxWx4 (alpha dropped) are accepted.
    params : PlateParams, optional
        Tunables; ``PlateParams()`` by default.

    Returns
    -------
    PlateResult
        The dish, the colonies (authentic, merged, mixed; artefacts dropped), counts and the time
        taken.

    Raises
    ------
    ValueError
        If the image is empty, has a wrong shape or type, or no dish is found.
    """
    t0 = time.perf_counter()
    params = PlateParams() if params is None else params
    img = as_image(image, color=True, min_side=64)
    h, w = img.shape[:2]
    stage_ms: dict[str, float] = {}
    t_stage = t0

    def stage_done(name: str) -> None:
        nonlocal t_stage
        now = time.perf_counter()
        stage_ms[name] = (now - t_stage) * 1000.0
        t_stage = now

    dish, copy, params, (x0, y0), usable, rim = prepare_plate(img, params)
    roi = copy.image[y0 : y0 + usable.shape[0], x0 : x0 + usable.shape[1]]
    if not params.drop_at_border:
        # a margin of PAD px all round, so that bodies touching the usable area's border
        # (colonies at the meniscus) still have whole crops
        roi = cv2.copyMakeBorder(roi, PAD, PAD, PAD, PAD, cv2.BORDER_REPLICATE)
        usable = cv2.copyMakeBorder(usable, PAD, PAD, PAD, PAD, cv2.BORDER_CONSTANT, value=0)
        x0, y0 = x0 - PAD, y0 - PAD
        if rim is not None:
            rim = (rim[0] + PAD, rim[1] + PAD, rim[2])
    stage_done("dish")

    # what needs only the image runs beside eq. 1's segmentation, in a thread
    profile, circles = start_beside(roi, usable, rim, params)
    background = agar_background(roi, usable, params, rim, profile)
    if params.method == "detector":
        objects = objects_by_detector(roi, usable, params)
    else:
        objects = objects_by_segmentation(roi, usable, params, background, circles)
    contours, d_alpha, centroids = objects.contours, objects.d_alpha, objects.centroids
    rejected, fg = objects.rejected, objects.foreground
    stage_done("objects")

    # a DES needs its centroid inside and a small D_alpha; only then does the waist matter. A
    # doubtful object (a lone dot the opening had erased) is counted, never offered: no DES
    des_shape = objects.inside & (d_alpha < params.des_threshold_deg) & ~objects.doubtful
    bodies = measure_bodies(contours, fg, des_shape, params, rejected)
    ppm = float(params.px_per_mm or 0.0)
    arc = np.zeros(len(bodies.index), bool)
    if rim is not None:  # pieces of the lid's and the wall's ring lines: never a chain
        polar = RimPolar.of(contours, bodies.index, rim)
        arc = rim_arcs(polar, bodies.area, ppm)
        if (arc & ~bodies.stroke).any():
            rejected["rim_arc"] = int((arc & ~bodies.stroke).sum())
        bodies.stroke |= arc
        if objects.unopened is not None:  # a piece of a line that goes on past both its ends
            line = on_ring_lines(polar, ~bodies.stroke, ppm, objects.unopened)
            if line.any():
                rejected["ring_line"] = int(line.sum())
                bodies.stroke |= line
                arc |= line
    stroke_shaped = bodies.stroke & ~arc
    # a single colony's shape: a DES outline, no waist, round
    single = des_shape[bodies.index] & (bodies.concavity < params.max_concavity)
    single &= bodies.elongation <= params.max_authentic_elongation
    if params.reject_ink:
        coarse = copy.factor > 1.0  # a resampled webcam frame: print's dots have merged
        ink = ink_bodies(roi, background, bodies, ~bodies.stroke, ppm, single if coarse else None)
        if ink.any():
            rejected["ink"] = int(ink.sum())
            bodies.stroke |= ink
    des = single & ~bodies.stroke
    # the plate's yardstick: the inscribed radius of its single colonies
    single_r_in = float(np.median(bodies.r_in[des])) if des.sum() >= MIN_SINGLES else 0.0
    if params.chain_ratio > 0 and single_r_in > 0:  # as wide as a colony: a chain of them
        chain = stroke_shaped & (bodies.r_in >= params.chain_ratio * single_r_in)
        if params.reject_ink and chain.any():
            chain &= ~ink_bodies(roi, background, bodies, chain, ppm)
        if chain.any():
            rejected["stroke"] -= int(chain.sum())
            bodies.stroke &= ~chain
    stage_done("measures")
    # every body is counted: a DES holding two peaks apart (two colonies that meet in a shallow
    # waist) is merged, never offered for picking
    least_peak = params.peak_floor_ratio * single_r_in  # thinner: no colony's centre
    if params.sliver_elongation > 0 and least_peak > 0:  # no centre anywhere, and long
        sliver = ~bodies.stroke & (bodies.r_in < least_peak)
        sliver &= bodies.elongation >= params.sliver_elongation
        if sliver.any():
            rejected["sliver"] = int(sliver.sum())
            bodies.stroke |= sliver
            des &= ~sliver
    # printed characters touching a colony are not counted as colonies
    count_mask, inked = None, np.zeros(len(des), bool)
    if params.reject_ink:
        found = without_ink(roi, background, bodies, ~bodies.stroke & ~des)
        if found is not None:
            count_mask, inked = found
    counts = merged_counts(
        bodies, ~bodies.stroke, params.valley_ratio, least_peak, des_shape[bodies.index], count_mask
    )
    des &= counts == 1
    counts = np.where(inked, counts, pair_counts(bodies, counts, des, params.pair_elongation))
    # small colonies on a large one: round spots off its dome, each one more colony
    large = ~bodies.stroke & (counts == 1) & (single_r_in > 0)
    large &= bodies.r_in >= LARGE_BODY_RATIO * single_r_in
    mix, spots = mix_scores(roi, bodies, des | large, params)
    counts = np.where(large, counts + spots, counts)
    if objects.departure is not None:  # a clump without waists: its colonies' cores
        clump = ~bodies.stroke & ~des & ~inked
        least_rise = 0.5 * math.sqrt(params.color_threshold)  # half eq. 1's t, as a distance
        cores = core_counts(bodies, objects.departure, clump, single_r_in, least_rise)
        counts = np.maximum(counts, cores)
    mix, spotted = np.where(des, mix, 0.0), spots > 0  # the mixed score is a DES's alone

    colonies: list[Colony] = []
    for b, k in enumerate(bodies.index.tolist()):
        if bodies.stroke[b]:
            continue
        klass = "merged"
        if des[b]:
            klass = "mixed" if mix[b] >= params.mix_fraction or spotted[b] else "authentic"
        centroid = copy.to_original(np.add(centroids[k], (x0, y0)))
        colonies.append(
            Colony(
                id=len(colonies),
                centroid=(float(centroid[0]), float(centroid[1])),
                klass=klass,
                area_px=float(bodies.area[b]) / copy.factor**2,
                d_alpha_median=float(d_alpha[k]),
                estimated_count=int(counts[b]),
                contour=copy.to_original(np.add(contours[k].reshape(-1, 2), (x0, y0))),
                mix_score=float(mix[b]),
            )
        )
    stage_done("classes")
    timing = (time.perf_counter() - t0) * 1000.0
    return PlateResult(
        width=w,
        height=h,
        timing_ms=timing,
        dish=dish,
        colonies=colonies,
        rejected=rejected,
        stage_ms=stage_ms,
    )
