"""Board files: printable boards (SVG, PDF, PNG) with their YAML description, and reading it.

``write_board(board, "board.pdf")`` writes the printable page and, beside it, ``board.yaml``
(:meth:`CodedBoard.to_dict` / :meth:`GridBoard.to_dict`). SVG and PDF are vector drawings at
true size (print them at 100 %, "actual size"); arcs are cubic Bezier curves of at most 30
degrees (shape error below 1e-6 of the radius). PNG is rendered at ``dpi`` by exact area
coverage (:mod:`labauto.synthetic.markers`), the page's top-left corner at the top-left pixel's
outer corner. :func:`read_board` loads a description with errors that name the file and field.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import yaml

from labauto.errors import LabautoError
from labauto.safeyaml import read_yaml_file
from labauto.vision.boards import Board, BoardError, CodedBoard, GridBoard, board_from_dict
from labauto.vision.marker_codes import N_BITS, RING_INNER, RING_OUTER, code_bits

FORMATS = (".svg", ".pdf", ".png")
PT_PER_MM = 72.0 / 25.4


class BoardFileError(LabautoError):
    """A board file cannot be read or written."""


def read_board(path: str | Path) -> Board:
    """Load and validate a board description (YAML)."""
    try:
        doc = read_yaml_file(path, what="board description")
    except FileNotFoundError:
        raise BoardFileError(f"{path}: no such board description") from None
    except yaml.YAMLError as exc:
        raise BoardFileError(f"{path}: not valid YAML ({' '.join(str(exc).split())})") from None
    except ValueError as exc:  # refused by the YAML guards
        raise BoardFileError(str(exc)) from None
    try:
        return board_from_dict(doc)
    except BoardError as exc:
        raise BoardFileError(f"{path}: {exc}") from None


# ------------------------------------------------------------------------------ shapes


def _paths(board: Board) -> list[list[tuple]]:
    """The board's ink as closed paths of ``("circle", cx, cy, r)`` or ``("sector", ...)``."""
    if isinstance(board, CodedBoard):
        shapes: list[list[tuple]] = []
        r = board.marker_radius_mm
        step = 2 * math.pi / N_BITS
        for marker_id, (cx, cy) in zip(board.ids.tolist(), board.centers_mm.tolist(), strict=True):
            shapes.append([("circle", cx, cy, r)])
            bits = code_bits(marker_id)
            start = int(np.flatnonzero(bits == 0)[0])
            k = 0
            while k < N_BITS:
                i = (start + k) % N_BITS
                run = 0
                while run < N_BITS - k and bits[(i + run) % N_BITS]:
                    run += 1
                if run:
                    t0, t1 = i * step, (i + run) * step
                    shapes.append([("sector", cx, cy, RING_INNER * r, RING_OUTER * r, t0, t1)])
                k += max(run, 1)
        return shapes
    out = []
    for x, y, _ in board.object_points().tolist():
        cx, cy = x + board.spacing_mm, y + board.spacing_mm
        outer = board.diameter_mm / 2
        if board.type == "circle-grid":
            out.append([("circle", cx, cy, outer)])
        else:
            out.append([("circle", cx, cy, outer), ("circle", cx, cy, board.inner_diameter_mm / 2)])
    return out


def _page(board: Board) -> tuple[float, float]:
    if isinstance(board, CodedBoard):
        return board.width_mm, board.height_mm
    return board.size_mm


def _colours(board: Board) -> tuple[str, str]:
    return ("#000000", "#ffffff") if board.polarity == "dark-on-light" else ("#ffffff", "#000000")


def _bezier_arc(cx: float, cy: float, r: float, t0: float, t1: float) -> list[tuple[float, ...]]:
    """Cubic pieces ``(x1, y1, x2, y2, x3, y3)`` of the arc from angle t0 to t1 (radians)."""
    n = max(1, math.ceil(abs(t1 - t0) / math.radians(30)))
    out = []
    for k in range(n):
        a, b = t0 + (t1 - t0) * k / n, t0 + (t1 - t0) * (k + 1) / n
        h = 4.0 / 3.0 * math.tan((b - a) / 4.0) * r
        out.append(
            (
                cx + r * math.cos(a) - h * math.sin(a),
                cy + r * math.sin(a) + h * math.cos(a),
                cx + r * math.cos(b) + h * math.sin(b),
                cy + r * math.sin(b) - h * math.cos(b),
                cx + r * math.cos(b),
                cy + r * math.sin(b),
            )
        )
    return out


def _outline(item: tuple) -> tuple[tuple[float, float], list[tuple[float, ...]], list]:
    """Start point and cubic pieces of a closed outline (a sector: outer arc, inner arc back)."""
    if item[0] == "circle":
        _, cx, cy, r = item
        return (cx + r, cy), _bezier_arc(cx, cy, r, 0.0, 2 * math.pi), []
    _, cx, cy, r_in, r_out, t0, t1 = item
    outer = _bezier_arc(cx, cy, r_out, t0, t1)
    inner = _bezier_arc(cx, cy, r_in, t1, t0)
    line_to = (cx + r_in * math.cos(t1), cy + r_in * math.sin(t1))
    return (cx + r_out * math.cos(t0), cy + r_out * math.sin(t0)), outer, [line_to, inner]


