"""Opening thin lines away and putting small colonies back, on drawn masks with known answers."""

from __future__ import annotations

import cv2
import numpy as np

from labauto.vision.plate_opening import open_thin_lines, with_erased_colonies


def test_a_thin_line_is_cut_away_from_the_colony_it_touches() -> None:
    fg = np.zeros((200, 300), np.uint8)
    cv2.circle(fg, (150, 100), 12, 255, -1)  # a colony
    cv2.line(fg, (0, 112), (299, 112), 255, 3)  # the lid's edge, touching it
    n_before, _ = cv2.connectedComponents(fg)
    out = open_thin_lines(fg, 9)
    n_after, _ = cv2.connectedComponents(out)
    assert n_before - 1 == 1 and n_after - 1 == 1  # one body before (joined), one after: the colony
    ys, xs = np.nonzero(out)
    assert abs(xs.mean() - 150) < 1.5 and abs(ys.mean() - 100) < 1.5
    assert out[112, 20] == 0 and out[112, 280] == 0  # the line is gone


def test_the_stub_of_a_thick_stroke_is_dropped_and_a_lone_colony_kept() -> None:
    fg = np.zeros((200, 300), np.uint8)
    cv2.line(fg, (20, 50), (280, 50), 255, 5)  # a pen stroke, thinner than the disc...
    cv2.circle(fg, (150, 50), 5, 255, -1)  # ...with a blot where it is wider (a crossing)
    cv2.circle(fg, (150, 150), 10, 255, -1)
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (9, 9))
    assert cv2.morphologyEx(fg, cv2.MORPH_OPEN, disc)[50, 150] == 255  # a plain opening keeps it
    out = open_thin_lines(fg, 9)
    assert out[150, 150] == 255
    assert not out[:100].any()


def test_small_pigmented_colonies_the_opening_erased_come_back() -> None:
    # 0.6 mm dots at 10 px/mm, narrower than the 0.75 mm opening: yellow ones (a hue: 40
    # levels less blue) are colonies, grey ones (a like share of every channel) in a row
    # 0.8 mm apart are printed dots
    agar = (150, 190, 205)
    img = np.zeros((600, 600, 3), np.uint8)
    img[:] = agar
    fg = np.zeros((600, 600), np.uint8)
    for i in range(5):
        cv2.circle(img, (150 + 60 * i, 200), 3, (110, 185, 210), -1)  # yellow, apart
        cv2.circle(img, (150 + 8 * i, 400), 3, (100, 140, 155), -1)  # grey, in a row
        cv2.circle(fg, (150 + 60 * i, 200), 3, 255, -1)
        cv2.circle(fg, (150 + 8 * i, 400), 3, 255, -1)
    cv2.circle(fg, (300, 300), 20, 255, -1)  # a colony the opening keeps
    opened = open_thin_lines(fg, 7)
    assert cv2.connectedComponents(opened)[0] - 1 == 1
    background = np.empty_like(img)
    background[:] = agar
    kept, dots = with_erased_colonies(fg, opened, img, background, 7)
    assert dots is None  # the yellow ones came back for their hue
    assert cv2.connectedComponents(kept)[0] - 1 == 6
    assert kept[200, 150:391:60].all() and not kept[400, 150:183:8].any()
    np.testing.assert_array_equal(kept[fg == 0], 0)  # nothing beyond the bodies


def test_a_lone_grey_dot_comes_back_and_a_line_s_pieces_do_not() -> None:
    # grey: no hue. A translucent dot 0.6 mm across with nothing round it is a small colony;
    # an opaque one is dust; the pieces of a broken thin line lie along it, and a dot beside
    # a colony is not alone either
    agar = (150, 190, 205)
    img = np.full((300, 400, 3), agar, np.uint8)
    fg = np.zeros((300, 400), np.uint8)
    cv2.circle(fg, (60, 60), 3, 255, -1)  # lone
    for x in range(100, 300, 12):  # a dashed line, dashes 8 px long, 2 px wide
        cv2.line(fg, (x, 150), (x + 7, 150), 255, 2)
    cv2.circle(fg, (300, 250), 20, 255, -1)  # a colony the opening keeps ...
    cv2.circle(fg, (328, 250), 3, 255, -1)  # ... and a dot 5 px from its edge
    img[fg > 0] = (120, 160, 175)  # 17 % less light than the agar
    cv2.circle(fg, (60, 200), 3, 255, -1)
    cv2.circle(img, (60, 200), 3, (60, 60, 60), -1)  # 67 % less: opaque, a speck of dust
    opened = open_thin_lines(fg, 7)
    kept, dots = with_erased_colonies(fg, opened, img, np.full_like(img, agar), 7)
    assert kept[60, 60] == 255 and kept[200, 60] == 0
    assert dots is not None
    assert dots[60, 60] == 255  # the lone dot, and nothing else
    assert cv2.countNonZero(dots) == cv2.countNonZero(fg[50:71, 50:71])
    assert not kept[150, 100:300].any()
    assert kept[250, 328] == 0 and kept[250, 300] == 255


def test_a_pigmented_colony_a_stroke_runs_into_is_no_fragment_of_it() -> None:
    # a grey stroke with a grey blot (a stroke's fragment) and the same stroke through a yellow
    # colony of the same size: both are pieces flanked by the stroke, only the blot is grey
    agar = (150, 190, 205)
    img = np.full((200, 300, 3), agar, np.uint8)
    fg = np.zeros((200, 300), np.uint8)
    for y, colour in ((50, (100, 140, 155)), (150, (110, 185, 210))):
        cv2.line(fg, (20, y), (280, y), 255, 5)
        cv2.line(img, (20, y), (280, y), (100, 140, 155), 5)
        cv2.circle(fg, (150, y), 5, 255, -1)
        cv2.circle(img, (150, y), 5, colour, -1)
    background = np.full_like(img, agar)
    blind = open_thin_lines(fg, 9)
    assert blind[50, 150] == 0 and blind[150, 150] == 0  # without colour: both fragments
    seen = open_thin_lines(fg, 9, img, background)
    assert seen[50, 150] == 0 and seen[150, 150] == 255
    assert cv2.connectedComponents(seen)[0] - 1 == 1
