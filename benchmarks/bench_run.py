"""Software overhead per pick: the orchestrated pick against the bare driver cycle.

Both use the same simulated devices at (nearly) full speed: the GRBL gantry behind a
pseudo-terminal with motion 10,000x faster than real, and the Modbus analyzer on 127.0.0.1 with
an analysis time of zero. The baseline is the bare cycle a script would run with the drivers
(``robot.pick``, ``robot.deposit``, ``analyzer.analyze``); the orchestrated pick adds the
stored pick states, the audit log with every device exchange, the analyzer result, the event
hooks and the annotated output. The difference is labauto's software overhead per pick.

Run: ``.venv/bin/python benchmarks/bench_run.py [--picks 12]``
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from labauto.config import parse_config
from labauto.drivers.camera import sample_plates_dir
from labauto.orchestrator.session import build_workcell, open_run
from labauto.plugin_manager import load_plugins
from labauto.store import Store

FAST = {
    "robot": {"simulator": {"speed_factor": 10000.0}, "dwell_s": 0.0},
    "analyzer": {"simulator": {"speed_factor": 10000.0, "analysis_seconds": 0.0}},
}


def make_config(folder: Path, picks: int):
    return parse_config(
        {
            "name": "bench",
            "database": {"url": f"sqlite:///{folder / 'bench.db'}"},
            "camera": {"path": str(sample_plates_dir()), "pattern": "plate_101*.png"},
            "picking": {"max_picks": picks, "min_neighbor_distance_px": 0.0},
            "output": {"dir": str(folder / "out")},
            **FAST,
        },
        "<bench>",
        environ={},
    )


def bare_cycles(config, picks: int) -> list[float]:
    """Milliseconds per bare driver cycle: pick, deposit, analyze."""
    workcell = build_workcell(config, load_plugins())
    robot, analyzer, cfg = workcell.robot, workcell.analyzer, config.robot
    try:
        robot.connect()
        robot.home()
        analyzer.connect()
        times = []
        for index in range(picks):
            start = time.perf_counter()
            robot.pick(60.0 + index, 60.0, cfg.pick_z_mm, cfg.dwell_s)
            robot.deposit(cfg.deposit.x, cfg.deposit.y, cfg.deposit.z, cfg.dwell_s)
            analyzer.analyze(f"BENCH{index:04d}", 10.0)
            times.append((time.perf_counter() - start) * 1000)
        return times
    finally:
        workcell.close()


def orchestrated_picks(config) -> tuple[list[float], float]:
    """Milliseconds per orchestrated pick (from the run's own pick.done events), run total."""
    store = Store.open(config.database.url)
    start = time.perf_counter()
    with open_run(config, store) as session:
        outcome = session.execute()
    total = time.perf_counter() - start
    assert outcome.state == "succeeded", outcome
    times = [e.data["ms"] for e in store.events(outcome.run_id, "pick.done")]
    return times, total


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--picks", type=int, default=12)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        config = make_config(Path(folder), args.picks)
        bare = bare_cycles(config, args.picks)
        orchestrated, total = orchestrated_picks(config)
    bare_ms, run_ms = statistics.median(bare), statistics.median(orchestrated)
    print(f"picks per run: {len(orchestrated)} (one 1.3-Mpixel sample plate)")
    print(f"{'cycle':<44}{'median ms':>10}{'min ms':>9}{'max ms':>9}")
    for name, times in (
        ("bare drivers (pick, deposit, analyze)", bare),
        ("orchestrated pick (stored, audited)", orchestrated),
    ):
        print(f"{name:<44}{statistics.median(times):>10.1f}{min(times):>9.1f}{max(times):>9.1f}")
    print(f"software overhead per pick: {run_ms - bare_ms:.1f} ms (median)")
    print(f"whole run incl. start-up, homing, plate analysis: {total:.2f} s")


if __name__ == "__main__":
    main()
