"""EMVA 1288 analysis: closed forms, exact recovery from noiseless model statistics, streaming statistics,
and bad input."""
import math
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from scipy.optimize import brentq

from uwlab.errors import ConfigError
from uwlab.experiments.emva.analysis import (
    PhotonTransfer,
    characterize,
    fit_line,
    line_posterior,
    photons_per_pixel,
)
from uwlab.experiments.emva.from_dataset import photon_transfer_from_points
from uwlab.experiments.emva.stream import StackAccumulator, stack_statistics
from uwlab.model.photometry import C_M_S, H_J_S, photon_flux, photons_per_joule

K, ETA, SIGMA_D, SAT_E, DARK_E_S, OFFSET = 0.5, 0.6, 3.0, 8000.0, 100.0, 40.0


def model_transfer(n=40, with_spatial=True) -> PhotonTransfer:
    """Noise-free EMVA statistics of a linear camera; the variance collapses past saturation."""
    t = np.linspace(0.001, 0.02, n)
    photons = 1.0e6 * t  # 1000 .. 20000 photons, saturation at 13333
    mu_e = np.minimum(ETA * photons, SAT_E)
    sat = ETA * photons > SAT_E
    dark_mean = OFFSET + K * DARK_E_S * t
    dark_var = K**2 * (SIGMA_D**2 + DARK_E_S * t) + 1 / 12
    var = np.where(sat, 0.1, dark_var + K**2 * mu_e)
    dsnu_dn2, prnu = (K * 2.0) ** 2, 0.01
    signal = K * mu_e
    return PhotonTransfer(
        photons=photons, exposure_s=t, mean_dn=dark_mean + signal, temporal_var_dn2=var,
        spatial_var_dn2=dsnu_dn2 + (prnu * signal) ** 2 + var / 4 if with_spatial else np.full(n, np.nan),
        frames=np.full(n, 4.0), dark_mean_dn=dark_mean, dark_temporal_var_dn2=dark_var,
        dark_spatial_var_dn2=dsnu_dn2 + dark_var / 4, dark_frames=np.full(n, 4.0),
        dark_exposure_s=t, dark_series_mean_dn=dark_mean, dark_series_var_dn2=dark_var, bit_depth=12,
    )


def test_photon_irradiance_closed_forms():
    # a flat 1 W/m²/nm spectrum over 400-600 nm: ∫ λ/(hc) dλ = (600² - 400²)/2 nm² · 1e-9 / (h c)
    nm = np.linspace(400, 600, 2001)
    expected = (600**2 - 400**2) / 2 * 1e-9 / (H_J_S * C_M_S)
    assert photon_flux(nm, np.ones_like(nm)) == pytest.approx(expected, rel=1e-9)
    assert photons_per_joule(500.0) == pytest.approx(500e-9 / (H_J_S * C_M_S))
    assert photons_per_pixel(1e18, 0.01, (3.45e-6) ** 2) == pytest.approx(1e18 * 0.01 * 3.45e-6**2)


def test_fit_line_exact_and_noisy():
    x = np.arange(1.0, 11.0)
    exact = fit_line(x, 3.0 * x + 2.0)
    assert (exact.slope, exact.intercept) == pytest.approx((3.0, 2.0))
    assert exact.slope_std == pytest.approx(0.0, abs=1e-9)
    rng = np.random.default_rng(1)
    y = 3.0 * x + rng.normal(0, 0.5, x.size)
    fit = fit_line(x, y, through_origin=True)
    slope_std = math.sqrt(np.sum((y - fit.slope * x) ** 2) / (x.size - 1) / np.sum(x**2))
    assert fit.slope == pytest.approx(np.sum(x * y) / np.sum(x * x))
    assert fit.slope_std == pytest.approx(slope_std)
    samples = line_posterior(x, y, through_origin=True, seed=3)[:, 0]
    assert np.mean(samples) == pytest.approx(fit.slope, abs=2 * fit.slope_std)
    assert np.std(samples) == pytest.approx(fit.slope_std, rel=0.35)


