"""Ocean Insight's own files read as shipped: OOIIrrad.cal, .LMP, OceanView and SpectraSuite exports
(tests/data, synthetic files of the simulated Flame whose truth is in uwlab/sim/devices/ocean_insight.py)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.support.paths import DATA
from tests.support.seabreeze_fake import CC3_AREA_CM2, calibration_uj_per_count, lamp_w_m2_nm
from uwlab.drivers.ocean_insight.files import (
    cosine_corrector_area_cm2,
    read_lamp,
    read_ocean_calibration,
    read_oceanview_spectrum,
    write_calibration_csv,
    write_ocean_calibration,
)
from uwlab.drivers.ocean_insight.radiometry import (
    irradiance_w_m2_nm,
    lamp_calibration,
    read_calibration,
    read_calibration_file,
)
from uwlab.errors import ConfigError
from uwlab.sim.devices.ocean_insight import flame_wavelengths_nm

OCEAN_CAL = DATA / "FLMS01234_OOIIrrad.cal"
LAMP = DATA / "ocean_insight_lamp_3100k.LMP"


def test_ocean_calibration_is_the_instruments_response():
    cal = read_ocean_calibration(OCEAN_CAL)
    assert cal.header["Spectrometer"] == "FLMS01234" and cal.header["Integration Time (sec)"] == "1.000000E-2"
    np.testing.assert_allclose(cal.wavelength_nm, flame_wavelengths_nm(), atol=5e-7)
    np.testing.assert_allclose(cal.uj_per_count, calibration_uj_per_count(cal.wavelength_nm), rtol=1e-9)
    assert cal.fibre_um == 3900 and cal.area_cm2 == pytest.approx(CC3_AREA_CM2, rel=1e-12)


def test_uncalibrated_ends_are_outside_the_calibration(tmp_path):
    """Ocean's files write 0 where the lamp did not calibrate: the calibration spans the factors between."""
    path = tmp_path / "ends_OOIIrrad.cal"
    path.write_text(CAL_HEADER + "[uJoule/count]\n250\t0\n300\t1e-7\n700\t2e-7\n900\t0\n950\t0\n")
    cal = read_ocean_calibration(path)
    assert cal.wavelength_nm.tolist() == [300, 700] and cal.uj_per_count.tolist() == [1e-7, 2e-7]


def test_header_keys_with_or_without_colon(tmp_path):
    path = tmp_path / "x.IrradCal"  # SpectraSuite's name for the same layout: found by its marker line
    path.write_text("Date:\tMon Jan 05 10:21:07 CET 2026\nFiber (micron)\t600\n[uJoule/count]\n400\t1e-7\n500\t1e-7\n")
    cal = read_calibration_file(path)
    assert cal.area_cm2 == pytest.approx(2.82743e-3, rel=1e-5)  # a 600 µm core
    assert read_ocean_calibration(path).header["Date"] == "Mon Jan 05 10:21:07 CET 2026"


def test_either_layout_through_one_reader():
    ocean, csv = read_calibration_file(OCEAN_CAL), read_calibration_file(DATA / "ocean_insight_calibration_3100k.csv")
    assert ocean.area_cm2 == pytest.approx(CC3_AREA_CM2) and csv.area_cm2 is None
    np.testing.assert_array_equal(read_calibration(OCEAN_CAL)[1], ocean.uj_per_count)


def test_lamp_file_is_the_lamp():
    wavelength_nm, uw_cm2_nm = read_lamp(LAMP)
    assert wavelength_nm[0] == 300 and wavelength_nm[-1] == 1100 and wavelength_nm.size == 801
    np.testing.assert_allclose(uw_cm2_nm, lamp_w_m2_nm(wavelength_nm) * 100, rtol=1e-6)  # 1 W/m² = 100 µW/cm²


def test_exports_of_both_programs():
    lamp = read_oceanview_spectrum(DATA / "oceanview_lamp_FLMS01234.txt")
    dark = read_oceanview_spectrum(DATA / "spectrasuite_dark_FLMS01234.txt")
    assert lamp.integration_s == pytest.approx(0.01) and dark.integration_s == pytest.approx(0.01)  # sec / usec
    assert lamp.values.size == dark.values.size == 2048 and lamp.header["Spectrometer"] == "FLMS01234"
    np.testing.assert_array_equal(lamp.wavelength_nm, dark.wavelength_nm)
    np.testing.assert_allclose(dark.values[100:], 1500.0 + 400.0 * 0.01, atol=0.005)  # electric + thermal dark


def test_cosine_corrector_areas():
    assert cosine_corrector_area_cm2("cc-3") == pytest.approx(CC3_AREA_CM2, rel=1e-12)
    assert cosine_corrector_area_cm2("CC-3-DA") == pytest.approx(0.4004, abs=1e-4)  # 7.14 mm
    with pytest.raises(ConfigError, match="not a known cosine corrector"):
        cosine_corrector_area_cm2("CC-9")


