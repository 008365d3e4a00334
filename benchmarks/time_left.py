"""The Mark dock's time left: the naive estimate (elapsed / paths done × paths left) against
:class:`insitu.ui.model.time_left.TimeLeft` (planned time left × the board's recent speed
ratio, smoothed, counting down), on the planned path times of a real job — a QR code hatched
along its modules, then a text, planned on the simulated step block's recorded scan — marked
at 1.3× the planned time with ±20 % noise per path, and with a slowdown to 3× half-way.
Prints the largest rise of the shown value between two updates and the error against the
true time left at a quarter, half and three quarters of the job.

    PYTHONPATH=src python benchmarks/time_left.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from insitu import services
from insitu.marking import Placement, path_seconds
from insitu.services.plan import joined, plan_placements
from insitu.services.station import connect
from insitu.ui.model.time_left import TimeLeft

DATA = Path(__file__).parents[1] / "tests" / "data"


def planned_path_times() -> np.ndarray:
    cloud = services.scan_replay(DATA / "scan-step-block-b4").cloud
    with connect(binning=4) as station:
        plans = plan_placements(cloud, [Placement('text:"AB"', (0.0, 28.0), 12.0, hatch_mm=0.1),
                                 Placement('qr:"insitu"', (0.0, -30.0), 10.0)],
                         station.driver)
        job = joined(plans)
        return path_seconds(job, station.driver.timing)


def run(planned: np.ndarray, actual: np.ndarray):
    """(largest rise s, errors at 25/50/75 %) of the naive estimate and TimeLeft."""
    n, elapsed = len(planned), np.cumsum(actual)
    truth = actual.sum() - elapsed
    new, shown_new, shown_old = TimeLeft(planned), [], []
    for d in range(1, n + 1):
        shown_old.append(elapsed[d - 1] / d * (n - d))
        shown_new.append(new.update(d, float(elapsed[d - 1])))
    out = []
    for shown in (np.array(shown_old), np.array(shown_new)):
        rise = max(float(np.max(np.diff(shown))), 0.0)
        errs = [abs(shown[int(f * n)] - truth[int(f * n)]) for f in (0.25, 0.5, 0.75)]
        out.append((rise, errs))
    return out


def main() -> None:
    planned = planned_path_times()
    rng = np.random.default_rng(0)
    n = len(planned)
    steady = planned * 1.3 * rng.uniform(0.8, 1.2, n)
    slow = steady * np.where(np.arange(n) >= n // 2, 3.0 / 1.3, 1.0)
    table = Table(title=f"time left while marking ({n} paths, {planned.sum():.1f} s planned)")
    for col in ("run", "estimate", "largest rise", "error at 25 %", "at 50 %", "at 75 %"):
        table.add_column(col, justify="right" if col != "run" else "left")
    for name, actual in (("1.3× the plan, ±20 %", steady), ("slows to 3× half-way", slow)):
        for label, (rise, errs) in zip(("elapsed/done (naive)", "TimeLeft"), run(planned, actual)):
            table.add_row(name, label, f"{rise:.2f} s", *(f"{e:.2f} s" for e in errs))
    Console().print(table)


if __name__ == "__main__":
    main()
