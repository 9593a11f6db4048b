"""The main job on the simulated rig: the paper's tank campaign, calibration, validation and report.

1. Write the inputs into ``inputs/``: the rig (`configs/rigs/paper-tank.toml`) with the chosen world
   (`uwlab.sim.world`: ``ideal``, ``tank``, ``turbid``) and the plan (`configs/plans/tank-exposure-sweep.toml`)
   pointing at it. In the turbid world the rig's water also declares the added scatterers at the world's values,
   as an experimenter who had measured them with a transmissometer would: the paper model then knows the water
   attenuates more, and only the veiling light is missing from it.
2. Start the simulated rig — the simulated cameras through the real camera interface, the simulated light and
   spectrometer as separate processes on pseudo-terminals talking to the real serial drivers — and run the plan:
   IMX250 and ICX285 cameras × no lens / 30 mm F2.0 / 12 mm F4.0, exposure sweeps, spectra at the target and at
   the camera. All simulated noise is seeded from `seed`.
3. Characterise each camera as a lab would before its tank campaign (`characterise_cameras`, with ``sensors =
   "emva"``, the default): the same simulated sensor (its profile and the world's sensor realism: the
   non-linearity near full well, DSNU, PRNU, hot pixels) on the simulated EMVA 1288 bench (flat light of known
   photon irradiance, `uwlab.experiments.emva.simulate.DirectBench`), characterised by the EMVA 1288 Release 4.0
   linear model into ``emva/<camera>/`` (datasheet, XML, sensor profile with its measured response curve).
4. Calibrate the chosen chain (``paper`` or ``extended``) against the tank sweeps, with posterior predictive checks,
   held-out configurations and the verdict (`uwlab.experiments.calibration.pipeline`); with the characterised
   sensors (``uwlab fit --sensor``) unless ``sensors = "profile"`` (the hand-written profiles, a linear response).
5. Measure the geometry meanwhile, in a process of its own (`uwlab.experiments.geometry.tank`): a slanted edge
   through the 12 mm F4.0 lens, focus and board distance stepped, MTF50, best focus and depth of field against the
   model, into ``geometry/``.
6. Write ``report.html`` and ``summary.json`` (the verdict, per parameter truth, median and interval, the held-out
   table and coverage, warnings).
"""

from __future__ import annotations

import numpy as np
import json
from collections import Counter
import subprocess
import sys
import tempfile
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import TYPE_CHECKING

import tomli_w

from uwlab.model.config import design_sections
from uwlab.sim.world import PRESETS, world_settings
from uwlab.errors import ConfigError, UwlabError
from uwlab.experiments.acquisition.plan import load_plan, resolved_rig
from uwlab.experiments.acquisition.sim_rig import SimRig
from uwlab.experiments.acquisition.sweep import SweepRunner
from uwlab.experiments.calibration.fit import default_config_for
from uwlab.experiments.calibration.forward import MODELS
from uwlab.experiments.calibration.pipeline import assess, calibrate
from uwlab.experiments.calibration.simulate import simulate_campaign
from uwlab.experiments.calibration.validation import default_folds
from uwlab.experiments.dataset import Dataset
from uwlab.experiments.geometry import GEOMETRY_FILE
from uwlab.experiments.report import write_report
from uwlab.model.data import config_dir, read_json, read_toml, resolve_path
from uwlab.model.build import build_design
from uwlab.model.sensor import SensorProfile, load_sensor_profile
from uwlab.outputs import output_dir

if TYPE_CHECKING:
    from uwlab.experiments.emva.datasheet import SheetInfo

DEMO_PLAN = "plans/tank-exposure-sweep.toml"
SENSOR_SOURCES = ("emva", "profile")
BENCH_PIXELS = (64, 64)  # the bench's region of the sensor: enough pixels for its statistics, quick to render
BENCH_STEPS = 40  # exposure steps from 1 % to 110 % of the saturation exposure (EMVA 1288 asks for >= 50 ...)
BENCH_RATE_E_S = 1e5  # the bench light's electron rate per pixel; η of the bench's narrow-band light:
BENCH_ETA = 0.6


