"""Fitted, bias-corrected centres in the tracker (issue 15, point 6: <= 0.1 px with ``--fit``).

Rendered coded markers with exact truth. The fitted centre comes from the centre circle and the
code ring's outer edge, so the whole marker (quiet zone included) must be in the searched
pixels: a marker that moved further than its window allowed for is searched again in a window
of its own rather than measured with its ring running into the mosaic's padding.
"""

from __future__ import annotations

import numpy as np
import pytest

from labauto.synthetic.markers import draw_marker, finish
from labauto.vision.markers import detect_markers
from labauto.vision.roi_mosaic import build_mosaic
from labauto.vision.tracking import MarkerTracker
from labauto.vision.tracking_search import MarkerSearch, holds

RADIUS = 10.0


def scene(
    centres: dict[int, tuple[float, float]], rng, smear=(0.0, 0.0), size=(480, 640), n=9
) -> np.ndarray:
    """Markers at ``centres`` (mid-exposure), moving by ``smear`` px during the exposure."""
    total = np.zeros(size)
    for s in np.linspace(-0.5, 0.5, n):  # the exposure's mean: exact motion blur
        image = np.full(size, 215.0)
        for mid, (x, y) in centres.items():
            draw_marker(image, mid, (x + s * smear[0], y + s * smear[1]), RADIUS, ink=25.0)
        total += image / n
    return finish(total, noise_sigma=1.0, rng=rng)


def test_a_window_holds_a_disc_unless_it_reaches_past_a_side_not_on_the_frame_border():
    assert holds((10, 10, 110, 110), np.array([60.0, 60.0]), 40.0, 640, 480)
    assert not holds((10, 10, 110, 110), np.array([90.0, 60.0]), 40.0, 640, 480)
    assert holds((0, 10, 110, 110), np.array([20.0, 60.0]), 40.0, 640, 480)  # frame border
    assert not holds((10, 10, 110, 110), np.array([20.0, 60.0]), 40.0, 640, 480)


def test_a_marker_cut_by_its_window_is_searched_again_in_a_window_of_its_own():
    rng = np.random.default_rng(3)
    truth = (300.3, 200.6)
    image = scene({7: truth}, rng, smear=(5.5, 2.0))
    search = MarkerSearch(detect_markers, None, candidates=False, fit=True)  # type: ignore[arg-type]
    # the window ends at the code ring's outer edge (x 330.3), blurred across it
    window = (240, 140, 331, 262)
    (found,), _ = search.in_windows(image, [window], extent_factor=3.6)
    assert found.id == 7
    assert np.hypot(*(found.position - truth)) < 0.03
    # measured in the cut window's tile, its ring's outer edge fit is off (0.16 px here)
    mosaic = build_mosaic(image, [window])
    (cut,) = [m for m in detect_markers(mosaic.image) if m.id == 7]
    assert np.hypot(*(np.subtract(cut.center, mosaic.offsets[0]) - truth)) > 0.1


@pytest.mark.parametrize("jump", [(22.0, 3.0), (-4.0, -21.0)])
def test_fitted_centres_hold_when_a_marker_moves_past_its_first_window(jump):
    """A new track has no velocity: its first window allows 12 px; these move ~21 px per
    frame, blurred over a quarter of it (the benchmark's exposure)."""
    rng = np.random.default_rng(5)
    start = {3: (200.4, 180.2), 11: (420.7, 300.9)}
    frames = [start, {m: (x + jump[0], y + jump[1]) for m, (x, y) in start.items()}]
    tracker = MarkerTracker(fit=True, full_interval=10)
    smear = (0.25 * jump[0], 0.25 * jump[1])
    results = [tracker.update(scene(truth, rng, smear)) for truth in frames]
    assert results[1].mode == "roi"  # found in their windows, no fall-back to the full frame
    for result, truth in zip(results, frames, strict=True):
        assert set(result.centers()) == set(truth)
        for mid, centre in result.centers().items():
            assert np.hypot(*np.subtract(centre, truth[mid])) < 0.05


@pytest.mark.parametrize("smear", [(0.0, 0.0), (5.5, 2.0), (-2.0, 5.5)])
def test_fitted_centres_are_unbiased_under_motion_blur(smear):
    """Motion blur (a symmetric smear) widens the edges across the motion beyond the edge
    windows' +-3 px; cut, their profiles pulled the centre toward the first (Canny) fit's,
    0.08-0.1 px off along the motion. The re-measure's first look (``marker_edges.
    FIRST_WINDOW_PX``, +-5 px) places the later windows on the blurred edges."""
    rng = np.random.default_rng(8)
    truth = {
        4 * r + c: (110.3 + 140 * c + 0.37 * r, 100.6 + 140 * r + 0.21 * c)
        for r in range(3)
        for c in range(4)
    }
    result = MarkerTracker(fit=True).update(scene(truth, rng, smear))
    errors = [np.hypot(*np.subtract(c, truth[m])) for m, c in result.centers().items()]
    assert len(errors) >= 11
    assert max(errors) < 0.03 and np.median(errors) < 0.015