def test_stack_statistics_closed_form():
    rng = np.random.default_rng(0)
    frames = [rng.integers(0, 4096, (16, 24), dtype=np.uint16) for _ in range(5)]
    frames[4][0, :3] = 4095
    stats = stack_statistics(iter(frames), 4095)
    stack = np.array(frames, float)
    pairs = [np.var(stack[0] - stack[1]) / 2, np.var(stack[2] - stack[3]) / 2]
    assert stats.frames == 5
    assert stats.mean_dn == pytest.approx(stack.mean())
    assert stats.temporal_var_dn2 == pytest.approx(np.mean(pairs))
    assert stats.spatial_var_dn2 == pytest.approx(stack.mean(axis=0).var(ddof=1))
    assert stats.saturated_fraction == pytest.approx(np.any(stack == 4095, axis=0).mean())


def test_stack_statistics_needs_a_pair():
    acc = StackAccumulator(255)
    acc.add(np.zeros((4, 4), np.uint8))
    with pytest.raises(ConfigError, match="frames"):
        acc.result()


def test_exact_model_is_recovered():
    v = characterize(model_transfer()).values
    assert v["K_dn_per_e"] == pytest.approx(K, rel=1e-9)
    assert v["quantum_efficiency"] == pytest.approx(ETA, rel=1e-9)
    assert v["dark_noise_e"] == pytest.approx(SIGMA_D, rel=1e-9)
    assert v["dark_current_e_per_s"] == pytest.approx(DARK_E_S, rel=1e-9)
    assert v["dark_current_var_e_per_s"] == pytest.approx(DARK_E_S, rel=1e-9)
    assert v["dsnu_e"] == pytest.approx(2.0, rel=1e-9)
    assert v["prnu_percent"] == pytest.approx(1.0, rel=1e-9)
    assert v["linearity_error_percent"] == pytest.approx(0.0, abs=1e-9)
    assert v["dark_offset_dn"] == pytest.approx(OFFSET)
    # saturation: the last point below the full well (maximum variance)
    photons = 1.0e6 * np.linspace(0.001, 0.02, 40)
    assert v["saturation_e"] == pytest.approx(ETA * photons[ETA * photons <= SAT_E].max())
    assert v["snr_max_db"] == pytest.approx(10 * math.log10(v["saturation_e"]))
    # μ_p,min: where the linear model's SNR (Release 4.0 Linear eq. 21) of the true camera reaches 1
    snr = lambda mu_p: ETA * mu_p / math.sqrt(SIGMA_D**2 + (1 / 12) / K**2 + ETA * mu_p) - 1.0  # noqa: E731
    mu_p_min = brentq(snr, 1e-3, 1e3, xtol=1e-12)
    assert v["sensitivity_threshold_photons"] == pytest.approx(mu_p_min, rel=1e-9)
    assert v["dynamic_range_db"] == pytest.approx(20 * math.log10(v["saturation_photons"] / mu_p_min), rel=1e-9)
    assert v["K_dn_per_e_std"] == pytest.approx(0.0, abs=1e-9)


def test_small_dark_variance_is_raised_to_the_quantisation_floor():
    pt = model_transfer()
    tiny = np.full_like(pt.dark_series_var_dn2, 0.1)
    v = characterize(replace(pt, dark_series_var_dn2=tiny, dark_temporal_var_dn2=tiny)).values
    assert v["dark_noise_e"] == pytest.approx(math.sqrt(0.24 - 1 / 12) / v["K_dn_per_e"], rel=1e-6)


def test_nonlinearity_shows_in_the_linearity_error():
    pt = model_transfer()
    signal = pt.mean_dn - pt.dark_mean_dn
    bent = pt.dark_mean_dn + signal * (1 - 0.02 * signal / signal.max())
    assert characterize(replace(pt, mean_dn=bent)).values["linearity_error_percent"] > 0.2


def test_too_few_points_in_the_fit_range():
    pt = model_transfer(n=4)
    with pytest.raises(ConfigError, match="too few points in the fit range"):
        characterize(pt)


