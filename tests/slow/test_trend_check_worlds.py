"""The within-configuration trend check sees structure the χ² check misses: a tank world whose sensor compresses
its charge by 3 % at full well (the fitted chain is linear) fails it with the drift named, although every
configuration's χ² posterior predictive check passes; the same world without the non-linearity passes it. The
false-alarm and detection rates over 20 seeds: benchmarks/bench_trend_check.py."""

from __future__ import annotations

import pytest

from tests.support.worlds import nonlinear_sensor_rig
from uwlab.experiments.calibration.adequacy import FAMILY_ALPHA, trend_check
from uwlab.experiments.calibration.fit import fit_points
from uwlab.experiments.calibration.simulate import simulate_campaign
from uwlab.experiments.calibration.validation import posterior_predictive_checks

TRUTH = {"light_efficiency": 0.8, "attenuation_scale": 1.2, "K_dn_per_e:imx250m": 0.36, "K_dn_per_e:icx285alm": 1.05}


def checked(tmp_path, nonlinearity: float, seed: int = 3):
    rig = nonlinear_sensor_rig(tmp_path, nonlinearity)
    points, rigs = simulate_campaign(TRUTH, seed=seed, rig=rig, world=None)
    ppc = posterior_predictive_checks(fit_points(points, rigs))
    return ppc, trend_check(ppc)


def test_an_injected_non_linearity_is_named_although_the_chi2_check_passes(tmp_path):
    ppc, check = checked(tmp_path, 0.03)
    assert not check.passed
    assert check.detail.startswith("unmodelled response non-linearity: the residuals drift with exposure")
    assert (ppc["ppc_p"] >= FAMILY_ALPHA / len(ppc)).all()  # the χ² check alone would pass this campaign
    # charge compression: the residuals fall with exposure, by about the injected amount over the sweep
    change = ppc["trend_end_percent"] - ppc["trend_start_percent"]
    assert (change < -1.0).all() and (change > -4.0).all()


@pytest.mark.parametrize("seed", [3, 4])
def test_the_linear_world_passes(tmp_path, seed):
    ppc, check = checked(tmp_path, 0.0, seed)
    assert check.passed, check.detail
    assert (ppc["trend_end_percent"] - ppc["trend_start_percent"]).abs().max() < 0.2
