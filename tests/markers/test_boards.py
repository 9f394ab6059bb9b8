"""``labauto markers board``: printable boards at true size and their YAML descriptions."""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import yaml

from labauto.calibration.boards_io import BoardFileError, read_board
from labauto.cli.main import main
from labauto.vision import board_points
from labauto.vision.board_points import ring_centres
from labauto.vision.boards import BoardError, board_from_dict
from labauto.vision.ellipse import Ellipse
from labauto.vision.marker_codes import RING_INNER, RING_OUTER


def _board(tmp_path, capsys, suffix: str, *extra: str):
    out = tmp_path / f"b.{suffix}"
    code = main(["markers", "board", "--rows", "2", "--cols", "3", "--pitch-mm", "25",
                 "--first-id", "40", "--out", str(out), *extra])  # fmt: skip
    _, err = capsys.readouterr()
    assert code == 0, err
    return out, read_board(tmp_path / "b.yaml")


def test_yaml_describes_ids_centres_and_sizes(tmp_path, capsys) -> None:
    _, board = _board(tmp_path, capsys, "svg")
    doc = yaml.safe_load((tmp_path / "b.yaml").read_text())
    assert doc["type"] == "coded" and doc["width_mm"] == 100 and doc["height_mm"] == 75
    assert [m["id"] for m in doc["markers"]] == list(range(40, 46))
    assert doc["markers"][4]["center_mm"] == [50.0, 50.0]  # x right, y down, from top-left
    assert board.marker_radius_mm == pytest.approx(doc["marker_radius_mm"])


def test_svg_is_true_size_and_its_circles_have_the_marker_radii(tmp_path, capsys) -> None:
    out, board = _board(tmp_path, capsys, "svg")
    root = ET.parse(out).getroot()
    assert root.get("width") == "100.0000mm" and root.get("height") == "75.0000mm"
    paths = [p.get("d") for p in root.iter("{http://www.w3.org/2000/svg}path")]
    r = board.marker_radius_mm
    # first marker: centre circle then its sectors; every curve end lies on one of the radii
    centre = board.centers_mm[0]
    radii = set()
    for d in paths[:6]:
        nums = np.array([float(v) for v in re.findall(r"-?\d+\.\d+", d)]).reshape(-1, 2)
        dist = np.hypot(*(nums - centre).T)
        on_curve = dist[np.isclose(dist, r, atol=1e-4) | np.isclose(dist, RING_INNER * r, atol=1e-4)
                        | np.isclose(dist, RING_OUTER * r, atol=1e-4)]  # fmt: skip
        radii.update(np.round(on_curve / r, 3).tolist())
    assert {1.0, RING_INNER, RING_OUTER} <= radii


def test_pdf_has_a_valid_xref_and_the_page_size(tmp_path, capsys) -> None:
    out, _ = _board(tmp_path, capsys, "pdf")
    data = out.read_bytes()
    assert data.startswith(b"%PDF-1.4")
    start = int(data.rsplit(b"startxref\n", 1)[1].split()[0])
    table = data[start:].split(b"\n")
    offsets = [int(line.split()[0]) for line in table[3:7]]
    for k, offset in enumerate(offsets, start=1):
        assert data[offset:].startswith(f"{k} 0 obj".encode())
    box = re.search(rb"/MediaBox \[0 0 ([\d.]+) ([\d.]+)\]", data)
    assert float(box.group(1)) == pytest.approx(100 * 72 / 25.4, abs=1e-3)
    assert float(box.group(2)) == pytest.approx(75 * 72 / 25.4, abs=1e-3)


def test_png_board_detects_every_id_where_the_yaml_says(tmp_path, capsys) -> None:
    out, board = _board(tmp_path, capsys, "png", "--dpi", "200")
    code = main(["markers", "detect", str(out), "--json"])
    doc = json.loads(capsys.readouterr()[0])
    assert code == 0
    assert [m["id"] for m in doc["markers"]] == board.ids.tolist()
    px_per_mm = 200 / 25.4
    expected = board.centers_mm * px_per_mm - 0.5
    found = np.array([m["center"] for m in doc["markers"]])
    assert np.abs(found - expected).max() < 0.02


