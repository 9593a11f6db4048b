"""Design-model speed: single-evaluation latency and grid throughput. Prints one JSON object.

Targets (issue 2): single evaluation ≤ 1 ms in-process; grid ≥ 1,000,000 design points per second on 2 cores.
The grid is the example design over altitude × f-number × exposure × gain (100 × 50 × 20 × 10 = 1,000,000 points).
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from uwlab.model.design import evaluate, load_design

EXAMPLE = Path(__file__).resolve().parents[1] / "configs" / "design" / "example.toml"


def best_of(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times), float(np.median(times))


def main() -> None:
    design = load_design(EXAMPLE)
    evaluate(design)
    single_best, single_median = best_of(lambda: evaluate(design), 200)
    axes = {
        "operation.altitude_m": np.linspace(0.5, 10.0, 100)[:, None, None, None],
        "lens.f_number": np.linspace(1.4, 16.0, 50)[None, :, None, None],
        "operation.exposure_s": np.geomspace(1e-4, 1e-2, 20)[None, None, :, None],
        "sensor.gain_db": np.linspace(0.0, 18.0, 10)[None, None, None, :],
    }
    grid = design.with_values(**axes)
    points = 100 * 50 * 20 * 10

    def run_grid():
        out = evaluate(grid)
        return np.broadcast_to(out["mean_dn"], (100, 50, 20, 10)).sum()

    run_grid()
    grid_best, grid_median = best_of(run_grid, 5)
    print(json.dumps({
        "single_evaluation_ms": {"best": single_best * 1e3, "median": single_median * 1e3, "target": 1.0},
        "grid_points": points,
        "grid_points_per_s": {"best": points / grid_best, "median": points / grid_median, "target": 1e6},
    }, indent=2))


if __name__ == "__main__":
    main()
