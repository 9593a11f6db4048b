"""Dataset storage benchmark (JSON on stdout): the cost of recording a point does not grow with the dataset.

1. ``append``: 20,000 points (each with a 401-wavelength spectrum) appended one at a time to a new dataset, each
   durable on return (`uwlab.experiments.dataset.Dataset.append_point`); reports the time of the first 100 and
   of the last 100 appends and their ratio (target ≤ 1.5), the median append, the number of part files at the
   end and the time to open the dataset and read its points.
2. ``sweep``: sweeps on the simulated rig (16×16 window, 2 frames, no dark frames, no settling) into a dataset
   already holding 10, then 1000 points; reports their cost per point (median of 3 sweeps of 40 points; target:
   the same at both sizes; issue 16 measured 33 ms at 10 points and 533 ms at 1000 with the storage this
   replaced). Most of it is fsync: run on an otherwise idle machine.

Usage: python benchmarks/bench_dataset.py [--points N] [--dir DIR]
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from uwlab.experiments.acquisition.plan import load_plan
from uwlab.experiments.acquisition.sim_rig import SimRig
from uwlab.experiments.acquisition.sweep import SweepRunner
from uwlab.experiments.dataset import Dataset, spectra_frame

WINDOW = 100
RIG = Path(__file__).resolve().parents[1] / "configs" / "rigs" / "sim-tank.toml"
NM = np.arange(380.0, 781.0)


def row(sweep_id: str, index: int) -> dict:
    return {
        "sweep_id": sweep_id,
        "point_index": index,
        "kind": "exposure",
        "frames": 2,
        "exposure_us": 100.0 + index,
        "mean_dn": 1000.0 + index,
        "temporal_var_dn2": 40.0,
        "spatial_var_dn2": 3.0,
        "saturated": False,
        "light_on": True,
        "t_start_ns": time.time_ns(),
        "t_end_ns": time.time_ns(),
    }


def spectrum(sweep_id: str, index: int):
    return spectra_frame(sweep_id, index, [("target", NM, np.full_like(NM, 1e-3))])


def bench_append(root: Path, points: int) -> dict:
    plan = {"name": "bench", "sweep": [{"id": "a", "kind": "exposure", "values": [float(i) for i in range(points)]}]}
    durations = []
    with Dataset.create(root, plan, plan_sha256="bench") as data:
        for index in range(points):
            t0 = time.perf_counter()
            data.append_point(row("a", index), spectrum("a", index))
            durations.append(time.perf_counter() - t0)
    t0 = time.perf_counter()
    opened = Dataset.open(root)
    rows = len(opened.points())
    open_s = time.perf_counter() - t0
    first, last = sum(durations[:WINDOW]), sum(durations[-WINDOW:])
    return {
        "points": points,
        "first_100_s": round(first, 4),
        "last_100_s": round(last, 4),
        "last_over_first": round(last / first, 3),
        "median_append_ms": round(1e3 * statistics.median(durations), 2),
        "max_append_ms": round(1e3 * max(durations), 1),
        "part_files": len(list((root / "parts").iterdir())),
        "open_and_read_points_s": round(open_s, 3),
        "rows_read": rows,
    }


SWEEP_PLAN = """
name = "bench-sweep"
rig = "{rig}"
[camera]
pixel_format = "Mono12"
window = [1192, 1000, 16, 16]
[defaults]
frames_per_point = 2
dark = "none"
settle_s = 0.0
kind = "exposure"
values = {{start = 100, stop = 400, num = {timed}}}
[[sweep]]
id = "recorded"
values = {{start = 100, stop = 400, num = {recorded}}}
"""
TIMED_SWEEPS = 3


def bench_sweep(directory: Path, rig: SimRig, recorded: int, timed: int = 40) -> float:
    """Median over `TIMED_SWEEPS` sweeps of ``timed`` points of the milliseconds per point (from each sweep's first
    point on: no set-up), into a dataset already holding ``recorded`` points."""
    path = directory / f"plan-{recorded}.toml"
    path.write_text(
        SWEEP_PLAN.format(rig=RIG, recorded=recorded, timed=timed)
        + "".join(f'[[sweep]]\nid = "timed-{n}"\n' for n in range(TIMED_SWEEPS))
    )
    plan = load_plan(path)
    stamps: dict[str, list[float]] = {}
    with Dataset.create(directory / f"sweep-{recorded}", plan.raw, plan_sha256=plan.sha256, sim=True) as data:
        for index in range(recorded):
            data.append_point(row("recorded", index), spectrum("recorded", index))
        SweepRunner(
            plan, data, rig, progress=lambda event: stamps.setdefault(event.sweep_id, []).append(time.perf_counter())
        ).run()
    return statistics.median(1e3 * (t[-1] - t[0]) / (len(t) - 1) for t in stamps.values())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=20000, help="points appended (default 20000)")
    parser.add_argument("--dir", type=Path, help="where to write (default: a temporary directory)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(dir=args.dir) as tmp:
        directory = Path(tmp)
        result = {"append": bench_append(directory / "append", args.points)}
        with SimRig(RIG) as rig:
            result["sweep_ms_per_point"] = {str(n): round(bench_sweep(directory, rig, n), 1) for n in (10, 1000)}
    print(json.dumps(result))


if __name__ == "__main__":
    main()
