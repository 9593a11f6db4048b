"""Where a result was made: the one record of the software and machine behind a dataset, a fit, an EMVA
characterisation and a report (`provenance`), and its one-line form (`provenance_line`).

Recorded: uwlab's version and git commit ("unknown" outside a git checkout of uwlab; ``modified`` when the checkout
has uncommitted changes to tracked files), Python, the versions of the packages the numbers depend on
(`PACKAGES`), the BLAS numpy calls with its thread count (threadpoolctl's view of the loaded library; without
threadpoolctl the BLAS numpy was built against, from ``numpy.show_config``, and the thread count only when an
environment variable sets it), the CPU model (``/proc/cpuinfo``) and count, the SIMD extensions numpy dispatches
to on it (``numpy_simd``, as ``numpy.show_runtime`` lists them: an AVX-512 machine's fit differs in the last bits
from an AVX2 machine's), and the platform. One machine and one
seed give the same numbers every time; what agrees between machines, and to what tolerance, the README says beside
the demo's numbers (tests/integration/test_demo_report.py checks them against the demo).
"""

from __future__ import annotations

import functools
import importlib
import os
import platform
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

from uwlab import __version__

# The distributions whose versions are recorded, by their index names (OpenCV: the one pyproject.toml installs).
PACKAGES = (
    "numpy",
    "scipy",
    "emcee",
    "opencv-contrib-python-headless",
    "pyarrow",
    "pandas",
    "arviz",
    "colour-science",
    "harvesters",
    "genicam",
    "pyserial",
    "tifffile",
)
# How `provenance_line` names them.
SHORT_NAMES = {"opencv-contrib-python-headless": "OpenCV"}
UNKNOWN = "unknown"
# The environment variables that set the BLAS thread count (OpenBLAS's own first, then OpenMP's).
THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")


def provenance() -> dict[str, Any]:
    """The record of this process's software and machine (module docstring), JSON-able:
    ``{"uwlab", "commit", "modified", "python", "packages", "blas": {"library", "version", "threads"}, "cpu",
    "cpus", "numpy_simd", "platform"}``."""
    commit, modified = _commit(Path(__file__).resolve().parent.parent)
    return {
        "uwlab": __version__,
        "commit": commit,
        "modified": modified,
        "python": f"{platform.python_version()} ({platform.python_implementation()})",
        "packages": _packages(),
        "blas": _blas(),
        "cpu": _cpu_model(),
        "cpus": os.cpu_count(),
        "numpy_simd": _numpy_simd(),
        "platform": platform.platform(),
    }


def provenance_line(record: dict[str, Any]) -> str:
    """A `provenance` record in one line: uwlab and its commit, Python, the first five `PACKAGES`, the BLAS and
    its threads, the CPU.

    >>> print(provenance_line({"uwlab": "0.1.0", "commit": "0123456789abcdef", "modified": True, "python": "3.11.7",
    ...     "packages": {"numpy": "2.4.6", "opencv-contrib-python-headless": "5.0.0.93"},
    ...     "blas": {"library": "openblas", "version": "0.3.31", "threads": 2}, "cpu": "AMD EPYC", "cpus": 2}))
    uwlab 0.1.0 (commit 0123456789ab, modified), Python 3.11.7, numpy 2.4.6, OpenCV 5.0.0.93,
    BLAS openblas 0.3.31 on 2 threads, CPU AMD EPYC (2 cores)
    """
    commit = (record.get("commit") or UNKNOWN)[:12] + (", modified" if record.get("modified") else "")
    text = f"uwlab {record.get('uwlab', UNKNOWN)} (commit {commit})"
    parts = [text, f"Python {record.get('python', UNKNOWN)}"]
    packages = record.get("packages") or {}
    parts += [f"{SHORT_NAMES.get(name, name)} {packages[name]}" for name in PACKAGES[:5] if name in packages]
    blas = record.get("blas") or {}
    threads = blas.get("threads")
    parts.append(
        f"BLAS {blas.get('library', UNKNOWN)} {blas.get('version', UNKNOWN)} on "
        f"{threads if threads is not None else 'an unknown number of'} threads"
    )
    simd = record.get("numpy_simd")
    cores = f"{record.get('cpus') or '?'} cores" + (f"; numpy SIMD {' '.join(simd)}" if simd else "")
    parts.append(f"CPU {record.get('cpu', UNKNOWN)} ({cores})")
    return ", ".join(parts)


