"""Photometry and light spectra against independent references."""

import colour
import numpy as np
import pytest

from uwlab.model.grid import WavelengthGrid
from uwlab.model.photometry import (
    K_M_LM_PER_W,
    luminous_flux,
    photon_flux,
    photopic_v,
    photopic_v_at,
    radiant_per_lumen,
)
from uwlab.model.spectra import NAMED_SPECTRA, generic_led, relative_spectrum

GRID = WavelengthGrid()


def test_683_lumens_of_555_nm_light_is_one_watt():
    spectrum = np.where(GRID.nm == 555.0, 1.0, 0.0)
    watts = GRID.integrate(683.002 * radiant_per_lumen(spectrum, GRID))
    assert watts == pytest.approx(1.0, rel=1e-12)
    assert photopic_v(GRID)[GRID.nm == 555.0][0] == pytest.approx(1.0)


def test_photopic_table_is_colour_sciences_cie_1924_observer():
    """The V(λ) table in configs/ (read without colour-science, for a fast start-up) equals its source."""
    sd = colour.colorimetry.SDS_LEFS_PHOTOPIC["CIE 1924 Photopic Standard Observer"]
    np.testing.assert_array_equal(photopic_v_at(sd.wavelengths), sd.values)
    assert photopic_v_at(np.array([359.0, 831.0])).tolist() == [0.0, 0.0]


@pytest.mark.parametrize("name", NAMED_SPECTRA)
def test_lumens_watts_lumens_round_trip(name):
    phi_e = 25000.0 * radiant_per_lumen(relative_spectrum(name, GRID), GRID)
    assert luminous_flux(phi_e, GRID) == pytest.approx(25000.0, rel=1e-12)


def test_luminous_efficacy_of_daylight_matches_colour_science():
    """D65's luminous efficacy from colour-science's own routine (an independent implementation)."""
    sd = colour.SDS_ILLUMINANTS["D65"].copy().align(colour.SpectralShape(380, 780, 1))
    expected = colour.luminous_efficacy(sd)
    s = relative_spectrum("daylight", GRID)
    ours = 1.0 / GRID.integrate(radiant_per_lumen(s, GRID))
    assert ours == pytest.approx(expected, rel=2e-3)


def test_generic_led_shape():
    nm = np.arange(380.0, 781.0)
    led = generic_led(nm)
    blue = nm[np.argmax(np.where(nm < 500, led, 0))]
    assert blue == pytest.approx(451, abs=1)
    area = 24.49 + 119.86
    assert np.trapezoid(generic_led(np.arange(0.0, 1500.0)), np.arange(0.0, 1500.0)) == pytest.approx(area, rel=1e-4)


def test_photon_flux_of_monochromatic_irradiance():
    spectrum = np.where(GRID.nm == 500.0, 1.0, 0.0)  # 1 W/m² at 500 nm
    expected = 500e-9 / (6.62607015e-34 * 299792458.0)
    assert photon_flux(GRID.nm, spectrum) == pytest.approx(expected, rel=1e-12)
    assert K_M_LM_PER_W == 683.002


def test_csv_spectrum_errors_name_the_key(tmp_path):
    bad = tmp_path / "s.csv"
    bad.write_text("wavelength_nm,power\n400,1\n")
    from uwlab.errors import ConfigError

    with pytest.raises(ConfigError, match="light.spectrum.*missing column"):
        relative_spectrum(str(bad), GRID)
    with pytest.raises(ConfigError, match="unknown spectrum"):
        relative_spectrum("led-ish", GRID)
