"""The within-configuration trend check sees structure the χ² check misses: a tank world whose sensor compresses
its charge by 3 % at full well (the fitted chain is linear) fails it with the drift named, although every
configuration's χ² posterior predictive check passes; the same world without the non-linearity passes it; and the
same campaign fitted with each camera as characterised on the simulated EMVA bench (`uwlab fit --sensor`: the
measured response curve in the forward model) passes it, its trends within 0.1 %. The false-alarm and detection
rates over 20 seeds: benchmarks/bench_trend_check.py."""

from __future__ import annotations

import numpy as np
import pytest

from tests.support.worlds import nonlinear_sensor_rig
from uwlab.experiments.calibration.adequacy import FAMILY_ALPHA, trend_check
from uwlab.experiments.calibration.fit import (
    DISCREPANCIES,
    Posterior,
    default_config_for,
    fit_points,
    sampling_coordinates,
    start_mode,
)
from uwlab.experiments.calibration.forward import build_forward_model
from uwlab.experiments.calibration.pipeline import with_characterised_sensors
from uwlab.experiments.emva.analysis import characterize
from uwlab.experiments.emva.profile import profile_documents
from uwlab.experiments.emva.simulate import DirectBench
from uwlab.model.sensor import load_sensor_profile
from uwlab.sim.devices.camera import SimTruth
from uwlab.experiments.calibration.simulate import simulate_campaign
from uwlab.experiments.calibration.validation import posterior_predictive_checks

TRUTH = {"light_efficiency": 0.8, "attenuation_scale": 1.2, "K_dn_per_e:imx250m": 0.36, "K_dn_per_e:icx285alm": 1.05}


def checked(tmp_path, nonlinearity: float, seed: int = 3, characterised: dict | None = None):
    rig = nonlinear_sensor_rig(tmp_path, nonlinearity)
    points, rigs = simulate_campaign(TRUTH, seed=seed, rig=rig, world=None)
    rigs = with_characterised_sensors(rigs, points, [f"{c}={p}" for c, p in (characterised or {}).items()])
    config = default_config_for(points[~points["saturated"]], rigs)
    ppc = posterior_predictive_checks(fit_points(points, rigs, config))
    return ppc, trend_check(ppc)


def bench_profiles(folder, nonlinearity: float) -> dict:
    """Each camera of the campaign (its profile, the campaign's K truth, the non-linearity) characterised on the
    simulated EMVA bench; {camera: profile TOML}."""
    found = {}
    for camera in ("imx250m", "icx285alm"):
        base = load_sensor_profile(camera)
        truth = SimTruth.from_sensor_profile(
            base, resolution_px=(64, 64), nonlinearity=nonlinearity, K_dn_per_e=TRUTH[f"K_dn_per_e:{camera}"]
        )
        t_sat_us = truth.saturation_e / 1e5 * 1e6
        pt = DirectBench(truth, 1e5, 0.6, seed=5).photon_transfer(
            np.linspace(0.01, 1.1, 40) * t_sat_us, dark_exposures_us=np.linspace(0.01, 1.0, 4) * t_sat_us
        )
        toml, csv = profile_documents(
            characterize(pt).values,
            name=camera,
            width_px=64,
            height_px=64,
            exposure_range_us=(10, 1e6),
            pixel_size_um=None,
            base=base,
        )
        (folder / f"{camera}.toml").write_text(toml)
        (folder / f"{camera}_qe.csv").write_text(csv)
        found[camera] = folder / f"{camera}.toml"
    return found


def test_the_bench_measures_the_response_and_the_gain_at_zero_signal(tmp_path):
    for camera, path in bench_profiles(tmp_path, 0.03).items():
        profile = load_sensor_profile(str(path))
        curve = profile.response
        # charge compression β u: c(u) = 1 − β u, with u of the measured (compressed) saturation capacity
        assert curve.a == pytest.approx(-0.03, abs=0.004) and abs(curve.b) < 0.004
        assert np.sqrt(curve.covariance[0][0]) < 0.002
        # the photon-transfer K is biased low by the compression; referred to zero signal it is the truth
        truth = TRUTH[f"K_dn_per_e:{camera}"]
        assert profile.K_dn_per_e < 0.98 * truth
        assert curve.zero_signal_gain(profile.K_dn_per_e) == pytest.approx(truth, rel=0.01)


def test_fitted_with_the_characterised_sensors_the_drift_is_gone(tmp_path):
    ppc, check = checked(tmp_path, 0.03, characterised=bench_profiles(tmp_path, 0.03))
    assert check.passed, check.detail
    assert (ppc["trend_end_percent"] - ppc["trend_start_percent"]).abs().max() < 0.1


def test_an_injected_non_linearity_is_named_although_the_chi2_check_passes(tmp_path):
    ppc, check = checked(tmp_path, 0.03)
    assert not check.passed
    assert check.detail.startswith("unmodelled response non-linearity (or the light drifting during the sweep)")
    assert "the residuals drift with exposure" in check.detail
    assert (ppc["ppc_p"] >= FAMILY_ALPHA / len(ppc)).all()  # the χ² check alone would pass this campaign
    # charge compression: the residuals fall with exposure, by about the injected amount over the sweep
    change = ppc["trend_end_percent"] - ppc["trend_start_percent"]
    assert (change < -1.0).all() and (change > -4.0).all()


def test_the_linear_worlds_mode_at_both_discrepancies_bound_keeps_the_scale_conditioned_coordinates(tmp_path):
    """Seed 4 of the linear world: the model describes it exactly, and the start's search ends with both
    discrepancies at zero (1e-18 and below). The τ-conditioned coordinates are still built there (the Laplace
    approximations' stencils are centred inside the support: `uwlab.experiments.calibration.laplace`); when they
    were not, the fit ran in the funnel, 11,750 steps where it now takes 3,000."""
    rig = nonlinear_sensor_rig(tmp_path, 0.0)
    points, rigs = simulate_campaign(TRUTH, seed=4, rig=rig, world=None)
    used = points[~points["saturated"]]
    config = default_config_for(used, rigs)
    post = Posterior(build_forward_model(used, rigs, config.names), config.priors)
    u_mode = start_mode(post, config.priors)
    assert np.all(post.to_theta(u_mode)[[config.names.index(n) for n in DISCREPANCIES]] < 1e-6)
    assert sampling_coordinates(post, config.priors, u_mode) is not None


@pytest.mark.parametrize("seed", [3, 4])
def test_the_linear_world_passes(tmp_path, seed):
    ppc, check = checked(tmp_path, 0.0, seed)
    assert check.passed, check.detail
    assert (ppc["trend_end_percent"] - ppc["trend_start_percent"]).abs().max() < 0.2