def demo_summary(calibration_summary: dict, report: Path) -> dict:
    keep = ("truth", "median", "p2_5", "p16", "p84", "p97_5", "tau")
    return {
        "world": calibration_summary["world"],
        "model": calibration_summary["model"],
        "model_adequate": calibration_summary["model_adequate"],
        "predictive_coverage": calibration_summary["predictive_coverage"],
        "parameters": {name: {k: p.get(k) for k in keep} for name, p in calibration_summary["parameters"].items()},
        "converged": calibration_summary["converged"],
        "cross_configuration": calibration_summary["cross_configuration"],
        "checks": calibration_summary["checks"],
        "warnings": calibration_summary["warnings"],
        "not_separable": calibration_summary["not_separable"],
        "report": str(report),
    }


def geometry_summary(directory: Path) -> dict:
    """The geometry validation's verdict and figures for summary.json (`uwlab.experiments.geometry`)."""
    doc = read_json(directory / GEOMETRY_FILE, "geometry")
    keep = ("adequate", "headline", "lens", "worst_mtf50_error", "best_focus_measured_m", "best_focus_predicted_m")
    return {key: doc[key] for key in (*keep, "focus_step_m", "dof_measured_m", "dof_model_m", "dof_depth_errors")}


def target_tally(summaries: list[dict]) -> dict:
    """The demo's targets over runs of one world and model: the held-out points inside their 95 % bands (pooled
    over the runs), the parameters with a simulated truth inside their 95 % intervals, the runs judged adequate
    and the runs whose warnings name backscatter; the held-out bands' sharpness per run (median 95 % half-width,
    median realised error, their ratio: `predictive_coverage`) as the median and range over the runs."""
    points = sum(r["points"] for s in summaries for r in s["cross_configuration"])
    inside = sum(r["points"] * r["inside_95"] for s in summaries for r in s["cross_configuration"])
    truths = [
        p["p2_5"] <= p["truth"] <= p["p97_5"]
        for s in summaries
        for p in s["parameters"].values()
        if p.get("truth") is not None
    ]
    return {
        "runs": len(summaries),
        "held_out_inside_95": inside / points if points else None,
        "truth_inside_95": sum(truths) / len(truths) if truths else None,
        "adequate": sum(bool(s["model_adequate"]) for s in summaries),
        "backscatter_named": sum(any("backscatter" in w for w in s["warnings"]) for s in summaries),
        "failed_checks": dict(
            Counter(check["name"] for s in summaries for check in s.get("checks", []) if not check["passed"])
        ),
        **{
            f"{key}_median_range": _median_range([s["predictive_coverage"].get(key) for s in summaries])
            for key in ("held_out_half_width_percent", "held_out_error_percent", "held_out_width_over_error")
        },
    }


def _median_range(values: list) -> list[float] | None:
    """[median, min, max] of the values that exist, or None."""
    known = [float(v) for v in values if v is not None]
    return [float(np.median(known)), min(known), max(known)] if known else None