def _svg(board: Board) -> str:
    width, height = _page(board)
    ink, paper = _colours(board)
    parts = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width:.4f}mm" height="{height:.4f}mm" '
        f'viewBox="0 0 {width:.4f} {height:.4f}">',
        f'<rect x="0" y="0" width="{width:.4f}" height="{height:.4f}" fill="{paper}"/>',
    ]
    for shape in _paths(board):
        d = []
        for item in shape:
            (x0, y0), first, rest = _outline(item)
            d.append(f"M{x0:.5f} {y0:.5f}")
            d += [("C" + " ".join(f"{v:.5f}" for v in c)) for c in first]
            if rest:
                (lx, ly), second = rest
                d.append(f"L{lx:.5f} {ly:.5f}")
                d += [("C" + " ".join(f"{v:.5f}" for v in c)) for c in second]
            d.append("Z")
        parts.append(f'<path fill="{ink}" fill-rule="evenodd" d="{" ".join(d)}"/>')
    parts.append("</svg>")
    return "\n".join(parts) + "\n"


def _pdf(board: Board) -> bytes:
    width, height = _page(board)
    ink, paper = _colours(board)
    grey = {"#000000": "0 g", "#ffffff": "1 g"}
    ops = [f"{PT_PER_MM:.6f} 0 0 {-PT_PER_MM:.6f} 0 {height * PT_PER_MM:.4f} cm"]
    ops.append(f"{grey[paper]} 0 0 {width:.4f} {height:.4f} re f")
    ops.append(grey[ink])
    for shape in _paths(board):
        for item in shape:
            (x0, y0), first, rest = _outline(item)
            ops.append(f"{x0:.5f} {y0:.5f} m")
            ops += [" ".join(f"{v:.5f}" for v in c) + " c" for c in first]
            if rest:
                (lx, ly), second = rest
                ops.append(f"{lx:.5f} {ly:.5f} l")
                ops += [" ".join(f"{v:.5f}" for v in c) + " c" for c in second]
            ops.append("h")
        ops.append("f*")  # even-odd: a ring's inner circle is a hole
    content = "\n".join(ops).encode("ascii")
    objects = [
        b"<< /Type /Catalog /Pages 2 0 R >>",
        b"<< /Type /Pages /Kids [3 0 R] /Count 1 >>",
        (
            f"<< /Type /Page /Parent 2 0 R /MediaBox [0 0 {width * PT_PER_MM:.4f} "
            f"{height * PT_PER_MM:.4f}] /Contents 4 0 R /Resources << >> >>"
        ).encode("ascii"),
        b"<< /Length " + str(len(content)).encode() + b" >>\nstream\n" + content + b"\nendstream",
    ]
    out = bytearray(b"%PDF-1.4\n")
    offsets = []
    for k, body in enumerate(objects, start=1):
        offsets.append(len(out))
        out += f"{k} 0 obj\n".encode() + body + b"\nendobj\n"
    xref = len(out)
    out += f"xref\n0 {len(objects) + 1}\n0000000000 65535 f \n".encode()
    out += b"".join(f"{o:010d} 00000 n \n".encode() for o in offsets)
    out += (
        f"trailer\n<< /Size {len(objects) + 1} /Root 1 0 R >>\nstartxref\n{xref}\n%%EOF\n".encode()
    )
    return bytes(out)


def render_board(board: Board, px_per_mm: float) -> np.ndarray:
    """The board as a grey uint8 image, ``px_per_mm`` pixels per millimetre."""
    from labauto.synthetic.board_views import draw_board
    from labauto.synthetic.markers import finish

    width, height = _page(board)
    paper = 255.0 if board.polarity == "dark-on-light" else 0.0
    img = np.full((math.ceil(height * px_per_mm), math.ceil(width * px_per_mm)), paper)

    def to_image(points: np.ndarray) -> np.ndarray:
        return np.asarray(points, np.float64) * px_per_mm - 0.5

    draw_board(img, board, to_image, paper=255.0, ink=0.0, page=False)
    return finish(img)


def write_board(board: Board, path: str | Path, dpi: float = 300.0) -> tuple[Path, Path]:
    """Write the printable board (by the suffix: .svg, .pdf or .png) and ``STEM.yaml``.

    Returns
    -------
    (board file, description file)
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in FORMATS:
        raise BoardFileError(
            f"{path}: cannot write a board as {suffix or 'no suffix'!r} (use {', '.join(FORMATS)})"
        )
    if not dpi > 0:
        raise BoardFileError(f"--dpi must be > 0, got {dpi}")
    description = path.with_suffix(".yaml")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        if suffix == ".svg":
            path.write_text(_svg(board), encoding="utf-8")
        elif suffix == ".pdf":
            path.write_bytes(_pdf(board))
        else:
            from labauto.imageio import write_image

            write_image(path, render_board(board, dpi / 25.4))
        doc = board.to_dict()
        header = f"# {path.name}: print at 100 % (actual size); positions in mm from the top-left\n"
        description.write_text(header + yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    except OSError as exc:
        raise BoardFileError(f"{exc.filename or path}: cannot write ({exc.strerror})") from None
    return path, description


__all__ = [
    "BoardFileError",
    "GridBoard",
    "read_board",
    "render_board",
    "write_board",
]
