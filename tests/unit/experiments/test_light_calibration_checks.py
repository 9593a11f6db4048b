"""`light calibrate` refuses what is not a calibration: spectra from the simulated spectrometer's count model
(`DetectorModel`: shot, dark and read noise, an imperfect dark) for lights whose truth the checks cannot see — a
gamma-law light, a dead one, one under stray light, one that droops at the top — and the noise estimate against the
count model's closed-form standard deviation."""

from __future__ import annotations

import numpy as np
import pytest

from uwlab.experiments.acquisition.light_calibration import (
    NotACalibration,
    _calibration,
    calibration_levels,
    check_calibration,
    integrated_noise_w_m2,
)
from uwlab.experiments.acquisition.spectra import irradiance_w_m2
from uwlab.sim.devices.serial_instruments import DetectorModel

WAVELENGTH_NM = np.arange(380.0, 781.0)
LAMP = np.where((WAVELENGTH_NM >= 400) & (WAVELENGTH_NM <= 700), 0.2, 0.0)  # 60 W/m² at full flux
INTEGRATION_S = 0.1
DETECTOR = DetectorModel()
WHITE_LED = 0.2 * np.exp(-0.5 * ((WAVELENGTH_NM - 450) / 10) ** 2) + 0.15 * np.exp(
    -0.5 * ((WAVELENGTH_NM - 570) / 50) ** 2
)


def measured(flux_fractions, extra=0.0, seed=7):
    """The light calibration the spectrometer reports for these flux fractions (plus `extra` W/m²/nm of light that
    does not come from the light)."""
    rng = np.random.default_rng(seed)
    spectra = [DETECTOR.measure(f * LAMP + extra, INTEGRATION_S, 1, rng)[0] for f in flux_fractions]
    levels = calibration_levels(len(flux_fractions))
    return _calibration(levels, WAVELENGTH_NM, np.array(spectra))


@pytest.mark.parametrize("spectrum", [np.zeros_like(LAMP), LAMP, WHITE_LED])
def test_noise_estimate_is_the_count_model_standard_deviation(spectrum):
    sigma_nm = DETECTOR.expected_sigma_w_m2_nm(spectrum, INTEGRATION_S, 1)
    weights = np.full_like(WAVELENGTH_NM, 1.0)
    weights[[0, -1]] = 0.5  # the trapezoid's on a 1 nm grid
    truth = float(np.sqrt(np.sum((weights * sigma_nm) ** 2)))
    rng = np.random.default_rng(11)
    estimates = [
        integrated_noise_w_m2(WAVELENGTH_NM, DETECTOR.measure(spectrum, INTEGRATION_S, 1, rng)[0]) for _ in range(20)
    ]
    assert np.mean(estimates) == pytest.approx(truth, rel=0.1)


def test_a_gamma_law_light_is_a_calibration():
    calibration = measured(calibration_levels(5) ** 2.2)
    check_calibration(calibration)
    assert calibration.irradiance_w_m2[-1] == pytest.approx(60.0, rel=0.01)


def test_a_dead_light_has_no_response():
    calibration = measured(np.zeros(5))
    with pytest.raises(NotACalibration, match=r"level 1 reads .* and level 0 .*no response above the dark's noise"):
        check_calibration(calibration)


def test_a_dead_light_under_stray_light_has_no_response():
    """The issue's case: 12.4 W/m² at every level, the light not reaching the spectrometer."""
    calibration = measured(np.zeros(5), extra=12.44 / 400)
    assert irradiance_w_m2(WAVELENGTH_NM, calibration.irradiance_w_m2_nm[0]) == pytest.approx(12.5, rel=0.01)
    with pytest.raises(NotACalibration, match="no response"):
        check_calibration(calibration)


def test_stray_light_at_level_zero_is_not_dark():
    calibration = measured(calibration_levels(5) ** 2.2, extra=0.01)  # 4 W/m²: 7 % of the light's 60
    with pytest.raises(NotACalibration, match=r"level 0 reads 4\.\d+ W/m², 6\.\d% .* level 1 .*not dark"):
        check_calibration(calibration)
    check_calibration(measured(calibration_levels(5) ** 2.2, extra=0.0005))  # 0.2 W/m²: 0.3 %, a calibration


def test_a_light_that_droops_at_the_top_is_not_monotonic():
    calibration = measured([0.0, 0.3, 0.6, 0.9, 0.8])
    with pytest.raises(NotACalibration, match=r"falls from 5\d\.\d+ W/m² at level 0\.75 to 4\d\.\d+ W/m² at level 1"):
        check_calibration(calibration)


def test_a_flat_top_within_the_noise_is_a_calibration():
    check_calibration(measured([0.0, 0.5, 1.0, 1.0, 1.0]))