def test_light_on_dark_png(tmp_path, capsys) -> None:
    out, board = _board(tmp_path, capsys, "png", "--dpi", "150", "--polarity", "light-on-dark")
    main(["markers", "detect", str(out), "--json"])
    doc = json.loads(capsys.readouterr()[0])
    assert [m["id"] for m in doc["markers"]] == board.ids.tolist()


def test_bad_board_options_are_one_line(tmp_path, capsys) -> None:
    code = main(["markers", "board", "--rows", "20", "--cols", "20", "--pitch-mm", "10",
                 "--out", str(tmp_path / "x.svg")])  # fmt: skip
    err = capsys.readouterr()[1]
    assert code == 1 and err.count("\n") == 1 and "ids 0..399 do not exist" in err
    code = main(["markers", "board", "--rows", "2", "--cols", "2", "--pitch-mm", "10",
                 "--out", str(tmp_path / "x.gif")])  # fmt: skip
    err = capsys.readouterr()[1]
    assert code == 1 and "cannot write a board as '.gif'" in err


@pytest.mark.parametrize(
    ("doc", "message"),
    [
        ({"type": "chess"}, "type: expected coded, circle-grid or ring-grid"),
        ({"type": "circle-grid", "cols": 4, "rows": 3}, "spacing_mm: missing"),
        ({"type": "circle-grid", "cols": 0, "rows": 3, "spacing_mm": 5}, "cols: expected"),
        ({"type": "ring-grid", "cols": 4, "rows": 3, "spacing_mm": 10, "outer_diameter_mm": 6,
          "inner_diameter_mm": 7}, "inner_diameter_mm: must be below"),
        ({"type": "circle-grid", "cols": 4, "rows": 3, "spacing_mm": 10, "polarity": "grey"},
         "polarity: expected one of"),
        ({"type": "coded", "marker_radius_mm": 2, "markers": [{"id": 1, "center_mm": [0, 0]},
          {"id": 1, "center_mm": [9, 0]}]}, r"id\(s\) \[1\] appear more than once"),
    ],
)  # fmt: skip
def test_board_descriptions_are_validated(doc, message) -> None:
    with pytest.raises(BoardError, match=message):
        board_from_dict(doc)


def test_grid_object_points_follow_opencv_order() -> None:
    sym = board_from_dict({"type": "circle-grid", "cols": 4, "rows": 3, "spacing_mm": 10})
    pts = sym.object_points()
    assert pts.shape == (12, 3) and pts[1].tolist() == [10, 0, 0] and pts[4].tolist() == [0, 10, 0]
    asym = board_from_dict(
        {"type": "circle-grid", "cols": 4, "rows": 3, "spacing_mm": 10, "asymmetric": True}
    )
    a = asym.object_points()
    assert a[1].tolist() == [20, 0, 0] and a[4].tolist() == [10, 10, 0]


def test_missing_board_file_is_named(tmp_path) -> None:
    with pytest.raises(BoardFileError, match=r"nosuch\.yaml: no such board description"):
        read_board(tmp_path / "nosuch.yaml")


def test_rings_pair_past_a_second_contour_of_the_inner_edge(monkeypatch) -> None:
    inner = Ellipse((100.0, 80.0), (10.0, 9.0), 20.0)
    duplicate = Ellipse((100.1, 80.0), (10.6, 9.5), 20.0)  # the same edge traced twice
    # of the right size, but the pair gives no centre: pairing must go on to the next one
    no_centre = Ellipse((100.4, 80.0), (19.5, 17.6), 20.0)
    outer = Ellipse((100.0, 80.0), (20.0, 18.0), 20.0)
    lone = Ellipse((300.0, 80.0), (10.0, 9.0), 0.0)  # no ring round it
    real = board_points.projected_center
    monkeypatch.setattr(
        board_points,
        "projected_center",
        lambda pair: None if no_centre in pair else real(pair),
    )
    centres = ring_centres([outer, no_centre, duplicate, lone, inner], ratio=0.5)
    assert centres.shape == (1, 2)
    np.testing.assert_allclose(centres[0], (100.0, 80.0), atol=1e-6)
