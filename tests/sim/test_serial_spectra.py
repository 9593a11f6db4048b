"""Derived spectral quantities against closed forms; Sekonic C-7000 import; spectrum CSV export."""

from __future__ import annotations


import colour
import numpy as np
import pandas as pd
import pytest

from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.spectra import (
    cct_k,
    illuminance_lux,
    irradiance_w_m2,
    read_sekonic_csv,
    spectrum_summary,
    write_spectrum_csv,
)
from uwlab.model.photometry import photon_flux
from tests.support.paths import DATA

H = 6.62607015e-34
C = 299792458.0
C2_M_K = 1.438776877e-2
SEKONIC_SAMPLE = DATA / "sekonic_c7000_synthetic.csv"


def planck(nm: np.ndarray, temperature_k: float) -> np.ndarray:
    """Relative Planck spectral radiance (second radiation constant c2 = hc/k, CODATA 2018)."""
    lam = nm * 1e-9
    return lam**-5 / np.expm1(C2_M_K / (lam * temperature_k))


def test_monochromatic_555_nm_is_683_lux():
    wavelength_nm = np.arange(380.0, 781.0)
    irradiance = np.where(wavelength_nm == 555.0, 1.0, 0.0)
    assert irradiance_w_m2(wavelength_nm, irradiance) == pytest.approx(1.0)
    assert illuminance_lux(wavelength_nm, irradiance) == pytest.approx(683.002, rel=1e-9)
    assert photon_flux(wavelength_nm, irradiance) == pytest.approx(555e-9 / (H * C), rel=1e-9)


def test_flat_spectrum_closed_forms():
    wavelength_nm = np.linspace(400.0, 700.0, 61)
    irradiance = np.full_like(wavelength_nm, 0.02)
    assert irradiance_w_m2(wavelength_nm, irradiance) == pytest.approx(0.02 * 300)
    expected_photons = 0.02 * 1e-9 * (700.0**2 - 400.0**2) / 2 / (H * C)
    assert photon_flux(wavelength_nm, irradiance) == pytest.approx(expected_photons, rel=1e-12)


@pytest.mark.parametrize("temperature_k", [2700.0, 4000.0, 6500.0])
def test_cct_of_planckian_spectrum(temperature_k):
    wavelength_nm = np.arange(360.0, 831.0)
    assert cct_k(wavelength_nm, planck(wavelength_nm, temperature_k)) == pytest.approx(temperature_k, rel=2e-3)


def test_dark_spectrum_has_no_cct():
    wavelength_nm = np.arange(380.0, 781.0)
    summary = spectrum_summary(wavelength_nm, np.zeros_like(wavelength_nm))
    assert summary["cct_k"] is None and summary["illuminance_lux"] == 0.0


def test_illuminance_matches_colour_science():
    wavelength_nm = np.arange(380.0, 781.0)
    irradiance = 1e-3 * planck(wavelength_nm, 3500.0) / planck(np.array([555.0]), 3500.0)
    sd = colour.SpectralDistribution(dict(zip(wavelength_nm, irradiance, strict=True)))
    assert illuminance_lux(wavelength_nm, irradiance) == pytest.approx(colour.luminous_flux(sd, K_m=683.002), rel=1e-3)


def test_sekonic_import_keeps_the_1_nm_block():
    wavelength_nm, irradiance = read_sekonic_csv(SEKONIC_SAMPLE)
    np.testing.assert_array_equal(wavelength_nm, np.arange(380.0, 781.0))
    expected = 1e-3 * planck(wavelength_nm, 3000.0) / planck(np.array([555.0]), 3000.0)
    np.testing.assert_allclose(irradiance, expected, rtol=0, atol=1e-12)
    assert cct_k(wavelength_nm, irradiance) == pytest.approx(3000.0, rel=3e-3)


@pytest.mark.parametrize(
    "content", ["Date Saved,today\nTcp [K],3000\n", "Spectral Data 380[nm],abc\nSpectral Data 381[nm],1\n"]
)
def test_sekonic_import_refuses_other_files(tmp_path, content):
    path = tmp_path / "x.csv"
    path.write_text(content)
    with pytest.raises(ConfigError) as info:
        read_sekonic_csv(path)
    assert info.value.key == "import" and str(path) in str(info.value)


def test_spectrum_csv_round_trip_and_no_overwrite(tmp_path):
    wavelength_nm, irradiance = np.array([400.0, 500.5, 600.0]), np.array([1e-3, 2.5e-2, 0.0])
    path = write_spectrum_csv(tmp_path / "s.csv", wavelength_nm, irradiance)
    table = pd.read_csv(path)
    assert list(table.columns) == ["wavelength_nm", "irradiance_w_m2_nm"]
    np.testing.assert_array_equal(table.to_numpy().T, [wavelength_nm, irradiance])
    with pytest.raises(ConfigError, match="refusing to overwrite"):
        write_spectrum_csv(path, wavelength_nm, irradiance)


def test_summary_refuses_unsorted_wavelengths():
    with pytest.raises(ConfigError):
        spectrum_summary([500.0, 400.0], [1.0, 1.0])
