"""Benchmark: storing the detections of one plate image, bulk versus row by row.

Every variant writes to a fresh SQLite file migrated by Alembic, with labauto's settings (WAL,
synchronous=FULL, foreign keys on). The baseline is the naive ORM loop (``session.add`` and
``commit`` per row), timed on fewer rows and extrapolated linearly to the full count; the
others store all rows in one transaction. A second table times the single writes the
orchestrator makes all through a run (one commit each).

Run::

    .venv/bin/python benchmarks/bench_store.py [--rows 10000] [--naive-rows 300] [--repeat 3]
"""

from __future__ import annotations

import argparse
import random
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from sqlalchemy import insert
from sqlalchemy.orm import Session

from labauto.store import Detection, Store


def detection_rows(n: int, seed: int = 1) -> list[dict]:
    """``n`` complete detection rows with varied values."""
    rng = random.Random(seed)
    rows = []
    for i in range(n):
        x, y = rng.uniform(0, 2000), rng.uniform(0, 1500)
        a = rng.uniform(3, 30)
        rows.append(
            {
                "object_index": i,
                "method": "canny",
                "centroid_x": x,
                "centroid_y": y,
                "n_points": rng.randint(12, 400),
                "closed": rng.random() < 0.9,
                "d_alpha_median": rng.uniform(0, 30),
                "d_alpha_mean": rng.uniform(0, 30),
                "centroid_inside": True,
                "is_des": rng.random() < 0.6,
                "shape": "ellipse",
                "ellipse_cx": x,
                "ellipse_cy": y,
                "ellipse_a": a,
                "ellipse_b": a * rng.uniform(0.5, 1.0),
                "ellipse_angle": rng.uniform(0, 180),
                "area_px": 3.14159 * a * a,
            }
        )
    return rows


class Scene:
    """A fresh migrated database with one run, plate and image."""

    def __init__(self, folder: Path, name: str) -> None:
        self.store = Store.open(f"sqlite:///{folder / name}.db")
        self.run_id = self.store.create_run("bench")
        plate_id = self.store.add_plate("bench-plate").id
        self.image_id = self.store.add_image(
            plate_id, "bench.png", 2000, 1500, "e" * 64, run_id=self.run_id
        ).id

    def rows(self, rows: list[dict]) -> list[dict]:
        return [{**row, "run_id": self.run_id, "image_id": self.image_id} for row in rows]


def naive_orm_loop(scene: Scene, rows: list[dict]) -> None:
    """Baseline: one ORM object and one commit per row."""
    for row in scene.rows(rows):
        with Session(scene.store.engine) as session:
            session.add(Detection(**row))
            session.commit()


def orm_bulk_insert(scene: Scene, rows: list[dict]) -> None:
    """``session.execute(insert(Detection), rows)``: ORM bulk INSERT, one transaction, no ids."""
    prepared = scene.rows(rows)
    with Session(scene.store.engine) as session, session.begin():
        session.execute(insert(Detection), prepared)


def orm_bulk_returning_ids(scene: Scene, rows: list[dict]) -> None:
    """ORM bulk INSERT ... RETURNING id in row order (the non-SQLite path of the Store)."""
    prepared = scene.rows(rows)
    statement = insert(Detection).returning(Detection.id, sort_by_parameter_order=True)
    with Session(scene.store.engine) as session, session.begin():
        ids = list(session.scalars(statement, prepared))
    assert len(ids) == len(rows)


def store_add_detections(scene: Scene, rows: list[dict]) -> None:
    """``Store.add_detections``: row checks, one Core executemany, ids in row order."""
    ids = scene.store.add_detections(scene.run_id, scene.image_id, rows)
    assert len(ids) == len(rows)


def timed(
    folder: Path, name: str, fn: Callable[[Scene, list[dict]], None], rows: list[dict]
) -> float:
    scene = Scene(folder, name)
    try:
        start = time.perf_counter()
        fn(scene, rows)
        return time.perf_counter() - start
    finally:
        scene.store.close()


def single_writes(folder: Path, n: int) -> list[tuple[str, float]]:
    """Seconds per call of the small writes made throughout a run."""
    scene = Scene(folder, "single")
    store = scene.store
    try:
        colony_ids = store.add_colonies(
            scene.run_id,
            scene.image_id,
            [
                {"colony_index": i, "klass": "authentic", "centroid_x": 1.0, "centroid_y": 1.0}
                for i in range(n)
            ],
        )
        pick_ids = store.plan_picks(scene.run_id, [{"colony_id": c} for c in colony_ids])
        results = []
        start = time.perf_counter()
        for i in range(n):
            store.record_event(scene.run_id, "robot.tx", f"G0 X{i} Y{i}", source="robot")
        results.append(("record_event", (time.perf_counter() - start) / n))
        start = time.perf_counter()
        for pick_id in pick_ids:
            store.set_pick_state(pick_id, "moving", deck_x_mm=1.0, deck_y_mm=2.0)
        results.append(("set_pick_state (+ audit event)", (time.perf_counter() - start) / n))
        start = time.perf_counter()
        for _ in range(n):
            store.picks_in_flight(scene.run_id)
        results.append(
            (f"picks_in_flight ({n} in flight, read)", (time.perf_counter() - start) / n)
        )
        return results
    finally:
        store.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=10_000, help="detections per image")
    parser.add_argument("--naive-rows", type=int, default=300, help="rows for the naive loop")
    parser.add_argument("--repeat", type=int, default=3, help="runs per variant (median shown)")
    parser.add_argument("--single", type=int, default=200, help="calls per single-write timing")
    args = parser.parse_args()

    rows = detection_rows(args.rows)
    naive_rows = rows[: args.naive_rows]
    variants = [
        ("naive ORM add+commit per row", naive_orm_loop, naive_rows),
        ("ORM bulk insert(Detection), no ids", orm_bulk_insert, rows),
        ("ORM bulk + RETURNING ids (ordered)", orm_bulk_returning_ids, rows),
        ("Store.add_detections (checks + ids)", store_add_detections, rows),
    ]
    with tempfile.TemporaryDirectory(prefix="labauto-bench-") as tmp:
        folder = Path(tmp)
        measured = []
        for k, (label, fn, subset) in enumerate(variants):
            times = [timed(folder, f"v{k}r{r}", fn, subset) for r in range(args.repeat)]
            per_row = statistics.median(times) / len(subset)
            measured.append((label, len(subset), per_row))
        singles = single_writes(folder, args.single)

    baseline = measured[0][2]
    print(f"\nStoring {args.rows} detections of one image (SQLite file, WAL, synchronous=FULL)")
    print(f"median of {args.repeat} runs; the naive loop ran {args.naive_rows} rows, extrapolated")
    header = f"{'method':<38} {'rows run':>8} {'s / ' + str(args.rows) + ' rows':>14}"
    header += f" {'rows/s':>10} {'speed-up':>9}"
    print(header)
    print("-" * len(header))
    for label, n, per_row in measured:
        print(
            f"{label:<38} {n:>8} {per_row * args.rows:>14.3f} {1 / per_row:>10.0f}"
            f" {baseline / per_row:>8.0f}x"
        )

    print(f"\nSingle writes during a run (one commit each, mean of {args.single} calls)")
    print(f"{'call':<38} {'ms / call':>10}")
    print("-" * 49)
    for label, seconds in singles:
        print(f"{label:<38} {seconds * 1000:>10.3f}")


if __name__ == "__main__":
    main()