def _points_frame(pt: PhotonTransfer) -> pd.DataFrame:
    n = len(pt.photons)
    return pd.DataFrame({
        "sweep_id": "s", "point_index": np.arange(n), "kind": "exposure", "exposure_us": pt.exposure_s * 1e6,
        "light_on": True, "frames": 4, "bit_depth": 12, "mean_dn": pt.mean_dn, "temporal_var_dn2": pt.temporal_var_dn2,
        "spatial_var_dn2": pt.spatial_var_dn2, "dark_mean_dn": pt.dark_mean_dn,
        "dark_temporal_var_dn2": pt.dark_temporal_var_dn2, "dark_spatial_var_dn2": pt.dark_spatial_var_dn2,
        "dark_frames": 4, "gain_db": 0.0, "sensor_profile": "imx250m", "camera_id": "c0", "light_level": 1.0,
        "irradiance_w_m2": 0.5, "irradiance_position": "camera", "roi_w": 64, "roi_h": 64,
    })


EMPTY_SPECTRA = pd.DataFrame(columns=["sweep_id", "point_index", "position", "wavelength_nm", "irradiance_w_m2_nm"])


def test_points_table_to_photons():
    pt = model_transfer()
    got = photon_transfer_from_points(_points_frame(pt), EMPTY_SPECTRA, wavelength_nm=550.0)
    expected = 0.5 * photons_per_joule(550.0) * pt.exposure_s * (3.45e-6) ** 2
    np.testing.assert_allclose(got.photons, expected, rtol=1e-12)
    with pytest.raises(ConfigError, match="--wavelength-nm"):
        photon_transfer_from_points(_points_frame(pt), EMPTY_SPECTRA)


def test_bad_tables_name_the_problem():
    pt = model_transfer()
    frame = _points_frame(pt)
    with pytest.raises(ConfigError, match="dark_temporal_var_dn2"):
        photon_transfer_from_points(frame.drop(columns=["dark_temporal_var_dn2"]), EMPTY_SPECTRA, wavelength_nm=550)
    no_dark = frame.assign(dark_mean_dn=np.nan)
    with pytest.raises(ConfigError, match="no dark frames"):
        photon_transfer_from_points(no_dark, EMPTY_SPECTRA, wavelength_nm=550)
    at_target = frame.assign(irradiance_position="target")
    with pytest.raises(ConfigError, match="irradiance at the sensor"):
        photon_transfer_from_points(at_target, EMPTY_SPECTRA, wavelength_nm=550)
    with pytest.raises(ConfigError, match="--sweep"):
        photon_transfer_from_points(frame, EMPTY_SPECTRA, sweep_id="other", wavelength_nm=550)


def test_a_variance_outlier_below_saturation_is_not_the_saturation_point():
    """A disturbed frame pair at low signal can show a variance above the true peak; saturation stays put."""
    pt = model_transfer()
    clean = characterize(pt).values
    spiked = pt.temporal_var_dn2.copy()
    spiked[3] = 10 * spiked.max()
    v = characterize(replace(pt, temporal_var_dn2=spiked)).values
    assert v["saturation_index"] == clean["saturation_index"]
    assert v["saturation_photons"] == clean["saturation_photons"] == pytest.approx(SAT_E / ETA, rel=0.05)


def test_sensitivity_threshold_is_where_the_snr_is_one():
    """μ_p,min solves η μ_p / √(σ²_y,dark/K² + η μ_p) = 1, and DR is μ_p,sat over it."""
    v = characterize(model_transfer()).values
    eta, k, mu = v["quantum_efficiency"], v["K_dn_per_e"], v["sensitivity_threshold_photons"]
    dark_var = max(v["dark_var_dn2"], 0.24)
    assert eta * mu / math.sqrt(dark_var / k**2 + eta * mu) == pytest.approx(1.0, rel=1e-12)
    assert v["dynamic_range_db"] == pytest.approx(20 * math.log10(v["saturation_photons"] / mu), rel=1e-12)
    assert v["sensitivity_threshold_e"] == pytest.approx(eta * mu, rel=1e-12)
