"""Sharpness and coverage of the held-out 95 % bands (issue 35) over seeds, on the quick simulated campaign the slow
tests use (`uwlab.experiments.demo.quick_demo`: the demo's rig, tank world, extended model, rendered in process).
Per seed: the median band half-width and the median realised error over the held-out points (both in % of the
prediction), their ratio and the fraction of points inside their bands (`band_sharpness`), for the 95 % bands and
(``*_90``) the 90 % bands; the medians over the seeds.
Target: ratio <= 2.5 with >= 90 % coverage (docs/validation.md gives the figures and why a calibrated
Gaussian 95 % band cannot go below 1.96 / 0.674 = 2.9). FOLDS: "loo" (the default: each configuration predicted
from a fit of all the others) or a number of folds (2: the earlier default) for a comparison.
Prints one JSON object. Usage: python benchmarks/held_out_bands.py [SEEDS [FOLDS]] (default 10 loo).
"""

from __future__ import annotations

import json
import resource
import sys
import time

import numpy as np

from uwlab.experiments.demo import quick_demo

KEYS = ("held_out_width_over_error", "held_out_inside_95", "held_out_half_width_percent", "held_out_error_percent")
KEYS_90 = ("width_over_error", "inside", "half_width_percent", "error_percent")  # the 90 % bands' (`held_out_90`)


def cpu_s() -> float:
    """CPU seconds (user + sys) of this process and its finished children (the folds' workers)."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def main(seeds: int = 10, folds: int | str = "loo") -> None:
    runs = []
    for seed in range(seeds):
        wall, cpu = time.perf_counter(), cpu_s()
        summary = quick_demo("tank", "extended", seed, held_out=folds)
        coverage = summary["predictive_coverage"]
        runs.append(
            {
                "seed": seed,
                **{key: coverage[key] for key in KEYS},
                **{f"{key}_90": value for key, value in coverage["held_out_90"].items()},
                "tau_median_per_fold": [f["config_discrepancy_median"] for f in summary["folds"]],
                "wall_s": time.perf_counter() - wall,
                "cpu_s": cpu_s() - cpu,
            }
        )
        print(json.dumps(runs[-1]), file=sys.stderr)
    print(
        json.dumps(
            {
                "seeds": seeds,
                "folds": folds,
                "target": {"held_out_width_over_error": "<= 2.5", "held_out_inside_95": ">= 0.90"},
                "median": {
                    key: float(np.median([r[key] for r in runs]))
                    for key in (*KEYS, *(f"{k}_90" for k in KEYS_90), "wall_s", "cpu_s")
                },
                "runs": runs,
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    count = sys.argv[2] if len(sys.argv) > 2 else "loo"
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 10, int(count) if count.isdigit() else count)
