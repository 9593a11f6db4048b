"""The malformed-definition campaign of issue 36: every shipped VISA light definition and every malformed variant of
each (a second command smuggled in with a newline or ';', an output level in setup, placeholders a command may not
use, formats that are not a plain number, formats and rig maxima that round above the limit), driven by
``uwlab light --on --level L`` on its twins (the CV/CC supply twin with an LED load over TCP, and the pyvisa-sim
devices) while the bytes each twin receives are recorded (tests/support/light_campaign.py). Targets: 0 over-limit
set points, 0 tracebacks.

Usage: python benchmarks/malformed_definitions.py   (prints JSON)
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests.support.light_campaign import campaign, counts


def main() -> dict:
    out: dict = {"targets": {"over_limit_set_points": 0, "tracebacks": 0}, "twins": {}}
    for kind in ("physics", "pyvisa-sim"):
        started = time.perf_counter()
        with tempfile.TemporaryDirectory() as folder:
            runs = campaign(Path(folder), kind)
        out["twins"][kind] = {
            **counts(runs),
            "over_limit": [{"run": r.label, "commands": r.over} for r in runs if r.over],
            "seconds": round(time.perf_counter() - started, 2),
        }
    return out


if __name__ == "__main__":
    print(json.dumps(main(), indent=2))
