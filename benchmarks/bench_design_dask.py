"""A 10⁹-point design grid streamed to Parquet on a Dask LocalCluster: throughput and peak memory. Prints JSON.

The grid is the example design over altitude × attenuation scale × beam half-angle × f-number (every point its own
spectral path), keeping one output column (`snr_db`) besides the four axes, written as one Parquet part per chunk
by the workers (`uwlab.experiments.design.distributed`). Peak RSS is sampled every 0.2 s over this process and
every worker process (their sum, and the largest single process). The output is deleted afterwards unless
`--out` is given.

    python benchmarks/bench_design_dask.py [--points 1e9] [--dask local|tcp://HOST:PORT] [--out DIR.parquet]
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import psutil

from uwlab.experiments.design.distributed import write_grid_dask
from uwlab.experiments.design.grid import DesignGrid
from uwlab.model.config import load_raw

EXAMPLE = Path(__file__).resolve().parents[1] / "configs" / "design" / "example.toml"


class PeakRss:
    """Samples the resident memory of this process and all its descendants (the LocalCluster's workers)."""

    def __init__(self, period_s: float = 0.2):
        self.period_s = period_s
        self.total = 0
        self.largest = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self):
        me = psutil.Process()
        while not self._stop.is_set():
            sizes = []
            for proc in [me, *me.children(recursive=True)]:
                try:
                    sizes.append(proc.memory_info().rss)
                except psutil.Error:
                    pass
            self.total = max(self.total, sum(sizes))
            self.largest = max(self.largest, max(sizes))
            self._stop.wait(self.period_s)

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()


def grid_axes(points: float) -> dict[str, list]:
    """Altitude × attenuation scale × beam half-angle × f-number, 1000 × 1000 × 100 × 10 for 10⁹ points (each
    axis scaled by (points/10⁹)^¼ otherwise)."""
    factor = (points / 1e9) ** 0.25
    n = [max(1, int(round(base * factor))) for base in (1000, 1000, 100, 10)]
    return {
        "operation.altitude_m": np.linspace(0.5, 10.0, n[0]).tolist(),
        "water.attenuation_scale": np.linspace(0.5, 2.0, n[1]).tolist(),
        "light.beam_half_angle_deg": np.linspace(10.0, 60.0, n[2]).tolist(),
        "lens.f_number": np.linspace(1.4, 16.0, n[3]).tolist(),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=float, default=1e9)
    parser.add_argument("--dask", default="local")
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    axes = grid_axes(args.points)
    grid = DesignGrid(load_raw(EXAMPLE), axes, EXAMPLE.parent, outputs=("snr_db",))
    workdir = None if args.out else Path(tempfile.mkdtemp(prefix="uwlab-bench-", dir=Path.cwd()))
    out = args.out or workdir / "grid.parquet"
    try:
        with PeakRss() as rss:
            t0 = time.perf_counter()
            summary = write_grid_dask(grid, out, args.dask)
            elapsed = time.perf_counter() - t0
        size = sum(p.stat().st_size for p in out.iterdir())
    finally:
        if workdir is not None:
            shutil.rmtree(workdir, ignore_errors=True)
    print(
        json.dumps(
            {
                "points": summary["points"],
                "shape": [len(v) for v in axes.values()],
                "axes": list(axes),
                "columns": summary["columns"],
                "chunks": summary["chunks"],
                "chunk_points": grid.chunk_points,
                "workers": summary["workers"],
                "cpu_count": psutil.cpu_count(),
                "elapsed_s": elapsed,
                "points_per_s": summary["points"] / elapsed,
                "peak_rss_total_mib": rss.total / 2**20,
                "peak_rss_largest_process_mib": rss.largest / 2**20,
                "output_gib": size / 2**30,
                "bytes_per_point": size / summary["points"],
                "log10_points": math.log10(summary["points"]),
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
