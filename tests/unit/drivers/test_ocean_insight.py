"""The Ocean Insight driver at the python-seabreeze boundary: a simulated Flame behind seabreeze's own API.

The truth (a 3100 K blackbody of known absolute irradiance, the instrument's energy per count) lives in
tests/support/seabreeze_fake.py, with the counts it gives through the inverse of OceanView's relation
(`lamp_counts_per_s`), computed independently of the driver's helpers (explicit neighbour distances, explicit unit
factors).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.support.paths import DATA
from tests.support.seabreeze_fake import (
    CC3_AREA_CM2,
    SimulatedDevice,
    _mismatches,
    api_mismatches,
    calibration_uj_per_count,
    fake_seabreeze,
    lamp_counts_per_s,
    lamp_w_m2_nm,
    optical,
)
from uwlab.drivers.ocean_insight import device as ocean_device
from uwlab.drivers.ocean_insight import open_ocean_insight, read_calibration
from uwlab.drivers.ocean_insight.radiometry import wavelength_spread_nm
from uwlab.errors import ConfigError, DeviceError
from uwlab.experiments.acquisition.light_calibration import measure_unsaturated

CALIBRATION = DATA / "ocean_insight_calibration_3100k.csv"
TOLERANCE = 1e-3  # the target: within 0.1 % of the independent computation


@pytest.fixture
def lamp_device() -> SimulatedDevice:
    device = SimulatedDevice()
    device.signal_counts_per_s = lamp_counts_per_s(device)
    return device


def open_fake(device: SimulatedDevice, monkeypatch=None, **options):
    if monkeypatch is not None:
        monkeypatch.setattr(ocean_device, "seabreeze_spectrometer_class", lambda backend: fake_seabreeze(device))
    return ocean_device.OceanInsightSpectrometer(
        fake_seabreeze(device).from_serial_number(device.serial),
        read_calibration(CALIBRATION),
        options.pop("area_cm2", CC3_AREA_CM2),
        **options,
    )


def test_the_fake_has_seabreezes_api():
    assert api_mismatches() == []


def test_the_api_check_catches_a_changed_signature():
    class Renamed:
        def intensities(self, correct_dark=False, correct_nonlinearity=False): ...

        def wavelength(self): ...

    from seabreeze.spectrometers import Spectrometer

    problems = _mismatches(Renamed, Spectrometer, "Spectrometer")
    assert any("intensities" in p for p in problems) and any("wavelength:" in p for p in problems)


def test_calibration_file_is_its_documented_formula():
    wavelength_nm, uj_per_count = read_calibration(CALIBRATION)
    assert wavelength_nm[0] == 335 and wavelength_nm[-1] == 1065 and np.all(np.diff(wavelength_nm) == 1)
    np.testing.assert_allclose(uj_per_count, calibration_uj_per_count(wavelength_nm), rtol=1e-15)


def test_wavelength_spread_closed_form():
    i = np.arange(1.0, 9.0)
    spread = wavelength_spread_nm(i**2)  # λ = i²: interior (λ[i+1] − λ[i−1]) / 2 = 2i; ends one-sided
    assert spread[0] == 4 - 1 and spread[-1] == 64 - 49
    np.testing.assert_array_equal(spread[1:-1], 2 * i[1:-1])


def test_blackbody_round_trip_with_electric_dark_and_nonlinearity(lamp_device):
    with open_fake(lamp_device, integration_ms=10.0) as spectrometer:
        wavelength_nm, irradiance = spectrometer.read_spectrum()
        assert spectrometer.nonlinearity_corrected and spectrometer.dark_mode == "electric"
        assert not spectrometer.last_saturated
    mask = optical(lamp_device)
    truth = lamp_w_m2_nm(wavelength_nm)
    assert np.max(np.abs(irradiance[mask] / truth[mask] - 1)) < TOLERANCE
    np.testing.assert_array_equal(irradiance[~mask], 0.0)  # the masked pixels see no light


def test_without_the_nonlinearity_correction_the_peak_reads_low(lamp_device):
    with open_fake(lamp_device, integration_ms=14.0, nonlinearity=False) as spectrometer:
        wavelength_nm, irradiance = spectrometer.read_spectrum()
        assert not spectrometer.nonlinearity_corrected
    mask = optical(lamp_device)
    ratio = irradiance[mask] / lamp_w_m2_nm(wavelength_nm)[mask]
    assert ratio.min() < 0.96  # the simulated detector is 4–5 % sublinear near the top: the correction matters


def test_area_and_integration_scale_as_the_relation_says(lamp_device):
    """Doubling the assumed area halves E; doubling the integration leaves E unchanged (counts double)."""
    with open_fake(lamp_device, integration_ms=5.0, area_cm2=2 * CC3_AREA_CM2) as spectrometer:
        _, half = spectrometer.read_spectrum()
        spectrometer.set_integration_ms(10.0)
        _, half_again = spectrometer.read_spectrum()
    mask = optical(lamp_device)
    truth = lamp_w_m2_nm(lamp_device.wavelength_nm)[mask]
    assert np.max(np.abs(half[mask] / truth - 0.5)) < 0.5 * TOLERANCE
    assert np.max(np.abs(half_again[mask] / truth - 0.5)) < 0.5 * TOLERANCE


def test_measured_dark_round_trip_and_its_integration_must_match(lamp_device):
    lamp_device.dark_pixel_indices = []  # a device without electric-dark pixels
    lamp_device.dark_counts_per_s = 20_000.0  # thermal counts growing with the integration time
    with pytest.raises(ConfigError, match="no electric-dark pixels"):
        open_fake(lamp_device, integration_ms=10.0)
    assert not lamp_device.is_open  # refused and closed
    with open_fake(lamp_device, integration_ms=10.0, dark_mode="measured") as spectrometer:
        lamp_device.light_on = False
        dark = spectrometer.measure_dark()
        lamp_device.light_on = True
        spectrometer.use_dark(dark)
        wavelength_nm, irradiance = spectrometer.read_spectrum()
        spectrometer.set_integration_ms(20.0)
        with pytest.raises(ConfigError, match="dark = 'dark': taken at 10 ms integration, the reading at 20 ms"):
            spectrometer.read_spectrum()
    assert np.max(np.abs(irradiance / lamp_w_m2_nm(wavelength_nm) - 1)) < TOLERANCE


def test_saturation_is_judged_on_raw_counts(lamp_device):
    """A pixel at 99.5 % of full scale reads 1500 counts lower after the electric dark (97.2 %): still saturated."""
    peak = lamp_device.signal_counts_per_s.max()
    lamp_device.nonlinearity_a = None
    target_raw = 0.995 * lamp_device.max_intensity
    lamp_device.signal_counts_per_s = lamp_device.signal_counts_per_s * (target_raw - 1500.0) / (peak * 0.010)
    with open_fake(lamp_device, integration_ms=10.0) as spectrometer:
        spectrometer.read_spectrum()
        assert spectrometer.last_saturated
        spectrometer.set_integration_ms(9.8)  # peak at 97.5 % of full scale
        spectrometer.read_spectrum()
        assert not spectrometer.last_saturated


def test_integration_limits_come_from_the_device_and_nothing_is_sent_outside(lamp_device):
    lamp_device.limits_us = (3800, 10_000_000)  # a Flame-S minimum of 3.8 ms
    with open_fake(lamp_device, integration_ms=10.0) as spectrometer:
        assert spectrometer.integration_ms_limits() == (3.8, 10_000.0)
        with pytest.raises(ConfigError, match=r"integration_ms = 2.0: must be in \[3.8, 10000\] ms"):
            spectrometer.set_integration_ms(2.0)
        with pytest.raises(ConfigError):
            spectrometer.set_integration_ms(math.nan)
        assert lamp_device.integration_us == 10_000 and spectrometer.integration_ms() == 10.0


def test_auto_integration_is_the_longest_under_80_percent(lamp_device):
    with open_fake(lamp_device, integration_ms=2000.0) as spectrometer:  # starts far into saturation
        chosen_ms = spectrometer.auto_integration()
        assert spectrometer.integration_ms() == chosen_ms
    full = lamp_device.max_intensity

    def raw_peak(integration_ms: float) -> float:
        lamp_device.integration_us = int(round(integration_ms * 1000))
        return float(lamp_device.raw().max())

    assert raw_peak(chosen_ms) < 0.8 * full <= raw_peak(chosen_ms * 1.02)


def test_sweep_interface_halves_a_saturated_reading_and_reads_back(lamp_device):
    lamp_device.limits_us = (3800, 10_000_000)
    with open_fake(lamp_device, integration_ms=160.0) as spectrometer:
        spectrometer.set_averaging(4)
        before = lamp_device.acquisitions
        wavelength_nm, irradiance = measure_unsaturated(spectrometer)
        readback = spectrometer.readback()
    assert readback.integration_ms == 20.0 and readback.averaging == 4  # 160 → 80 → 40 → 20 ms
    assert lamp_device.acquisitions - before == 4 * 4
    mask = optical(lamp_device)
    assert np.max(np.abs(irradiance[mask] / lamp_w_m2_nm(wavelength_nm)[mask] - 1)) < TOLERANCE


def test_calibration_must_cover_the_device(lamp_device, tmp_path):
    path = tmp_path / "short.csv"
    path.write_text("wavelength_nm,uJ_per_count\n400,1e-7\n900,1e-7\n")
    with pytest.raises(ConfigError, match="covers 400–900 nm, the device 340–1057.41 nm"):
        ocean_device.OceanInsightSpectrometer(
            fake_seabreeze(lamp_device).from_serial_number(None), read_calibration(path), CC3_AREA_CM2
        )
    assert not lamp_device.is_open


@pytest.mark.parametrize("cell", ["-1e-7", "nan", "0"])
def test_calibration_factors_must_be_positive_and_finite(tmp_path, cell):
    path = tmp_path / "bad.csv"
    path.write_text(f"wavelength_nm,uJ_per_count\n400,1e-7\n500,{cell}\n900,1e-7\n")
    with pytest.raises(ConfigError, match="calibration"):
        read_calibration(path)


def test_no_device_is_a_device_error(monkeypatch, lamp_device):
    monkeypatch.setattr(ocean_device, "seabreeze_spectrometer_class", lambda backend: fake_seabreeze(lamp_device))
    with pytest.raises(DeviceError, match="spectrometer 'USB2H99999': not found"):
        open_ocean_insight("USB2H99999", read_calibration(CALIBRATION), CC3_AREA_CM2)
    monkeypatch.setattr(ocean_device, "seabreeze_spectrometer_class", lambda backend: fake_seabreeze())
    with pytest.raises(DeviceError, match="the first spectrometer: not found"):
        open_ocean_insight(None, read_calibration(CALIBRATION), CC3_AREA_CM2)
