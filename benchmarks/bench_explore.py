"""Design explorer speed: HTTP round trips to `uwlab explore` (a real process on 127.0.0.1). Prints one JSON object.

Targets (issue 14): one design ≤ 100 ms (``/api/design``, and ``/api/view``, what the page asks on every edit:
the numbers, warnings, light budget and the five figures); a 10⁴-point sweep ≤ 1 s (``/api/sweep``, f-number ×
altitude, 100 × 100). Each request changes the design (a new f-number or altitude), as editing does.
"""

from __future__ import annotations

import json
import statistics
import sys
import time
from pathlib import Path

import httpx2

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.support.explorer_process import Explorer  # noqa: E402

EXAMPLE = ROOT / "configs" / "design" / "example.toml"


def timed(client: httpx2.Client, url: str, bodies: list[dict]) -> dict:
    times = []
    for body in bodies:
        t0 = time.perf_counter()
        response = client.post(url, json=body)
        times.append(time.perf_counter() - t0)
        response.raise_for_status()
    return {"best_ms": min(times) * 1e3, "median_ms": statistics.median(times) * 1e3, "requests": len(times)}


def main() -> None:
    explorer = Explorer(str(EXAMPLE))
    try:
        with httpx2.Client(base_url=explorer.url, timeout=60) as client:
            client.post("api/view", json={})  # first request: caches warm
            numbers = [{"set": {"lens.f_number": 1.4 + 0.1 * i}} for i in range(60)]
            design = timed(client, "api/design", numbers)
            view = timed(client, "api/view", [{"set": {"operation.altitude_m": 0.5 + 0.05 * i}} for i in range(30)])
            grid = {"lens.f_number": "1:20.8:0.2", "operation.altitude_m": "0.5:10.4:0.1"}
            sweep_body = [{"set": {"sensor.gain_db": float(i)}, "grid": grid, "output": "snr_db"} for i in range(5)]
            points = client.post("api/sweep", json=sweep_body[0]).json()["points"]
            sweep = timed(client, "api/sweep", sweep_body)
    finally:
        explorer.stop()
    print(
        json.dumps(
            {
                "design_round_trip": {**design, "target_ms": 100},
                "view_round_trip": {**view, "target_ms": 100},
                "sweep_round_trip": {**sweep, "points": points, "target_ms": 1000},
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