def quick_demo(
    world: str | None = None,
    model: str | None = None,
    seed: int = 0,
    directory: Path | None = None,
    progress=None,
    held_out: int | str | None = None,
) -> dict:
    """The demo's campaign without devices, a summary like `run_demo`'s: the same rig and world rendered in process
    (`uwlab.experiments.calibration.simulate`: its sweeps span each configuration's own exposure range, the light
    does not drift, there is no spectrometer), calibrated and judged like the demo (`assess`; `held_out`: its
    folds, "loo" or a number, None: the default config's, leave one configuration out). For tests and quick looks;
    `directory` receives the derived rig (default: a temporary one)."""
    with tempfile.TemporaryDirectory(prefix="uwlab-quick-demo-") as tmp:
        plan = write_inputs(config_dir() / DEMO_PLAN, world, Path(directory or tmp) / "inputs")
        rig = load_plan(plan).rig_path
        raw = read_toml(rig, "rig")
        truth = {"light_efficiency": raw["sim"]["light_efficiency"]}
        points, rigs = simulate_campaign(truth, seed=seed, rig=rig, world=None, points_per_sweep=10)
        config = default_config_for(points[~points["saturated"]], rigs)
        sweeps = list(dict.fromkeys(points["sweep_id"]))
        folds = default_folds(sweeps, config.holdout.folds if held_out is None else held_out)
        assessment = assess(points, rigs, config, folds, model, progress)
    summary = assessment.result.summary()
    names = assessment.result.names
    truths = {
        **{n: None for n in names},
        **truth,
        "attenuation_scale": float(raw["water"]["attenuation_scale"]),
        **{n: load_sensor_profile(n.split(":", 1)[1]).K_dn_per_e for n in names if n.startswith("K_dn_per_e:")},
    }
    for name, entry in summary["parameters"].items():
        entry["truth"] = truths.get(name)
    return {**summary, **assessment.summary(), "world": world}


def bench_characterisations(plan, seed: int = 0) -> dict:
    """Every camera of `plan` characterised on the simulated EMVA bench (module docstring, step 3), in memory:
    {camera (sensor profile name): (its EMVA analysis, the photon transfer measured, its sensor profile)}."""
    import numpy as np

    from uwlab.experiments.emva.analysis import characterize
    from uwlab.experiments.emva.simulate import DirectBench
    from uwlab.sim.devices.camera import SimTruth
    from uwlab.sim.scene import RigScene

    realism = RigScene.from_toml(plan.rig_path).sensor_realism()
    profiles = {sweep.sensor_profile: sweep.design.sensor for sweep in plan.sweeps}
    found = {}
    for index, (name, profile) in enumerate(sorted(profiles.items())):
        truth = SimTruth.from_sensor_profile(profile, resolution_px=BENCH_PIXELS, **realism)
        bench = DirectBench(truth, BENCH_RATE_E_S, BENCH_ETA, seed=seed * 1000 + index)
        t_sat_us = truth.saturation_e / BENCH_RATE_E_S * 1e6
        pt = bench.photon_transfer(
            np.linspace(0.01, 1.1, BENCH_STEPS) * t_sat_us, dark_exposures_us=np.linspace(0.01, 1.0, 4) * t_sat_us
        )
        found[name] = (characterize(pt), pt, profile)
    return found


def bench_sheet_info(profile: SensorProfile) -> SheetInfo:
    """The datasheet header of a camera characterised on the simulated bench."""
    from uwlab.experiments.emva.datasheet import SheetInfo

    return SheetInfo(vendor="uwlab (simulated)", model=f"sim {profile.name}", measured="simulated EMVA bench")


def characterise_cameras(plan, out: Path, seed: int = 0) -> dict[str, Path]:
    """Characterise every camera of `plan` on the simulated EMVA bench (`bench_characterisations`) into
    ``out/<camera>/``; returns {camera (sensor profile name): its characterised profile TOML}."""
    from uwlab.experiments.emva.output import output_paths, write_characterization

    out.mkdir()
    found = {}
    for name, (result, pt, profile) in bench_characterisations(plan, seed).items():
        paths = output_paths(out / name, result, name, with_profile=True)
        out.joinpath(name).mkdir()
        write_characterization(
            result, pt, paths, name=name, base=profile, pixel_size_um=None, info=bench_sheet_info(profile)
        )
        assert paths.profile is not None
        found[name] = paths.profile[0]
    return found