@functools.cache
def _commit(root: Path) -> tuple[str, bool | None]:
    """(HEAD's commit, whether tracked files differ from it) of the git checkout at `root` (uwlab's: the one it is
    imported from); (UNKNOWN, None) for an installed copy, without git or before the first commit. Once per
    process."""
    if not (root / ".git").exists():
        return UNKNOWN, None
    environment = {k: v for k, v in os.environ.items() if not k.startswith("GIT_")}

    def git(*args: str) -> str:
        return subprocess.run(
            ["git", "-C", str(root), *args], capture_output=True, text=True, timeout=10, check=True, env=environment
        ).stdout.strip()

    # One git call (each costs ~5 ms): "# branch.oid SHA" ("(initial)" before the first commit), a line per change.
    try:
        lines = git("status", "--porcelain=v2", "--branch", "--untracked-files=no").splitlines()
    except (OSError, subprocess.SubprocessError):
        return UNKNOWN, None
    commit = next((line.split()[2] for line in lines if line.startswith("# branch.oid ")), "(initial)")
    if commit == "(initial)":
        return UNKNOWN, None
    return commit, any(not line.startswith("#") for line in lines)


@functools.cache
def _packages() -> dict[str, str]:
    """The installed versions of `PACKAGES`, from the names of the ``.dist-info`` directories on ``sys.path``
    (``{name}-{version}.dist-info``, the name with ``_`` for ``-``: PyPA's "Recording installed projects"
    specification), the first on the path as an import finds it: one directory listing per path entry, where
    ``importlib.metadata.version`` parses each package's METADATA (~20 ms of a short command's start)."""
    wanted = {_normalized(name): name for name in PACKAGES}
    versions: dict[str, str] = {}
    for entry in sys.path:
        try:
            names = os.listdir(entry or ".")
        except OSError:
            continue
        for directory in names:
            if not directory.endswith(".dist-info"):
                continue
            name, _, version = directory.removesuffix(".dist-info").partition("-")
            package = wanted.get(_normalized(name))
            if version and package and package not in versions:
                versions[package] = version
    return {name: versions[name] for name in PACKAGES if name in versions}


def _normalized(name: str) -> str:
    """A distribution name as PyPA's name normalisation (PEP 503) compares it: lower case, runs of ``-_.`` as ``-``."""
    return re.sub(r"[-_.]+", "-", name).lower()


def _blas() -> dict[str, Any]:
    """The BLAS numpy calls: library, version and thread count (threadpoolctl), else what numpy was built with."""
    import numpy as np

    try:
        from threadpoolctl import threadpool_info
    except ImportError:
        built = np.show_config(mode="dicts")["Build Dependencies"]["blas"]
        threads = next((os.environ[v] for v in THREAD_VARIABLES if os.environ.get(v, "").isdigit()), None)
        return {
            "library": built.get("name", UNKNOWN),
            "version": built.get("version", UNKNOWN),
            "threads": None if threads is None else int(threads),
        }
    pools = [p for p in threadpool_info() if p.get("user_api") == "blas"]
    numpy_dir = str(Path(np.__file__).resolve().parent.parent)
    # numpy's own BLAS first (a wheel's bundled library lies beside numpy; scipy may load another)
    pools.sort(key=lambda p: not str(p.get("filepath", "")).startswith(numpy_dir + os.sep + "numpy"))
    if not pools:
        return {"library": UNKNOWN, "version": UNKNOWN, "threads": None}
    pool = pools[0]
    return {
        "library": pool.get("internal_api", UNKNOWN),
        "version": pool.get("version") or UNKNOWN,
        "threads": pool.get("num_threads"),
    }


def _numpy_simd() -> list[str] | None:
    """The SIMD targets numpy dispatches to on this CPU (its build's dispatch list, those the CPU has and the
    environment has not disabled); None where numpy does not say (its private module, as ``numpy.show_runtime``)."""
    try:
        umath = importlib.import_module("numpy._core._multiarray_umath")
    except ImportError:
        return None
    dispatch, features = getattr(umath, "__cpu_dispatch__", None), getattr(umath, "__cpu_features__", None)
    if dispatch is None or features is None:
        return None
    return [str(target) for target in dispatch if features.get(target)]


@functools.cache
def _cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo (x86 ``model name``; Arm ``Model``/``Hardware``), else what
    `platform` knows."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as file:
            text = file.read(1 << 20)
    except OSError:
        text = ""
    for key in ("model name", "Model", "Hardware", "cpu model"):
        for line in text.splitlines():
            name, _, value = line.partition(":")
            if name.strip() == key and value.strip():
                return value.strip()
    return platform.processor() or platform.machine() or UNKNOWN
