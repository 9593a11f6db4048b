"""Start-up cost of the `uwlab` command, end to end as a user sees it. Prints one JSON object.

Each command runs as a fresh process (``python -m uwlab.cli.main ...``, the interpreter's own start included)
RUNS times; the figures are the median and the fastest wall-clock time in seconds, and the number of modules
the process imported (``-X importtime`` lines) for the median-free count.

Targets (issue 10): ``uwlab --help`` ≤ 0.3 s; ``uwlab design CONFIG --json`` for one design ≤ 1.0 s.
``import_uwlab`` (issue 23): ``import uwlab`` in a fresh interpreter ≤ 0.3 s — the median over RUNS fresh processes
of the import alone (``import_s``, timed inside the process) and of the whole process (``median_s``, the
interpreter's start included); the Python API's names load on first use.
Usage: ``python benchmarks/bench_startup.py [RUNS]`` (default 7).
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "configs" / "design" / "example.toml"
COMMANDS = {
    "help": ["--help"],
    "version": ["--version"],
    "design_json": ["design", str(EXAMPLE), "--json"],
    "spectrum_help": ["spectrum", "--help"],
}
TARGETS_S = {"help": 0.3, "version": 0.3, "design_json": 1.0}


def run(argv: list[str], env: dict) -> float:
    start = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "uwlab.cli.main", *argv],
        env=env,
        check=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    return time.perf_counter() - start


IMPORT_PROBE = "import time; t = time.perf_counter(); import uwlab; print(time.perf_counter() - t)"


def import_uwlab(env: dict) -> tuple[float, float]:
    """(wall-clock seconds of a fresh ``python -c 'import uwlab'``, seconds of the import itself)."""
    start = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", IMPORT_PROBE], env=env, check=True, capture_output=True, text=True)
    return time.perf_counter() - start, float(out.stdout)


def modules_imported(argv: list[str], env: dict) -> int:
    out = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "uwlab.cli.main", *argv],
        env=env,
        check=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    return sum(line.startswith("import time:") for line in out.stderr.splitlines()) - 1  # minus the header


def main() -> None:
    runs = int(sys.argv[1]) if len(sys.argv) > 1 else 7
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    result = {"runs": runs, "python": sys.version.split()[0], "load_average": os.getloadavg()[0]}
    for name, argv in COMMANDS.items():
        run(argv, env)  # warm the file cache and byte-code
        times = [run(argv, env) for _ in range(runs)]
        entry = {
            "median_s": round(statistics.median(times), 3),
            "min_s": round(min(times), 3),
            "modules": modules_imported(argv, env),
        }
        if name in TARGETS_S:
            entry["target_s"] = TARGETS_S[name]
            entry["meets_target"] = entry["median_s"] <= TARGETS_S[name]
        result[name] = entry
    import_uwlab(env)  # warm
    walls, imports = zip(*(import_uwlab(env) for _ in range(runs)), strict=True)
    result["import_uwlab"] = {
        "median_s": round(statistics.median(walls), 3),
        "import_s": round(statistics.median(imports), 4),
        "target_s": 0.3,
        "meets_target": statistics.median(imports) <= 0.3,
    }
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