def write_inputs(plan_path: Path, world: str | None, directory: Path) -> Path:
    """The plan and its rig with the `world` preset (None: the rig's own; module docstring) written into
    `directory`; the plan's path."""
    plan_raw = read_toml(plan_path, "plan")
    rig_path = resolve_path(plan_raw["rig"], plan_path.resolve().parent)
    raw = read_toml(rig_path, "rig")
    settings = world_settings(raw.get("world"), world)
    rig = resolved_rig(build_design(design_sections(raw), rig_path.parent))
    world_table = {
        **raw.get("world", {}),
        "preset": settings.preset,
        "lens_transmittance_csv": str(resolve_path(settings.lens_transmittance_csv, rig_path.parent)),
    }
    if settings.preset == "turbid":
        rig["water"].update(
            particle_scattering_per_m=settings.particle_b550_per_m,
            particle_scattering_exponent=settings.particle_scattering_exponent,
            particle_phase_function=settings.particle_phase_function,
        )
    directory.mkdir(parents=True)
    (directory / "rig.toml").write_text(tomli_w.dumps({**rig, "sim": raw.get("sim", {}), "world": world_table}))
    (directory / "plan.toml").write_text(tomli_w.dumps({**plan_raw, "rig": "rig.toml"}))
    return directory / "plan.toml"


def run_demo(
    out: Path,
    sweep_progress: Callable | None = None,
    fit_progress: Callable | None = None,
    plan_path: Path | None = None,
    seed: int = 0,
    world: str | None = None,
    model: str | None = None,
    sensors: str = "emva",
) -> dict:
    """Run the campaign into `out` (which must not exist or be empty) in `world`, fit `model` (None: the rig's own
    [world] preset and [model] kind; the demo's rig has the tank world and the extended model) with the cameras
    characterised on the EMVA bench (`sensors` "emva") or their profiles ("profile"), with all simulated noise
    seeded from `seed` (equal seeds, equal numbers); returns the summary written to summary.json."""
    if sensors not in SENSOR_SOURCES:
        raise ConfigError("--sensor", sensors, f"must be one of {', '.join(SENSOR_SOURCES)}")
    if world is not None and world not in PRESETS:
        raise ConfigError("--world", world, f"must be one of {', '.join(PRESETS)}")
    if model is not None and model not in MODELS:
        raise ConfigError("--model", model, f"must be one of {', '.join(MODELS)}")
    out = output_dir(out, "--out", empty=True)
    plan = load_plan(write_inputs(plan_path or config_dir() / DEMO_PLAN, world, out / "inputs"))
    # The geometry (MTF, focus, depth of field) needs the rig alone: it is measured meanwhile, on the core the
    # sweep leaves idle while it waits for the simulated instruments, then beside the characterisation and the fit;
    # its own process (python -m), never a child re-running the caller's script.
    geometry = subprocess.Popen(
        [sys.executable, "-P", "-m", "uwlab.experiments.geometry.tank", "--out", str(out / "geometry")]
        + ["--rig", str(plan.rig_path), "--seed", str(seed)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        # The EMVA bench needs the plan alone too: the cameras are characterised in a thread while the sweep waits.
        with ThreadPoolExecutor(1) as bench:
            characterising = bench.submit(characterise_cameras, plan, out / "emva", seed) if sensors == "emva" else None
            with (
                Dataset.create(out / "dataset", plan.raw, plan_sha256=plan.sha256, sim=True) as dataset,
                SimRig(plan.rig_path, seed=seed) as rig,
            ):
                SweepRunner(plan, dataset, rig, sweep_progress).run()
            characterised = characterising.result() if characterising is not None else {}
        calibration = calibrate(
            out / "dataset",
            None,
            out / "fit",
            progress=fit_progress,
            model=model,
            sensors=[f"{camera}={path}" for camera, path in characterised.items()],
        )
        _, errors = geometry.communicate()
    finally:
        if geometry.poll() is None:
            geometry.kill()
            geometry.wait()
    if geometry.returncode != 0:
        last = (errors or "").strip().splitlines()[-1:] or [f"exit code {geometry.returncode}"]
        raise UwlabError(f"the geometry validation failed: {last[0]}")
    report = write_report(out, out / "report.html")
    summary = demo_summary(calibration.summary, report)
    summary["geometry"] = geometry_summary(out / "geometry")
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary
