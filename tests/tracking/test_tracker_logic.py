"""MarkerTracker's search logic on stand-in markers with known motion (see blob_world)."""

from __future__ import annotations

import numpy as np
import pytest
from blob_world import SIZE, detect_blobs, render, swaps

from labauto.vision.roi_mosaic import build_mosaic, merge_overlapping
from labauto.vision.tracking import MarkerTracker


def orbit(ids, t, speed=1.0):
    """Markers on a slowly turning, drifting ring: positions at frame ``t``."""
    out = {}
    for k, mid in enumerate(ids):
        angle = 2 * np.pi * k / len(ids) + 0.02 * speed * t
        out[mid] = (320 + 150 * np.cos(angle) + 0.8 * speed * t, 240 + 150 * np.sin(angle))
    return out


def run(tracker, truths, **render_options):
    results = []
    for truth in truths:
        results.append(tracker.update(render(truth, **render_options)))
    return results


def test_windows_follow_the_motion_and_full_searches_come_at_the_interval():
    ids = list(range(12))
    truths = [orbit(ids, t) for t in range(40)]
    tracker = MarkerTracker(detect_blobs, extent_factor=1.5, full_interval=10)
    results = run(tracker, truths)
    modes = [r.mode for r in results]
    assert [i for i, m in enumerate(modes) if m == "full"] == [0, 10, 20, 30]
    for result, truth in zip(results, truths, strict=True):
        assert set(result.centers()) == set(ids)
        for mid, center in result.centers().items():
            assert np.hypot(*np.subtract(center, truth[mid])) < 0.3
        assert swaps(result, truth, tol=1.0) == 0
    assert results[0].appeared == ids and all(not r.lost and not r.appeared for r in results[1:])
    # the windows searched are a small share of the frame (the first, without velocities, more)
    assert max(tracker.stats.window_pixels) < 0.4 * SIZE[0] * SIZE[1]
    assert np.median(tracker.stats.window_pixels) < 0.12 * SIZE[0] * SIZE[1]


def test_a_jerk_past_the_window_falls_back_to_a_full_search_in_the_same_frame():
    truths = [{1: (100 + 3 * t, 100), 2: (400, 300)} for t in range(6)]
    truths.append({1: (100 + 3 * 6 + 80, 100 + 60), 2: (400, 300)})  # a jump of 100 px
    tracker = MarkerTracker(detect_blobs, extent_factor=1.5, full_interval=50)
    results = run(tracker, truths)
    assert [r.mode for r in results] == ["full"] + ["roi"] * 5 + ["full"]
    assert set(results[-1].centers()) == {1, 2} and not results[-1].lost
    assert tracker.stats.fallbacks == 1


def test_markers_leaving_and_entering_are_lost_then_found_at_the_next_full_search():
    # marker 7 drives off the right edge at ~frame 12 and comes back from frame 30 on
    def place(t):
        x = 560 + 8 * t if t < 20 else 700 - 8 * (t - 20)
        return {3: (200.0, 200.0 + t), 7: (float(x), 300.0)}

    truths = [place(t) for t in range(50)]
    tracker = MarkerTracker(detect_blobs, extent_factor=1.5, full_interval=10, coast_frames=2)
    results = run(tracker, truths)
    visible = [
        (t, R_in_view(truth[7])) for t, truth in enumerate(truths)
    ]  # whether 7 is wholly in the frame
    left = next(t for t, v in visible if not v)
    back = next(t for t, v in visible[left:] if v)
    lost_at = next(r.frame for r in results if 7 in r.lost)
    assert lost_at == left
    assert all(7 not in r.centers() for r in results[left:back])
    next_full = next(r.frame for r in results[back:] if r.mode == "full")
    found_again = next(r.frame for r in results[back:] if 7 in r.centers())
    assert found_again <= next_full + 1
    assert 7 in results[found_again].appeared
    assert all(3 in r.centers() for r in results)  # the other marker never dropped


def R_in_view(point, margin=10):
    x, y = point
    return margin <= x <= SIZE[1] - 1 - margin and margin <= y <= SIZE[0] - 1 - margin