def test_written_files_read_back(tmp_path):
    wavelength_nm = np.array([400.0, 401.5, 403.25])
    factor = np.array([1.234567891e-7, 2.5e-7, 3.75e-7])
    header = {"Spectrometer": "FLMS01234", "Fiber (micron)": "400.0"}
    write_ocean_calibration(tmp_path / "x_OOIIrrad.cal", wavelength_nm, factor, header)
    back = read_ocean_calibration(tmp_path / "x_OOIIrrad.cal")
    np.testing.assert_allclose(back.uj_per_count, factor, rtol=1e-9)
    assert back.area_cm2 == pytest.approx(np.pi * 0.02**2)  # 400 µm core
    write_calibration_csv(tmp_path / "x.csv", wavelength_nm, factor, ["a comment"])
    np.testing.assert_array_equal(read_calibration(tmp_path / "x.csv")[1], factor)  # CSV keeps every digit
    with pytest.raises(ConfigError, match="refusing to overwrite"):
        write_calibration_csv(tmp_path / "x.csv", wavelength_nm, factor, [])


def test_lamp_calibration_inverts_the_relation():
    """C from a lamp reading, then the lamp read with C: the relation and its inverse close on the lamp."""
    wavelength_nm = flame_wavelengths_nm(64) + 100
    lamp = (np.array([300.0, 1200.0]), np.array([5.0, 15.0]))  # µW/cm²/nm, linear
    truth = 2e-7 * (1 + wavelength_nm / 1000)
    spread = np.gradient(wavelength_nm)
    lamp_on_pixels = 5.0 + 10.0 * (wavelength_nm - 300.0) / 900.0
    signal = lamp_on_pixels * 0.5 * spread / truth * 0.02  # E · A · dλ / C · T, A = 0.5 cm², T = 20 ms
    factor = lamp_calibration(wavelength_nm, signal, 0.02, 0.5, lamp)
    np.testing.assert_allclose(factor, truth, rtol=1e-12)
    irradiance = irradiance_w_m2_nm(signal, 0.0, factor, 0.02, 0.5, wavelength_nm)
    np.testing.assert_allclose(irradiance, lamp_on_pixels * 0.01, rtol=1e-12)


def test_lamp_calibration_refuses_a_dead_light_and_short_lamps():
    wavelength_nm = np.linspace(400.0, 700.0, 100)
    lamp = (np.array([300.0, 1200.0]), np.array([5.0, 15.0]))
    signal = np.full(100, 1000.0)
    signal[50] = -2.0  # a pixel without signal in the middle of the array
    with pytest.raises(ConfigError, match="no lamp signal above the dark at 1 of 100 pixels"):
        lamp_calibration(wavelength_nm, signal, 0.01, 0.1, lamp)
    signal[50], signal[2] = 1000.0, 0.0  # at the edge: tolerated, given the nearest pixel's factor
    factor = lamp_calibration(wavelength_nm, signal, 0.01, 0.1, lamp)
    assert factor[2] in (factor[1], factor[3])
    with pytest.raises(ConfigError, match="no lamp signal"):
        lamp_calibration(wavelength_nm, np.zeros(100), 0.01, 0.1, lamp)
    with pytest.raises(ConfigError, match="covers 450–1200 nm, the spectrometer 400–700 nm"):
        lamp_calibration(wavelength_nm, np.full(100, 1000.0), 0.01, 0.1, (np.array([450.0, 1200.0]), lamp[1]))


CAL_HEADER = "Spectrometer:\tFLMS01234\nIntegration Time (sec):\t1.000000E-2\nFiber (micron):\t3900\n"


@pytest.mark.parametrize(
    "reader, text, expected",
    [
        (read_ocean_calibration, CAL_HEADER + "[uJoule/count]\n", "no wavelength rows after [uJoule/count]"),
        (read_ocean_calibration, CAL_HEADER + "400\t1e-7\n500\t1e-7\n", "no [uJoule/count] line"),
        (read_ocean_calibration, CAL_HEADER + "[uJoule/count]\n400\t1e-7\n400\t1e-7\n", "400 nm repeats"),
        (read_ocean_calibration, CAL_HEADER + "[uJoule/count]\n500\t1e-7\n400\t1e-7\n", "400 nm is below the"),
        (read_ocean_calibration, CAL_HEADER + "[uJoule/count]\n1e-7\n2e-7\n", "no wavelengths: its 2 rows hold one"),
        (read_ocean_calibration, CAL_HEADER + "[uJoule/count]\n400\t1e-7\n450\t0\n500\t1e-7\n", "at 450 nm it is 0"),
        (read_ocean_calibration, CAL_HEADER + "[uJoule/count]\n400\t1e-7\n450\t-1e-7\n", "at 450 nm it is -1e-07"),
        (read_ocean_calibration, CAL_HEADER + "[uJoule/count]\n400\t0\n450\t0\n", "every µJ/count factor is 0"),
        (read_ocean_calibration, "Fiber (micron):\t3.9\n[uJoule/count]\n400\t1e-7\n500\t1e-7\n", "diameter in µm"),
        (read_lamp, "400\t10.0\n500\t-0.5\n", "negative irradiance -0.5 µW/cm²/nm at 500 nm"),
        (read_lamp, "400\t10.0\nabc\t1\n", "line 2: 'abc\\t1' is not a wavelength"),
        (read_oceanview_spectrum, "Spectrometer: FLMS01234\n400\t100\n500\t200\n", "no >>>>>Begin Spectral Data"),
    ],
)
def test_bad_files_name_what_is_wrong(tmp_path, reader, text, expected):
    path = tmp_path / "file"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        reader(path)
    assert expected in str(info.value)
