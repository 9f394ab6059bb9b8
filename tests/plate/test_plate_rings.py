"""Ring colonies (``labauto.vision.plate_rings``): a round edge with little body inside."""

from __future__ import annotations

import cv2
import numpy as np

from labauto.synthetic.plates import generate_plate, score_plate
from labauto.vision.plate import PlateParams, analyze_plate
from labauto.vision.plate_rings import ring_bodies, ring_circles

PX_PER_MM = 12.0


def _agar_with_rings(centres: list[tuple[int, int]], radius: int = 36) -> np.ndarray:
    """Flat pale agar (600 x 600 px at 12 px/mm) with dark rings of 6 mm, 3 px wide, 14 levels."""
    rng = np.random.default_rng(0)
    img = np.full((600, 600, 3), (150, 190, 170), np.float32)
    rings = np.zeros((600, 600), np.uint8)
    for c in centres:
        cv2.circle(rings, c, radius, 255, 3, cv2.LINE_AA)
    img -= 14.0 * (rings.astype(np.float32) / 255.0)[..., None]
    img += rng.normal(0.0, 2.0, img.shape).astype(np.float32)
    return np.clip(img, 0, 255).astype(np.uint8)


def _usable() -> np.ndarray:
    usable = np.zeros((600, 600), np.uint8)
    cv2.circle(usable, (300, 300), 290, 255, -1)
    return usable


def _rings(img: np.ndarray, fg: np.ndarray) -> np.ndarray:
    """The ring search on ``img`` and its circles filled into ``fg``."""
    return ring_bodies(_usable(), fg, ring_circles(img, _usable(), PX_PER_MM), PX_PER_MM)


def test_a_ring_is_filled_as_a_disc() -> None:
    img = _agar_with_rings([(200, 300), (400, 300)])
    fg = np.zeros((600, 600), np.uint8)
    out = _rings(img, fg)
    assert not fg.any()  # the input is not changed
    n, _, stats, centroids = cv2.connectedComponentsWithStats(out)
    assert n == 3
    order = np.argsort(centroids[1:, 0]) + 1
    for label, x in zip(order, (200, 400), strict=True):
        # within one cell of the Hough accumulator (1.5 work pixels of 1/4 mm: 4.5 px here)
        assert np.hypot(centroids[label, 0] - x, centroids[label, 1] - 300) < 4.5
        area = stats[label, cv2.CC_STAT_AREA]
        assert 0.8 * np.pi * 36**2 < area < 1.2 * np.pi * 36**2


def test_flat_agar_gives_no_ring() -> None:
    img = _agar_with_rings([])
    assert not _rings(img, np.zeros((600, 600), np.uint8)).any()


def test_a_colony_found_already_is_left_as_it_is() -> None:
    img = _agar_with_rings([(300, 300)])
    fg = np.zeros((600, 600), np.uint8)
    cv2.circle(fg, (300, 300), 30, 255, -1)  # eq. 1 found most of it
    out = _rings(img, fg)
    assert np.array_equal(out, fg)


def test_a_ring_on_the_agar_edge_is_not_taken() -> None:
    img = _agar_with_rings([(300, 30)])  # cut by the usable area's border (it starts at y=10)
    assert not _rings(img, np.zeros((600, 600), np.uint8)).any()


def test_a_piece_inside_joins_the_ring_and_a_neighbour_stays_apart() -> None:
    img = _agar_with_rings([(300, 300)])
    fg = np.zeros((600, 600), np.uint8)
    cv2.circle(fg, (300, 300), 8, 255, -1)  # the ring's darker centre, found by eq. 1
    cv2.circle(fg, (352, 300), 20, 255, -1)  # a neighbour reaching into the disc
    out = _rings(img, fg)
    n, labels = cv2.connectedComponents(out)
    assert n == 3  # the ring (with its centre) and the neighbour, not one body
    assert labels[300, 300] != labels[300, 352]
    assert labels[300, 270] == labels[300, 300]  # the disc holds the centre piece


def test_ring_colonies_of_the_generator_are_found() -> None:
    # faint colonies with a dark rim, as on AGAR plate 510
    found = {True: 0, False: 0}
    false_positives = {True: 0, False: 0}
    for seed in (1, 2, 3):
        img, truth = generate_plate(
            seed,
            agar="amber",
            faint_fraction=1.0,
            faint_contrast=0.04,
            ring_edge=10.0,
            colony_scale=1.6,
            n_merged=0,
            n_mixed=0,
            artefacts=False,
        )
        for rings in (True, False):
            score = score_plate(truth, analyze_plate(img, PlateParams(find_rings=rings)).colonies)
            found[rings] += score.found
            false_positives[rings] += score.false_positives
    # measured: 55 against 44 of 60, no false positive either way
    assert found[True] >= found[False] + 6
    assert false_positives[True] <= false_positives[False]
