"""detect_markers on renders with known geometry: ids, false ids, centre accuracy, bias gain."""

from __future__ import annotations

import numpy as np
import pytest

import labauto
from labauto.synthetic import shapes
from labauto.synthetic.marker_scenes import tilted_plane
from labauto.synthetic.markers import draw_marker, fill_polygons, finish, homography_map
from labauto.vision.markers import detect_markers, find_markers


def _errors(markers, truth) -> np.ndarray:
    where = {t.id: np.array(t.center) for t in truth}
    return np.array([np.hypot(*(np.array(m.center) - where[m.id])) for m in markers])


def test_all_ids_and_no_false_ids_among_rectangles_and_artefacts(noisy_scenes) -> None:
    for image, truth in noisy_scenes:
        found = detect_markers(image)
        assert sorted(m.id for m in found) == sorted(t.id for t in truth)


def test_centres_within_0_1_px_with_noise_and_blur(noisy_scenes) -> None:
    for image, truth in noisy_scenes:
        found = detect_markers(image)
        assert all(m.bias_corrected for m in found)
        assert _errors(found, truth).max() < 0.1


def test_centres_within_0_02_px_noise_free(clean_scene) -> None:
    image, truth = clean_scene
    found = detect_markers(image)
    assert len(found) == len(truth)
    assert _errors(found, truth).max() < 0.02


def _one_marker(tilt: float, radius: float = 16.0, noise: float = 0.0, seed: int = 0):
    img = np.full((200, 240), 200.0)
    hom = tilted_plane((121.3, 98.6), radius, tilt, 20.0, 35.0, focal_px=800.0)
    centre = draw_marker(img, 77, (0.0, 0.0), 1.0, to_image=homography_map(hom), ink=40.0)
    rng = np.random.default_rng(seed)
    return finish(img, blur_sigma=1.0, noise_sigma=noise, rng=rng), np.array(centre)


def test_bias_correction_removes_the_perspective_shift() -> None:
    image, centre = _one_marker(tilt=60.0)
    (corrected,) = detect_markers(image)
    (plain,) = detect_markers(image, correct_bias=False)
    ellipse_error = np.hypot(*(np.array(plain.center) - centre))
    corrected_error = np.hypot(*(np.array(corrected.center) - centre))
    assert corrected.id == plain.id == 77
    assert corrected.bias_corrected and not plain.bias_corrected
    assert ellipse_error > 0.15  # the ellipse's centre is not the circle's centre
    assert corrected_error < 0.02
    assert corrected_error < ellipse_error / 10


def test_light_on_dark_markers_read_alike() -> None:
    image, centre = _one_marker(tilt=30.0, noise=2.0)
    (m,) = detect_markers(255 - image)
    assert m.id == 77 and np.hypot(*(np.array(m.center) - centre)) < 0.1


def test_a_window_gives_the_same_marker_offset() -> None:
    image, _centre = _one_marker(tilt=40.0)
    (full,) = detect_markers(image)
    x0, y0 = 31, 17
    (part,) = detect_markers(image[y0 : y0 + 170, x0 : x0 + 190])
    moved = part.shifted(x0, y0)
    assert part.id == full.id
    assert np.allclose(moved.center, full.center, atol=1e-6)
    assert np.allclose(moved.ellipse.center, full.ellipse.center, atol=1e-6)


def test_a_marker_whose_ring_leaves_the_image_gets_no_id() -> None:
    image, centre = _one_marker(tilt=0.0)
    cut = image[:, : int(centre[0]) + 30]  # the centre circle is inside, the ring is cut
    assert detect_markers(cut) == []


def test_rectangles_dots_and_uncoded_rings_get_no_id() -> None:
    img = np.full((300, 400), 210.0)
    things = [
        shapes.rectangle((60, 60), 40, 30, 20),
        shapes.ellipse((160, 70), (14, 14), 0),  # a plain dot: DES, but no ring
        shapes.ellipse((300, 80), (18, 11), 30),
        shapes.star((90, 200), 25, 12, 5, 0),
    ]
    fill_polygons(img, [t.vertices for t in things], 30.0)
    # a dot inside a full ring: the ring reads as all ink, an odd/invalid word
    fill_polygons(img, [shapes.ellipse((260, 210), (45, 45), 0).vertices], 30.0)
    fill_polygons(img, [shapes.ellipse((260, 210), (30, 30), 0).vertices], 210.0)
    fill_polygons(img, [shapes.ellipse((260, 210), (15, 15), 0).vertices], 30.0)
    image = finish(img, blur_sigma=1.0, noise_sigma=2.0, rng=np.random.default_rng(3))
    assert detect_markers(image) == []


def test_json_form_and_the_public_api(tmp_path) -> None:
    image, _centre = _one_marker(tilt=20.0)
    result = find_markers(image)
    doc = result.to_dict()
    (entry,) = doc["markers"]
    assert entry["id"] == 77
    assert set(entry) >= {"id", "center", "ellipse", "score"}
    assert set(entry["ellipse"]) == {"center", "axes", "angle"}
    assert 0 < entry["score"] <= 1 and doc["timing_ms"] > 0
    path = tmp_path / "m.png"
    import cv2

    cv2.imwrite(str(path), image)
    (m,) = labauto.detect_markers(str(path))
    assert m.to_dict() == entry


def test_unknown_option_is_named() -> None:
    with pytest.raises(ValueError, match="nosuch"):
        detect_markers(np.zeros((50, 50), np.uint8), nosuch=1)


def test_a_marker_read_at_the_border_is_kept_whether_or_not_its_bias_is_corrected() -> None:
    # the code ring's reach (3 radii + 1 px) within a tenth of a pixel of the image's edge: the
    # read's fit finds the ring inside; the re-measured circle, a little larger, must not then
    # drop the marker (correct_bias=False reports it)
    read = 0
    for x in np.arange(127.9, 128.35, 0.05):
        img = np.full((120, 160), 200.0)
        draw_marker(img, 41, (float(x), 60.0), 10.0, ink=40.0)
        image = finish(img, blur_sigma=1.0, noise_sigma=0.0, rng=np.random.default_rng(1))
        plain = [m.id for m in detect_markers(image, correct_bias=False)]
        assert [m.id for m in detect_markers(image)] == plain, x
        read += plain == [41]
    assert read >= 8  # of 9 positions: the marker is read at all (the last is cut by the edge)


def test_ring_ellipses_hold_only_the_ring_fit_the_centre_came_from(monkeypatch) -> None:
    from labauto.vision import markers as mk

    image, _centre = _one_marker(tilt=30.0)
    real = mk.refine_circles

    def with_inner_too(*args, **kwargs):
        # as when the coarse first look missed the outer edge (so the inner one was measured
        # too) and the next pass found it: both ring edges have fits, the centre uses the outer
        circles, centres = real(*args, **kwargs)
        circles[:, 1] = circles[:, 0]
        circles[:, 1, 2:4] *= 2.0
        return circles, centres

    monkeypatch.setattr(mk, "refine_circles", with_inner_too)
    (m,) = detect_markers(image)
    assert m.bias_corrected
    (ring,) = m.ring_ellipses
    assert ring.axes[0] > 2.5 * m.ellipse.axes[0]  # the outer edge
