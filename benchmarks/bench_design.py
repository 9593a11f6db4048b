"""Design-model speed: single-evaluation latency and grid throughput. Prints one JSON object.

Targets (issues 2 and 13): single evaluation ≤ 1 ms in-process; ≥ 2,000,000 design points per second on 2 cores
for every grid. Grids of 1,000,000 points on the example design:
- easy: altitude × f-number × exposure × gain (100 × 50 × 20 × 10): exposure and gain only scale the result;
- hard: altitude × attenuation scale × beam half-angle (100 × 100 × 100): every point its own spectral path;
- focal: altitude × focal length × beam half-angle (100 × 100 × 100): 100 lens geometries, each its own image
  average;
- geometry_per_point: altitude × focal length × water index (100 × 100 × 100): 10,000 lens/port geometries, each
  with its own 100 paths; the image average then takes a Gauss rule of the sample radii (8–24 lookups a point).
"model" is `evaluate` on the open mesh (arrays broadcast, outputs materialised over the grid); "rows" is the
chunked pipeline of `uwlab design --grid` (`DesignGrid` chunks into Arrow tables with every column, no disk).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from uwlab.experiments.design.grid import DesignGrid
from uwlab.model.config import load_raw
from uwlab.model.design import evaluate, load_design

EXAMPLE = Path(__file__).resolve().parents[1] / "configs" / "design" / "example.toml"

GRIDS = {
    "easy": {
        "operation.altitude_m": np.linspace(0.5, 10.0, 100),
        "lens.f_number": np.linspace(1.4, 16.0, 50),
        "operation.exposure_s": np.geomspace(1e-4, 1e-2, 20),
        "sensor.gain_db": np.linspace(0.0, 18.0, 10),
    },
    "hard": {
        "operation.altitude_m": np.linspace(0.5, 10.0, 100),
        "water.attenuation_scale": np.linspace(0.5, 2.0, 100),
        "light.beam_half_angle_deg": np.linspace(10.0, 60.0, 100),
    },
    "focal": {
        "operation.altitude_m": np.linspace(0.5, 10.0, 100),
        "lens.focal_length_mm": np.linspace(4.0, 50.0, 100),
        "light.beam_half_angle_deg": np.linspace(10.0, 60.0, 100),
    },
    "geometry_per_point": {
        "operation.altitude_m": np.linspace(0.5, 10.0, 100),
        "lens.focal_length_mm": np.linspace(4.0, 50.0, 100),
        "housing.water_index": np.linspace(1.33, 1.35, 100),
    },
}


def best_of(fn, repeats: int) -> tuple[float, float]:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times), float(np.median(times))


def mesh(axes: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    n = len(axes)
    return {k: v.reshape([-1 if i == j else 1 for j in range(n)]) for i, (k, v) in enumerate(axes.items())}


def model_throughput(design, axes: dict[str, np.ndarray], repeats: int) -> dict:
    shape = tuple(v.size for v in axes.values())
    grid = design.with_values(**mesh(axes))

    def run():
        out = evaluate(grid)
        return sum(float(np.broadcast_to(out[k], shape).sum()) for k in ("mean_dn", "snr_db"))

    first = best_of(run, 1)[0]
    best, median = best_of(run, repeats)
    points = int(np.prod(shape))
    return {
        "points": points,
        "first_points_per_s": points / first,
        "best_points_per_s": points / best,
        "median_points_per_s": points / median,
    }


def rows_throughput(axes: dict[str, np.ndarray]) -> dict:
    grid = DesignGrid(load_raw(EXAMPLE), {k: v.tolist() for k, v in axes.items()}, EXAMPLE.parent)
    grid.check()
    columns = len(grid.schema)
    t0 = time.perf_counter()
    rows = sum(grid.chunk_table(i).num_rows for i in range(grid.chunks))
    elapsed = time.perf_counter() - t0
    return {"points": rows, "chunks": grid.chunks, "columns": columns, "points_per_s": rows / elapsed}


def main() -> None:
    design = load_design(EXAMPLE)
    evaluate(design)
    single_best, single_median = best_of(lambda: evaluate(design), 200)
    grids = {}
    for name, axes in GRIDS.items():
        grids[name] = {"axes": list(axes), "model": model_throughput(design, axes, 5), "rows": rows_throughput(axes)}
    print(
        json.dumps(
            {
                "single_evaluation_ms": {"best": single_best * 1e3, "median": single_median * 1e3, "target": 1.0},
                "grid_target_points_per_s": 2e6,
                "grids": grids,
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
