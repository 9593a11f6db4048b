"""Dataset integrity campaign: random single-bit flips across every file of a recorded dataset (parts, manifest,
metadata and their sealed copies), each read as a user would, then repaired with `dataset check --repair`.
Prints one JSON object (tests/support/bitflips.py says what each outcome means).

Target (issue 25): 0 silent changes over ≥ 300 flips; every intact point still readable after --repair.
Usage: ``.venv/bin/python benchmarks/dataset_integrity.py [FLIPS] [SEED]``.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.support.bitflips import flip_campaign, small_dataset  # noqa: E402


def main() -> None:
    flips = int(sys.argv[1]) if len(sys.argv) > 1 else 300
    seed = int(sys.argv[2]) if len(sys.argv) > 2 else 0
    with tempfile.TemporaryDirectory() as tmp:
        pristine = Path(tmp) / "pristine"
        small_dataset(pristine)
        started = time.perf_counter()
        outcomes = flip_campaign(pristine, Path(tmp), flips, np.random.default_rng(seed))
        elapsed = time.perf_counter() - started
    print(
        json.dumps(
            {
                "benchmark": "dataset_integrity",
                "flips": flips,
                "seed": seed,
                "outcomes": dict(outcomes.counts),
                "flips_by_file": dict(outcomes.by_file),
                "silent_changes": len(outcomes.silent),
                "silent": outcomes.silent,
                "intact_points_lost_by_repair": len(outcomes.lost_intact),
                "not_repaired": outcomes.unrepaired,
                "seconds": round(elapsed, 1),
            },
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
