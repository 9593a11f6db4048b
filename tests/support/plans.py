"""Sweep plans for the tests, written from tables with tomli-w so that a test states only what its sweeps need, and
`record`: a plan's sweeps on a simulated rig in process, as ``uwlab sweep --sim`` runs them."""

from __future__ import annotations

from pathlib import Path

import tomli_w

from uwlab.experiments.acquisition.plan import Plan
from uwlab.experiments.acquisition.sweep import SweepRunner
from uwlab.experiments.dataset import Dataset

from tests.support.paths import SIM_TANK

# A small stand-in for the demo's campaign (configs/plans/tank-exposure-sweep.toml): its IMX250 sweeps through the
# 30 mm F2.0 and the 12 mm F4.0 lens, 8 exposures from 20 µs to 1.5 ms, 32 × 24 px windows, 2 frames a point.
CAMPAIGN_DEFAULTS = {
    "kind": "exposure",
    "values": {"start": 20, "stop": 1500, "num": 8, "spacing": "log"},
    "frames_per_point": 2,
    "dark": "point",
    "dark_frames": 2,
    "spectrometer": ["target", "camera"],
    "spectrometer_integration_ms": 10,
}
CAMPAIGN_SWEEPS = [
    {
        "id": "imx250-30mm-f2",
        "sensor": "imx250m",
        "lens": {"focal_length_mm": 30, "f_number": 2.0, "f_number_range": [2.0, 16.0]},
        "camera": {"id": "blackfly-s", "pixel_format": "Mono12", "window": [1192, 1000, 32, 24]},
    },
    {
        "id": "imx250-12mm-f4",
        "sensor": "imx250m",
        "lens": {"focal_length_mm": 12, "f_number": 4.0, "f_number_range": [1.4, 16.0]},
        "camera": {"id": "blackfly-s", "pixel_format": "Mono12", "window": [1192, 1000, 32, 24]},
    },
]


def camera(width: int, height: int, **settings) -> dict:
    """A ``[camera]`` table: Mono12, a ``width`` × ``height`` px window from pixel (1192, 1000) of the tank camera's
    2448 × 2048 IMX250 (on the board), and ``settings``."""
    return {"pixel_format": "Mono12", "window": [1192, 1000, width, height], **settings}


def write_plan(path: Path, name: str | None, sweeps: list[dict] = (), *, rig: Path | None = SIM_TANK, **tables) -> Path:
    """A plan file at ``path`` (docs/sweeps.md): ``name``, ``rig``, the other top-level keys and tables (``camera``,
    ``instruments``, ``defaults``, ...) and a ``[[sweep]]`` table per item of ``sweeps``; None leaves a key out."""
    raw = {"name": name, "rig": None if rig is None else str(rig), **tables, "sweep": list(sweeps) or None}
    path.write_text(tomli_w.dumps({key: value for key, value in raw.items() if value is not None}))
    return path


def write_campaign(path: Path, name: str, sweeps: int = len(CAMPAIGN_SWEEPS), **defaults) -> Path:
    """The small campaign's first ``sweeps`` sweeps as a plan at ``path``, its ``defaults`` changed by ``defaults``."""
    return write_plan(path, name, CAMPAIGN_SWEEPS[:sweeps], defaults={**CAMPAIGN_DEFAULTS, **defaults})


def record(plan: Plan, out: Path, rig) -> Dataset:
    """``plan``'s sweeps run on the simulated ``rig`` into a new dataset at ``out`` (its lock released after), opened
    for reading."""
    with Dataset.create(out, plan.raw, plan_sha256=plan.sha256, sim=True) as data:
        SweepRunner(plan, data, rig).run()
    return Dataset.open(out)
