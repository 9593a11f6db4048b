"""Instrument round trip on pyvisa-sim: set the drive, wait for nothing, read the error queue and the drive back
(`VisaLight.set_level`: write + SYST:ERR? + CURR?), for every shipped VISA light definition. Target: median < 5 ms.

Usage: python benchmarks/bench_instruments.py [REPEATS]   (default 200; prints JSON)
"""

from __future__ import annotations

import json
import statistics
import sys
import time
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests.support.paths import CONFIGS
from uwlab.drivers.instruments import open_visa_light


def main(repeats: int) -> dict:
    out: dict = {"repeats": repeats, "target_median_ms": 5.0, "definitions": {}}
    for path in sorted((CONFIGS / "instruments" / "sim").glob("*.yaml")):
        resource = next(iter(yaml.safe_load(path.read_text())["resources"]))
        with open_visa_light(path.stem, resource, f"{path}@sim") as light:
            times = []
            for i in range(repeats):
                started = time.perf_counter()
                light.set_level((i % 10) / 10)
                times.append(1e3 * (time.perf_counter() - started))
        out["definitions"][path.stem] = {
            "median_ms": round(statistics.median(times), 3),
            "p99_ms": round(sorted(times)[int(0.99 * len(times)) - 1], 3),
        }
    return out


if __name__ == "__main__":
    print(json.dumps(main(int(sys.argv[1]) if len(sys.argv) > 1 else 200), indent=2))
