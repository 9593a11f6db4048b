"""`uwlab spectrum --instrument ocean-insight` in-process, on the simulated Flame behind seabreeze's API."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.support.cli import one_line_error
from tests.support.paths import DATA
from tests.support.seabreeze_fake import (
    CC3_AREA_CM2,
    SimulatedDevice,
    fake_seabreeze,
    lamp_counts_per_s,
    lamp_w_m2_nm,
    optical,
)
from uwlab.cli import spectrum as spectrum_cli
from uwlab.cli.main import main
from uwlab.drivers.ocean_insight import device as ocean_device

CALIBRATION = str(DATA / "ocean_insight_calibration_3100k.csv")
BASE = ["spectrum", "--instrument", "ocean-insight", "--calibration", CALIBRATION, "--area-cm2", repr(CC3_AREA_CM2)]


@pytest.fixture
def lamp(monkeypatch) -> SimulatedDevice:
    device = SimulatedDevice()
    device.signal_counts_per_s = lamp_counts_per_s(device)
    monkeypatch.setattr(ocean_device, "seabreeze_spectrometer_class", lambda backend: fake_seabreeze(device))
    return device


def run_json(capsys, *args: str) -> dict:
    assert main([*BASE, *args, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_json_reading_is_the_lamp(lamp, capsys):
    reading = run_json(capsys, "--integration-ms", "10")
    assert {"wavelength_nm", "irradiance_w_m2_nm", "saturated", "integration_ms", "serial"} <= set(reading)
    assert reading["serial"] == "FLMS01234" and reading["integration_ms"] == 10.0 and reading["saturated"] is False
    assert reading["nonlinearity_corrected"] is True and reading["dark"] == "electric"
    wavelength_nm, irradiance = np.array(reading["wavelength_nm"]), np.array(reading["irradiance_w_m2_nm"])
    mask = optical(lamp)
    assert np.max(np.abs(irradiance[mask] / lamp_w_m2_nm(wavelength_nm)[mask] - 1)) < 1e-3
    assert not lamp.is_open  # closed on exit


def test_definition_area_is_the_cc3(lamp, capsys):
    argv = [a for a in BASE if a not in ("--area-cm2", repr(CC3_AREA_CM2))]
    assert main([*argv, "--json"]) == 0
    reading = json.loads(capsys.readouterr().out)
    assert reading["area_cm2"] == 0.1195  # configs/instruments/ocean-insight.toml
    mask = optical(lamp)
    ratio = np.array(reading["irradiance_w_m2_nm"])[mask] / lamp_w_m2_nm(np.array(reading["wavelength_nm"]))[mask]
    np.testing.assert_allclose(ratio, CC3_AREA_CM2 / 0.1195, rtol=1e-3)


def test_auto_integration_reports_its_choice(lamp, capsys):
    reading = run_json(capsys, "--integration-ms", "500", "--auto-integration")
    assert 10.0 < reading["integration_ms"] < 20.0 and reading["saturated"] is False


def test_dark_now_saved_and_reused(lamp, capsys, monkeypatch, tmp_path):
    lamp.dark_pixel_indices, lamp.dark_counts_per_s = [], 5000.0
    prompts = []

    def operator(message: str) -> None:
        prompts.append(message)
        lamp.light_on = "unblock" in message

    monkeypatch.setattr(spectrum_cli, "_confirm", operator)
    dark_file = tmp_path / "dark.csv"
    first = run_json(capsys, "--integration-ms", "10", "--dark-now", "--save-dark", str(dark_file))
    assert prompts == ["block the light to the spectrometer", "unblock the light"] and first["dark"] == "measured"
    second = run_json(capsys, "--integration-ms", "10", "--dark", str(dark_file))
    for reading in (first, second):
        irradiance = np.array(reading["irradiance_w_m2_nm"])
        assert np.max(np.abs(irradiance / lamp_w_m2_nm(np.array(reading["wavelength_nm"])) - 1)) < 1e-3
    err = one_line_error(
        capsys, [*BASE, "--integration-ms", "20", "--dark", str(dark_file), "--out", str(tmp_path / "spectrum.csv")]
    )
    assert "dark" in err and "taken at 10 ms integration, the reading at 20 ms" in err
    assert not (tmp_path / "spectrum.csv").exists() and not lamp.is_open


def test_device_without_electric_dark_needs_a_dark(lamp, capsys):
    lamp.dark_pixel_indices = []
    assert "no electric-dark pixels" in one_line_error(capsys, BASE)


@pytest.mark.parametrize(
    "rows, expected",
    [
        ("400,1e-7\n900,1e-7\n", "covers 400–900 nm, the device 340–1057.41 nm"),
        ("300,1e-7\n700,-2e-7\n1100,1e-7\n", "at 700 nm it is -2e-07"),
        ("300,1e-7\n700,nan\n1100,1e-7\n", "line 3: uJ_per_count = nan is not a finite number"),
    ],
)
def test_bad_calibration_is_one_line_and_nothing_written(lamp, capsys, tmp_path, rows, expected):
    path = tmp_path / "calibration.csv"
    path.write_text("wavelength_nm,uJ_per_count\n" + rows)
    out = tmp_path / "spectrum.csv"
    err = one_line_error(capsys, [*BASE, "--calibration", str(path), "--out", str(out)])
    assert expected in err and not out.exists()
    assert lamp.integration_us is None or not lamp.is_open


def test_no_device_found(monkeypatch, capsys):
    monkeypatch.setattr(ocean_device, "seabreeze_spectrometer_class", lambda backend: fake_seabreeze())
    assert "the first spectrometer: not found" in one_line_error(capsys, BASE)


@pytest.mark.parametrize(
    "extra, key",
    [
        (["--area-cm2", "11.9"], "area_cm2 = 11.9"),  # mm² given as cm²
        (["--integration-ms", "0.1"], "integration_ms = 0.1"),
        (["--save-dark", "new.csv"], "save-dark = 'new.csv': needs --dark-now"),
        (["--dark", "d.csv", "--auto-integration"], "dark"),
    ],
)
def test_bad_options_are_refused_before_the_device_is_opened(lamp, capsys, tmp_path, monkeypatch, extra, key):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "d.csv").write_text("wavelength_nm,dark_counts,integration_ms\n340,1500,10\n")
    assert key in one_line_error(capsys, [*BASE, *extra])
    assert lamp.integration_us is None  # nothing was sent


def test_seabreeze_options_need_instrument(capsys):
    err = one_line_error(capsys, ["spectrum", "--port", "/dev/null", "--calibration", CALIBRATION])
    assert "calibration" in err and "needs --instrument" in err


def test_an_instrument_without_its_calibration_is_refused_before_opening(lamp, capsys):
    err = one_line_error(capsys, ["spectrum", "--instrument", "ocean-insight", "--json"])
    assert "calibration" in err and "uJ_per_count" in err
    assert lamp.integration_us is None and not lamp.is_open
