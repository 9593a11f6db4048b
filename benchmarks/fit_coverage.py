"""Calibration of the credible intervals (simulation-based; `uwlab.experiments.calibration.coverage`): truths drawn
from the priors, one simulated campaign per seed, and the fraction of 95 % intervals that contain the truth.
Target (issue 6): 90–99 % over ≥ 20 seeds; the slow test in tests/slow/test_fit.py checks 4 seeds (≥ 8 of 12).
Prints one JSON object (coverage, wall time and every miss). Usage: python benchmarks/fit_coverage.py [SEEDS]
"""

from __future__ import annotations

import json
import sys
import time

from uwlab.experiments.calibration.coverage import interval_coverage


def main(seeds: int = 20) -> None:
    t0 = time.perf_counter()
    result = interval_coverage(seeds)
    print(
        json.dumps(
            {
                "seeds": seeds,
                "coverage_95": result.fraction,
                "target": [0.90, 0.99],
                "wall_time_s": time.perf_counter() - t0,
                "misses": result.misses,
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 20)
