"""The model's band for a sweep plan before it runs (`uwlab.experiments.calibration.planned`, the rig console's
predicted band): the points a simulated run of the plan records — the simulator's truth, which the prediction never
sees — fall inside the band from the design's priors; `uwlab fit` of those points gives a band that holds them too
and is far narrower; a fit of other configurations, or no fit directory, is refused in one line."""

from __future__ import annotations

import numpy as np
import pytest

import uwlab
from tests.support.paths import ROOT
from tests.support.plans import CAMPAIGN_SWEEPS, record, write_campaign, write_plan, CAMPAIGN_DEFAULTS
from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.plan import load_plan
from uwlab.experiments.acquisition.sim_rig import SimRig
from uwlab.experiments.calibration.planned import predicted_bands


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A small plan (two lenses, 8 exposures each), its simulated run and a short `uwlab fit` of that run."""
    folder = tmp_path_factory.mktemp("planned")
    plan = load_plan(write_campaign(folder / "plan.toml", "planned-band"))
    with SimRig(plan.rig_path, seed=5) as rig:
        data = record(plan, folder / "run", rig)
    uwlab.fit(folder / "run", out=folder / "fit", max_steps=1000, chunk_steps=500, progress=False)
    return plan, data.points(), folder / "fit"


def band_at(configuration: dict, exposure_us: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The band's lo, median and hi at ``exposure_us`` (linear in log-log between its dense exposures: the
    response is a power of the exposure there)."""
    x = np.log(configuration["exposure_us"])
    at = lambda key: np.exp(np.interp(np.log(exposure_us), x, np.log(configuration[key])))  # noqa: E731
    return at("lo"), at("median"), at("hi")


def inside(band: dict, points) -> dict[str, np.ndarray]:
    """Per sweep: whether each unsaturated measured point lies inside its configuration's band."""
    out = {}
    for configuration in band["configurations"]:
        mine = points[(points["sweep_id"] == configuration["sweep_id"]) & ~points["saturated"].astype(bool)]
        lo, _, hi = band_at(configuration, mine["exposure_us"].to_numpy(float))
        signal = mine["signal_dn"].to_numpy(float)
        out[configuration["sweep_id"]] = (signal >= lo) & (signal <= hi)
    return out


def test_the_points_of_a_simulated_run_fall_inside_the_design_band(run):
    plan, points, _ = run
    band = predicted_bands(plan)
    assert band["source"] == "design" and [c["sweep_id"] for c in band["configurations"]] == [
        s["id"] for s in CAMPAIGN_SWEEPS
    ]
    for configuration in band["configurations"]:
        lo, median, hi = (np.asarray(configuration[k]) for k in ("lo", "median", "hi"))
        assert np.all(lo <= median) and np.all(median <= hi) and np.all(hi <= configuration["clip_dn"])
        assert min(configuration["exposure_us"]) == 20 and max(configuration["exposure_us"]) == 1500
    for sweep_id, ok in inside(band, points).items():
        assert ok.size >= 5 and ok.all(), sweep_id


def test_a_fit_of_the_run_gives_a_narrower_band_that_holds_its_points(run):
    plan, points, fit_dir = run
    design, fitted = predicted_bands(plan), predicted_bands(plan, fit_dir)
    assert fitted["source"] == f"fit: {fit_dir}"
    for sweep_id, ok in inside(fitted, points).items():
        assert ok.mean() >= 0.8, sweep_id  # a 95 % band of a new measurement, from a short (1000-step) fit
    for a, b in zip(fitted["configurations"], design["configurations"], strict=True):
        unclipped = np.asarray(b["hi"]) < b["clip_dn"]
        fit_width, design_width = (np.log(np.asarray(c["hi"]) / np.asarray(c["lo"]))[unclipped] for c in (a, b))
        assert unclipped.sum() > 10 and np.all(fit_width < 0.2 * design_width), a["sweep_id"]
        # The fitted median follows the measured points to within a few per cent.
        mine = points[(points["sweep_id"] == a["sweep_id"]) & ~points["saturated"].astype(bool)]
        _, median, _ = band_at(a, mine["exposure_us"].to_numpy(float))
        assert np.allclose(mine["signal_dn"].to_numpy(float), median, rtol=0.05)


def test_a_fit_of_other_configurations_or_no_fit_is_refused(run, tmp_path):
    _, _, fit_dir = run
    other = load_plan(
        write_plan(
            tmp_path / "other.toml",
            "other-lens",
            [{**CAMPAIGN_SWEEPS[0], "id": "f28", "lens": {"focal_length_mm": 30, "f_number": 2.8}}],
            defaults=CAMPAIGN_DEFAULTS,
        )
    )
    with pytest.raises(ConfigError, match=r"no configuration imx250m 30.0 mm f/2.8 \(sweep f28\)"):
        predicted_bands(other, fit_dir)
    with pytest.raises(ConfigError, match="not a directory"):
        predicted_bands(other, tmp_path / "missing")


def test_the_shipped_tank_plan_is_predicted_bare_sensor_and_lenses_alike():
    band = predicted_bands(load_plan(ROOT / "configs" / "plans" / "tank-exposure-sweep.toml"), samples=200)
    assert len(band["configurations"]) == 6 and not band["skipped"]
    for configuration in band["configurations"]:
        median = np.asarray(configuration["median"])
        assert np.all(np.isfinite(median)) and np.all(np.diff(median) >= 0)  # more exposure, no less signal
