"""The model's band for a sweep plan before it runs (`uwlab.experiments.calibration.planned`, the rig console's
predicted band): the points a simulated run of the plan records — the simulator's truth, which the prediction never
sees — fall inside the band from the design's priors; `uwlab fit` of those points gives a band that holds them too
and is far narrower; a fit of other configurations, or no fit directory, is refused in one line."""

from __future__ import annotations

import numpy as np
import pytest

import uwlab
from tests.support.paths import ROOT
from tests.support.plans import CAMPAIGN_DEFAULTS, CAMPAIGN_SWEEPS, record, write_plan
from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.plan import load_plan
from uwlab.experiments.acquisition.sim_rig import SimRig
from uwlab.experiments.calibration.planned import predicted_bands

DIMMED = 0.35  # the simulated light's output there is 0.35^2.2 of full (its dimming curve, which the model lacks)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A small plan (two lenses, 8 exposures each, the second with the light dimmed to level 0.35), its simulated
    run and a short `uwlab fit` of that run."""
    folder = tmp_path_factory.mktemp("planned")
    sweeps = [CAMPAIGN_SWEEPS[0], {**CAMPAIGN_SWEEPS[1], "light_level": DIMMED}]
    plan = load_plan(write_plan(folder / "plan.toml", "planned-band", sweeps, defaults=CAMPAIGN_DEFAULTS))
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
    full, dimmed = (s["id"] for s in CAMPAIGN_SWEEPS)
    assert band["source"] == "design" and [c["sweep_id"] for c in band["configurations"]] == [full]
    assert band["skipped"][dimmed].startswith("light level 0.35: the light's level-to-output curve is not modelled")
    for configuration in band["configurations"]:
        lo, median, hi = (np.asarray(configuration[k]) for k in ("lo", "median", "hi"))
        assert np.all(lo <= median) and np.all(median <= hi) and np.all(hi <= configuration["clip_signal_dn"])
        assert min(configuration["exposure_us"]) == 20 and max(configuration["exposure_us"]) == 1500
    (ok,) = inside(band, points).values()
    assert ok.size >= 5 and ok.all()


def test_a_fit_of_the_run_gives_a_narrower_band_that_holds_its_points(run):
    plan, points, fit_dir = run
    design, fitted = predicted_bands(plan), predicted_bands(plan, fit_dir)
    assert fitted["source"] == f"fit: {fit_dir}" and not fitted["skipped"]
    # The dimmed sweep too: the light's output at level 0.35 as the fit's dataset measured it (spectrometer).
    assert [c["sweep_id"] for c in fitted["configurations"]] == [s["id"] for s in CAMPAIGN_SWEEPS]
    for sweep_id, ok in inside(fitted, points).items():
        assert ok.size >= 5 and ok.mean() >= 0.8, sweep_id  # a 95 % band of a new measurement; a short fit
    for a in fitted["configurations"]:
        mine = points[(points["sweep_id"] == a["sweep_id"]) & ~points["saturated"].astype(bool)]
        _, median, _ = band_at(a, mine["exposure_us"].to_numpy(float))
        signal = mine["signal_dn"].to_numpy(float)
        # Within a few per cent where the signal is well above the few DN of offset and quantisation.
        assert (signal > 20).sum() >= 5 and np.allclose(signal[signal > 20], median[signal > 20], rtol=0.05)
    for a, b in zip(fitted["configurations"], design["configurations"], strict=False):
        unclipped = np.asarray(b["hi"]) < b["clip_signal_dn"]
        fit_width, design_width = (np.log(np.asarray(c["hi"]) / np.asarray(c["lo"]))[unclipped] for c in (a, b))
        assert unclipped.sum() > 10 and np.all(fit_width < 0.2 * design_width), a["sweep_id"]


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
    # Its sweeps at full light (the 12 mm lens on each camera); the dimmed ones need a fit of them.
    assert {c["sweep_id"] for c in band["configurations"]} == {"imx250-12mm-f4", "icx285-12mm-f4"}
    assert all(why.startswith("light level") for why in band["skipped"].values()) and len(band["skipped"]) == 4
    for configuration in band["configurations"]:
        median = np.asarray(configuration["median"])
        assert np.all(np.isfinite(median)) and np.all(np.diff(median) >= 0)  # more exposure, no less signal
