"""The main job on the simulated rig: the paper's tank campaign, calibration, validation and report.

1. Start the simulated rig — the simulated cameras through the real camera interface, the simulated light and
   spectrometer as separate processes on pseudo-terminals talking to the real serial drivers — and run
   `configs/plans/tank-exposure-sweep.toml`: IMX250 and ICX285 cameras × no lens / 30 mm F2.0 / 12 mm F4.0,
   exposure sweeps, spectra at the target and at the camera.
2. Calibrate the model against it (`uwlab.experiments.calibration.pipeline`), with the cross-configuration check.
3. Write ``report.html`` and ``summary.json`` (per parameter: truth, median, 2.5/16/84/97.5th percentiles, τ;
   converged; cross-configuration errors).
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Callable

from uwlab.experiments.calibration.pipeline import calibrate
from uwlab.experiments.dataset import Dataset
from uwlab.experiments.acquisition.plan import load_plan
from uwlab.experiments.report import write_report
from uwlab.experiments.acquisition.rigs import SimRig
from uwlab.experiments.acquisition.sweep import SweepRunner
from uwlab.model.data import config_dir
from uwlab.outputs import output_dir

DEMO_PLAN = "plans/tank-exposure-sweep.toml"


def demo_summary(calibration_summary: dict, report: Path) -> dict:
    keep = ("truth", "median", "p2_5", "p16", "p84", "p97_5", "tau")
    return {
        "parameters": {name: {k: p.get(k) for k in keep} for name, p in calibration_summary["parameters"].items()},
        "converged": calibration_summary["converged"],
        "cross_configuration": calibration_summary["cross_configuration"],
        "training_sweeps": calibration_summary["training_sweeps"],
        "warnings": calibration_summary["warnings"],
        "not_separable": calibration_summary["not_separable"],
        "report": str(report),
    }


def run_demo(out: Path, sweep_progress: Callable | None = None, fit_progress: Callable | None = None,
             plan_path: Path | None = None, seed: int = 0) -> dict:
    """Run the campaign into `out` (which must not exist or be empty) on the simulated rig with all its noise seeded
    from `seed` (equal seeds, equal numbers); returns the summary written to summary.json."""
    out = output_dir(out, "--out", empty=True)
    plan = load_plan(plan_path or config_dir() / DEMO_PLAN)
    with Dataset.create(out / "dataset", plan.raw, plan_sha256=plan.sha256, sim=True) as dataset, \
            SimRig(plan.rig_path, seed=seed) as rig:
        SweepRunner(plan, dataset, rig, sweep_progress).run()
    calibration = calibrate(out / "dataset", None, out / "fit", progress=fit_progress)
    report = write_report(out, out / "report.html")
    summary = demo_summary(calibration.summary, report)
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary
