"""The pieces of the marker pipeline that only speed changed: the same results as plain code."""

from __future__ import annotations

import numpy as np

from labauto.synthetic.marker_scenes import tilted_plane
from labauto.synthetic.markers import draw_marker, finish, homography_map
from labauto.vision import markers as mk
from labauto.vision.detector import extract_contours
from labauto.vision.marker_codes import RING_OUTER
from labauto.vision.marker_edges import refine_circles


def test_sector_means_of_every_phase_match_the_rolled_reference() -> None:
    level = np.random.default_rng(0).random((7, mk.N_BITS * mk.SAMPLES_PER_BIT))
    s = mk.SAMPLES_PER_BIT
    reference = np.stack(
        [
            np.roll(level, -p, axis=1).reshape(7, mk.N_BITS, s)[:, :, 1:-1].mean(axis=2)
            for p in range(s)
        ],
        axis=1,
    )
    assert np.allclose(mk._sector_means(level), reference, atol=1e-12)


def _marker_and_read(tilt: float = 35.0):
    img = np.full((220, 240), 200.0)
    hom = tilted_plane((118.4, 109.7), 14.0, tilt, 25.0, 40.0, focal_px=900.0)
    centre = draw_marker(img, 41, (0.0, 0.0), 1.0, to_image=homography_map(hom), ink=40.0)
    image = finish(img, blur_sigma=1.0, noise_sigma=0.0, rng=np.random.default_rng(1))
    params = mk.MarkerParams()
    contours = extract_contours(image, params.detector_params())
    _centroids, _index, rows = mk._candidates(image, contours, params)
    ids, _score, _bit0, bits, start = mk._read_codes(image, rows, params)
    (j,) = np.flatnonzero(ids == 41)
    return image, np.array(centre), rows[[j]], bits[[j]], start[[j]], params


def test_outer_ring_edge_measured_and_inner_one_left_out() -> None:
    image, centre, rows, bits, start, params = _marker_and_read()
    circles, centres = refine_circles(
        image.astype(np.float32), rows, bits, start, params.min_contrast
    )
    assert np.isfinite(circles[0, 0, 0]) and np.isfinite(circles[0, 2, 0])
    assert not np.isfinite(circles[0, 1, 0])  # not needed: the outer edge has a fit
    assert np.hypot(*(centres[0] - centre)) < 0.02


def test_inner_ring_edge_stands_in_where_the_outer_one_is_gone() -> None:
    image, centre, rows, bits, start, params = _marker_and_read()
    # ink over the ring's outer edge all round: no step there, the inner edge must serve
    ys, xs = np.mgrid[: image.shape[0], : image.shape[1]]
    cx, cy, a = rows[0, 0], rows[0, 1], rows[0, 2]
    r = np.hypot(xs - cx, ys - cy)
    painted = image.astype(np.float32)
    painted[(r > (RING_OUTER - 0.6) * a) & (r < (RING_OUTER + 0.8) * a)] = 40.0
    circles, centres = refine_circles(painted, rows, bits, start, params.min_contrast)
    assert not np.isfinite(circles[0, 2, 0])
    assert np.isfinite(circles[0, 0, 0]) and np.isfinite(circles[0, 1, 0])
    assert np.hypot(*(centres[0] - centre)) < 0.1