def test_an_occluded_marker_is_found_again_by_its_coasting_window_or_the_next_full_search():
    truths = [{1: (100.0 + 2 * t, 200.0), 2: (300.0 + 2 * t, 200.0)} for t in range(40)]
    occluded = range(8, 16)
    tracker = MarkerTracker(detect_blobs, extent_factor=1.5, full_interval=10, coast_frames=3)
    results = []
    for t, truth in enumerate(truths):
        box = [(280 + 2 * t, 180, 320 + 2 * t, 220)] if t in occluded else []
        results.append(tracker.update(render(truth, occluders=box)))
    assert [r.frame for r in results if 2 in r.lost] == [8]
    back = next(r.frame for r in results if r.frame >= 16 and 2 in r.centers())
    assert back <= 21  # the full search at 20 (+ 1 frame)
    assert all(1 in r.centers() for r in results)


def test_a_misread_code_never_moves_an_id_to_another_marker():
    """The detector reads marker 5's code as 3 in one frame: 3's track rejects the jump."""
    truths = [{3: (100.0 + t, 100.0), 5: (400.0 - t, 350.0)} for t in range(10)]

    def misreading(image):
        found = detect_blobs(image)
        if misreading.frame == 6:
            found = [b if b.id != 5 else type(b)(3, b.centroid, b.center, b.ellipse) for b in found]
            found = [b for b in found if not (b.id == 3 and b.centroid[1] < 200)]
        return found

    misreading.frame = 0
    tracker = MarkerTracker(misreading, extent_factor=1.5, full_interval=3)
    for t, truth in enumerate(truths):
        misreading.frame = t
        result = tracker.update(render(truth))
        assert swaps(result, truth, tol=1.0) == 0, (t, result.markers)
    assert tracker.stats.rejected_jumps >= 1


def test_one_new_id_at_two_places_is_not_reported():
    def doubled(image):
        found = detect_blobs(image)
        return found + [
            type(b)(b.id, (b.centroid[0] + 200, b.centroid[1]), b.center, b.ellipse) for b in found
        ]

    tracker = MarkerTracker(doubled, extent_factor=1.5)
    result = tracker.update(render({4: (100.0, 100.0)}))
    assert result.markers == [] and tracker.stats.ambiguous == 1


def test_full_interval_one_searches_every_frame_whole():
    tracker = MarkerTracker(detect_blobs, extent_factor=1.5, full_interval=1)
    results = run(tracker, [orbit([1, 2], t) for t in range(5)])
    assert {r.mode for r in results} == {"full"}


@pytest.mark.parametrize(
    "bad", [{"full_interval": 0}, {"margin_px": -1}, {"speed_gain": float("nan")}]
)
def test_bad_parameters_are_refused(bad):
    with pytest.raises(ValueError):
        MarkerTracker(detect_blobs, extent_factor=1.5, **bad)


def test_the_mosaic_maps_detections_back_exactly():
    truth = {1: (50.3, 60.7), 2: (70.1, 65.2), 3: (400.6, 300.4)}
    frame = render(truth)
    rects = merge_overlapping([(30, 40, 75, 85), (50, 45, 95, 90), (380, 280, 425, 325)])
    assert len(rects) == 2
    mosaic = build_mosaic(frame, rects)
    assert mosaic.image.size < frame.size / 10
    direct = {b.id: b.centroid for b in detect_blobs(frame)}
    for blob in detect_blobs(mosaic.image):
        tile = mosaic.owner_of(blob.centroid)
        assert tile is not None
        assert mosaic.to_frame(tile, blob.centroid) == pytest.approx(direct[blob.id], abs=1e-9)


def test_the_tracker_is_labauto_public_api():
    import labauto

    assert labauto.MarkerTracker is MarkerTracker and "MarkerTracker" in labauto.__all__


def test_the_tracker_reads_frames_as_detect_markers_does():
    """A float 0-1 or a BGRA frame: the same markers as the uint8 grey frame (it found none
    in the float frame and refused the BGRA one)."""
    from labauto.synthetic.marker_scenes import marker_scene

    image, _ = marker_scene(np.random.default_rng(3), 640, 512, n_markers=6, n_rectangles=2,
                            n_artefacts=2, max_tilt_deg=20.0)  # fmt: skip
    expected = MarkerTracker().update(image).centers()
    assert len(expected) == 6
    bgra = np.dstack([image] * 3 + [np.full_like(image, 255)])
    for frame in (image / 255.0, bgra):
        assert MarkerTracker().update(frame).centers().keys() == expected.keys()
