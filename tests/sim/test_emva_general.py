"""EMVA 1288 Release 4.0 General (the black-box model) against the simulated sensor's truth: a camera whose signal is
compressed quadratically (β = 0.25 at the full well) and a linear one. Referred to the input, the general model must
find the sensor's own responsivity in the dark R_d = K η, its input SNR (the linear closed form, eq. 21: the noise
is added before the non-linearity), and DSNU, PRNU, dark noise and dark current in photons."""

import math

import numpy as np
import pytest
from scipy.interpolate import BSpline

from uwlab.sim.devices.camera import SimTruth
from uwlab.errors import ConfigError
from uwlab.experiments.emva.analysis import characterize
from uwlab.experiments.frames.nonuniformity import white_noise_gain
from uwlab.experiments.emva.regression import bspline_regression
from uwlab.experiments.emva.simulate import DirectBench
from uwlab.model.sensor import load_sensor_profile

RATE_E_S, ETA, DARK_E_S, DSNU, PRNU = 1.07e5, 0.6, 200.0, 1.5, 1.0
# logarithmic steps from SNR_p < 1 (General D.1: the exposure steps should reach SNR_p ≈ 1), then linear ones
EXPOSURES_US = np.r_[np.geomspace(20, 2e3, 15), np.linspace(2.5e3, 115e3, 45)]


def bench(beta: float, seed: int) -> DirectBench:
    truth = SimTruth.from_sensor_profile(
        load_sensor_profile("imx250m"),
        resolution_px=(96, 96),
        dark_current_e_per_s=DARK_E_S,
        dsnu_e=DSNU,
        prnu_percent=PRNU,
        nonlinearity=beta,
    )
    return DirectBench(truth, RATE_E_S, ETA, seed=seed)


def measured(beta: float, seed: int = 3):
    b = bench(beta, seed)
    pt = b.photon_transfer(
        EXPOSURES_US, dark_exposures_us=np.linspace(1e5, 6e5, 6), stack_exposure_us=50e3, stack_frames=16
    )
    return b.truth, pt


@pytest.fixture(scope="module")
def nonlinear():
    truth, pt = measured(0.25)
    return truth, characterize(pt, "general").values


def mu_p_min_closed_form(truth: SimTruth) -> float:
    """Release 4.0 Linear eq. 26 of the underlying sensor at the shortest exposure (20 µs)."""
    k = truth.K_dn_per_e
    dark_var = k**2 * (truth.dark_noise_e**2 + DARK_E_S * 20e-6) + 1 / 12
    return (math.sqrt(dark_var / k**2 + 0.25) + 0.5) / ETA


def test_responsivity_in_the_dark_and_threshold(nonlinear):
    truth, v = nonlinear
    assert v["model"] == "general" and v["K_dn_per_e"] is None and v["quantum_efficiency"] is None
    assert v["responsivity_dark_dn_per_photon"] == pytest.approx(truth.K_dn_per_e * ETA, rel=0.01)
    assert v["sensitivity_threshold_photons"] == pytest.approx(mu_p_min_closed_form(truth), rel=0.03)
    assert v["dynamic_range"] == pytest.approx(v["saturation_photons"] / v["sensitivity_threshold_photons"])


def test_quantities_in_photons(nonlinear):
    truth, v = nonlinear
    gain = math.sqrt(white_noise_gain())
    assert v["dsnu_p"] == pytest.approx(DSNU / ETA * gain, rel=0.05)  # eq. 58
    assert v["prnu_percent"] == pytest.approx(PRNU * gain, rel=0.05)  # eq. 59: the input-referred PRNU
    assert v["dark_current_p_per_s"] == pytest.approx(DARK_E_S / ETA, rel=0.02)  # eq. 24
    assert v["dark_noise_p"] == pytest.approx(truth.dark_noise_e / ETA, rel=0.04)  # eq. 50 at t_exp → 0


def test_input_snr_is_the_sensors_own(nonlinear):
    """SNR_p = (μ_p/σ_y) ∂μ_y/∂μ_p (eq. 10) undoes the compression: it follows eq. 21 of the linear sensor inside."""
    truth, pt = measured(0.25, seed=4)
    result = characterize(pt, "general")
    c = result.curves
    upto = slice(5, c["sat"] + 1)
    p = c["photons"][upto]
    e_dark = truth.dark_noise_e**2 + DARK_E_S * pt.exposure_s[upto]
    expected = ETA * p / np.sqrt(ETA * p + e_dark + (1 / 12) / truth.K_dn_per_e**2)
    assert np.median(np.abs(c["snr_p"][upto] / expected - 1)) < 0.02
    # the output SNR does not: by eq. 10 it is larger by μ_y/(μ_p ∂μ_y/∂μ_p) = (1 − βu)/(1 − 2βu), u = μ_e/e_sat
    sat = c["sat"]
    u = ETA * c["photons"][sat] / truth.saturation_e
    assert c["snr_y"][sat] / c["snr_p"][sat] == pytest.approx((1 - 0.25 * u) / (1 - 0.5 * u), rel=0.05)


def test_general_model_of_a_linear_camera_agrees_with_the_linear_model():
    _, pt = measured(0.0, seed=5)
    lin, gen = characterize(pt, "linear").values, characterize(pt, "general").values
    assert gen["responsivity_dark_dn_per_photon"] == pytest.approx(lin["responsivity_dn_per_photon"], rel=0.01)
    assert gen["sensitivity_threshold_photons"] == pytest.approx(lin["sensitivity_threshold_photons"], rel=0.03)
    assert gen["saturation_photons"] == lin["saturation_photons"]
    assert gen["dsnu_p"] == pytest.approx(lin["dsnu_e"] / lin["quantum_efficiency"], rel=0.02)


def test_bspline_regression_reproduces_a_cubic_and_its_slope():
    """Eq. 44–48: a cubic polynomial lies in the spline space, so the regression and its derivative are exact; the
    basis is the B-splines of degree 3 on uniform knots (scipy's, independently of eq. 45 as written here)."""
    x = np.linspace(0, 10, 40)
    y = 0.5 * x**3 - 2 * x**2 + x + 3
    intervals = 4
    spline = bspline_regression(x, y, intervals)
    np.testing.assert_allclose(spline(x), y, atol=1e-9)
    np.testing.assert_allclose(spline.slope(x), 1.5 * x**2 - 4 * x + 1, atol=1e-8)
    step = 10 / intervals
    knots = (np.arange(intervals + 7) - 3) * step
    reference = BSpline(knots, spline.coefficients, 3)
    np.testing.assert_allclose(reference(x), spline(x), atol=1e-9)
    np.testing.assert_allclose(reference.derivative()(x), spline.slope(x), atol=1e-8)


def test_bspline_needs_enough_points():
    with pytest.raises(ConfigError, match="B-spline"):
        bspline_regression(np.arange(5.0), np.arange(5.0), 4)
