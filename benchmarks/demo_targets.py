"""The demo's targets (issue 11) over seeds: `uwlab demo` itself (the simulated rig with its devices, ≈ 1 min a run)
for each world and model, pooled with `uwlab.experiments.demo.target_tally`.

Targets: tank world + extended model: ≥ 90 % of held-out points inside their 95 % bands, every parameter with a
simulated truth inside its 95 % interval in ≥ 90 % of cases, adequate in every run; turbid world + paper model:
inadequate, backscatter named; ideal world + paper model: adequate (today's closed-world results).
Prints one JSON object. Usage: python benchmarks/demo_targets.py [SEEDS] [WORLD:MODEL ...]
(default 10 seeds, tank:extended turbid:paper ideal:paper). The slow test tests/slow/test_demo_targets.py checks
the same targets on a reduced, in-process campaign.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

from uwlab.experiments.demo import run_demo, target_tally

DEFAULT_RUNS = ("tank:extended", "turbid:paper", "ideal:paper")
TARGETS = {
    "tank:extended": {
        "held_out_inside_95": ">= 0.90",
        "truth_inside_95": ">= 0.90",
        "adequate": "all runs",
        "held_out_width_over_error": "<= 2.5 (issues 24, 35), or the documented reason (docs/validation.md: "
        "a calibrated 95 % band is 2.9x a Gaussian error; the configurations' levels genuinely differ)",
    },
    "turbid:paper": {"adequate": "no run", "backscatter_named": "all runs"},
    "ideal:paper": {"adequate": "all runs"},
}


def main(seeds: int = 10, runs: tuple[str, ...] = DEFAULT_RUNS) -> None:
    out = {"seeds": seeds}
    for run in runs:
        world, model = run.split(":")
        summaries, times = [], []
        for seed in range(seeds):
            with tempfile.TemporaryDirectory(prefix="uwlab-demo-targets-") as tmp:
                t0 = time.perf_counter()
                summaries.append(run_demo(Path(tmp) / "demo", seed=seed, world=world, model=model))
                times.append(time.perf_counter() - t0)
        out[run] = {
            **target_tally(summaries),
            "target": TARGETS.get(run),
            "wall_time_s_mean": sum(times) / len(times),
            "wall_time_s_max": max(times),
        }
        print(json.dumps(out, indent=2), file=sys.stderr)
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 10, tuple(sys.argv[2:]) or DEFAULT_RUNS)
