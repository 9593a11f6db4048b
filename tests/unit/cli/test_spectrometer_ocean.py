"""Ocean's own files at the command line, on the simulated Flame: ``uwlab spectrum --calibration *_OOIIrrad.cal``,
``--raw``, ``--sim``, and ``uwlab spectrometer calibrate --lamp FILE.LMP`` (measured, or from OceanView exports).

The truth the code never sees: the simulated instrument's response ``calibration_uj_per_count`` [µJ/count], the
lamp ``lamp_w_m2_nm`` and the bench's collection area (a CC-3) in uwlab/sim/devices/ocean_insight.py.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.support.cli import one_line_error
from tests.support.paths import DATA
from tests.support.seabreeze_fake import (
    CC3_AREA_CM2,
    SimulatedDevice,
    calibration_uj_per_count,
    fake_seabreeze,
    lamp_counts_per_s,
    lamp_w_m2_nm,
    optical,
)
from uwlab.cli import spectrum as spectrum_cli
from uwlab.cli.main import main
from uwlab.drivers.ocean_insight import device as ocean_device
from uwlab.drivers.ocean_insight.files import read_ocean_calibration
from uwlab.drivers.ocean_insight.radiometry import read_calibration

OCEAN_CAL = str(DATA / "FLMS01234_OOIIrrad.cal")
CSV_CAL = str(DATA / "ocean_insight_calibration_3100k.csv")
LAMP = str(DATA / "ocean_insight_lamp_3100k.LMP")
LAMP_EXPORT = str(DATA / "oceanview_lamp_FLMS01234.txt")
DARK_EXPORT = str(DATA / "spectrasuite_dark_FLMS01234.txt")
SPECTRUM = ["spectrum", "--instrument", "ocean-insight"]
CALIBRATE = ["spectrometer", "calibrate", "--lamp", LAMP]
MASKED = slice(2, 18)  # the simulated Flame's electric-dark pixels


def run_json(capsys, argv: list[str]) -> dict:
    assert main([*argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def lamp_error(reading: dict) -> float:
    """Largest relative deviation of a reading from the simulated lamp, over the pixels that see light."""
    wavelength_nm, irradiance = np.array(reading["wavelength_nm"]), np.array(reading["irradiance_w_m2_nm"])
    lit = np.ones(wavelength_nm.size, dtype=bool)
    lit[MASKED] = False
    return float(np.max(np.abs(irradiance[lit] / lamp_w_m2_nm(wavelength_nm[lit]) - 1)))


@pytest.fixture
def lamp(monkeypatch) -> SimulatedDevice:
    device = SimulatedDevice()
    device.signal_counts_per_s = lamp_counts_per_s(device)
    monkeypatch.setattr(ocean_device, "seabreeze_spectrometer_class", lambda backend: fake_seabreeze(device))
    return device


def test_ocean_calibration_and_csv_give_the_same_irradiance(capsys):
    """Target of issue 32: the OOIIrrad.cal (area from its Fiber (micron)) and the CSV (area given) agree within
    0.1 %, and both read the lamp."""
    ocean = run_json(capsys, [*SPECTRUM, "--sim", "--calibration", OCEAN_CAL, "--dark-now"])
    capsys.readouterr()
    csv = run_json(
        capsys, [*SPECTRUM, "--sim", "--calibration", CSV_CAL, "--area-cm2", repr(CC3_AREA_CM2), "--dark-now"]
    )
    assert ocean["area_cm2"] == pytest.approx(CC3_AREA_CM2, rel=1e-12) and ocean["calibration"] == OCEAN_CAL
    lit = np.ones(len(ocean["wavelength_nm"]), dtype=bool)
    lit[MASKED] = False
    ratio = np.array(ocean["irradiance_w_m2_nm"])[lit] / np.array(csv["irradiance_w_m2_nm"])[lit]
    assert np.max(np.abs(ratio - 1)) < 1e-3
    assert lamp_error(ocean) < 1e-3 and lamp_error(csv) < 1e-3


def test_cosine_corrector_agrees_with_the_file_or_is_refused(capsys):
    reading = run_json(capsys, [*SPECTRUM, "--sim", "--calibration", OCEAN_CAL, "--cosine-corrector", "CC-3"])
    assert reading["area_cm2"] == pytest.approx(CC3_AREA_CM2, rel=1e-12)
    err = one_line_error(capsys, [*SPECTRUM, "--sim", "--calibration", OCEAN_CAL, "--cosine-corrector", "CC-3-DA"])
    assert "made with a 0.11946 cm² optic" in err and "a calibration belongs to its optic" in err
    err = one_line_error(capsys, [*SPECTRUM, "--sim", "--calibration", CSV_CAL, "--cosine-corrector", "CC-9"])
    assert "not a known cosine corrector" in err


def test_raw_prints_the_devices_counts(lamp, capsys, tmp_path):
    out = tmp_path / "counts.csv"
    reading = run_json(capsys, [*SPECTRUM, "--raw", "--integration-ms", "20", "--average", "3", "--out", str(out)])
    counts = np.array(reading["counts"])
    # the detector's truth at 20 ms: electric dark 1500 + x / (1 + a x), x = lamp counts/s · T; masked pixels 1500
    x = lamp.signal_counts_per_s * 0.02
    expected = 1500.0 + x / (1 + 1e-6 * x)
    expected[MASKED] = 1500.0
    np.testing.assert_allclose(counts, expected, rtol=1e-12)
    assert reading["saturated"] is False and reading["integration_ms"] == 20 and reading["averaging"] == 3
    assert lamp.acquisitions == 3 and not lamp.is_open
    assert out.read_text().startswith("wavelength_nm,counts\n") and len(out.read_text().splitlines()) == 2049
    text = main([*SPECTRUM, "--raw", "--integration-ms", "20"]), capsys.readouterr().out
    assert text[0] == 0 and "raw counts: 2048 pixels" in text[1] and "% of full scale 65535" in text[1]


def test_raw_refuses_what_it_does_not_use(lamp, capsys):
    err = one_line_error(capsys, [*SPECTRUM, "--raw", "--calibration", CSV_CAL])
    assert "not used with --raw" in err and lamp.integration_us is None


def test_calibrate_on_the_simulated_bench_round_trip(capsys, tmp_path):
    """Calibrate the simulated Flame against the lamp file (the bench is lit by what the file says), then read the
    lamp with the calibration: C recovers the instrument's hidden response, and the reading the lamp, within 1e-6
    (the .cal's 10 significant digits and its Fiber (micron) to 0.1 µm; 3e-10 when this was written)."""
    cal, csv = tmp_path / "flame_OOIIrrad.cal", tmp_path / "flame.csv"
    args = ["--sim", "--cosine-corrector", "CC-3", "--auto-integration", "--out-cal", str(cal), "--out-csv", str(csv)]
    summary = run_json(capsys, [*CALIBRATE, *args])
    assert summary["area_cm2"] == pytest.approx(CC3_AREA_CM2) and summary["fiber_um"] == pytest.approx(3900)
    assert 0.5 < summary["peak_fraction"] < 0.8 and summary["serial"] == "FLMS01234"
    written = read_ocean_calibration(cal)
    assert written.header["Spectrometer"] == "FLMS01234" and written.fibre_um == pytest.approx(3900, abs=0.05)
    lit = np.ones(written.wavelength_nm.size, dtype=bool)
    lit[MASKED] = False
    truth = calibration_uj_per_count(written.wavelength_nm)
    assert np.max(np.abs(written.uj_per_count[lit] / truth[lit] - 1)) < 1e-6
    np.testing.assert_allclose(read_calibration(csv)[1], written.uj_per_count, rtol=1e-9)
    for calibration in (cal, csv):  # the CSV states no area: give the optic (the .cal has its Fiber (micron))
        capsys.readouterr()
        optic = ["--cosine-corrector", "CC-3"] if calibration == csv else []
        argv = [*SPECTRUM, "--sim", "--calibration", str(calibration), *optic, "--dark-now", "--integration-ms", "7"]
        reading = run_json(capsys, argv)
        assert reading["area_cm2"] == pytest.approx(CC3_AREA_CM2, rel=1e-4)
        assert lamp_error(reading) < 1e-6


def test_calibrate_from_oceanview_exports(capsys, tmp_path):
    cal = tmp_path / "export_OOIIrrad.cal"
    args = ["--lamp-spectrum", LAMP_EXPORT, "--dark-spectrum", DARK_EXPORT, "--cosine-corrector", "CC-3"]
    summary = run_json(capsys, [*CALIBRATE, *args, "--out-cal", str(cal)])
    assert summary["integration_ms"] == pytest.approx(10.0) and summary["serial"] == "FLMS01234"
    written = read_ocean_calibration(cal)
    inner = slice(103, 1945)  # inside the tolerated 5 % edges, past the masked pixels
    truth = calibration_uj_per_count(written.wavelength_nm[inner])
    # counts exported with 2 decimals: ≤ 0.01 counts of S − D on ≥ 1900 counts of signal (3e-5 when written)
    assert np.max(np.abs(written.uj_per_count[inner] / truth - 1)) < 1e-4


def test_calibrate_refuses_a_dead_light(lamp, capsys, tmp_path, monkeypatch):
    lamp.signal_counts_per_s = None  # the lamp's light does not reach the optic
    prompts = []
    monkeypatch.setattr(spectrum_cli, "_confirm", prompts.append)
    out = tmp_path / "dead_OOIIrrad.cal"
    err = one_line_error(capsys, [*CALIBRATE, "--out-cal", str(out)])
    assert "no lamp signal above the dark at" in err and not out.exists() and not lamp.is_open
    assert prompts == ["block the light to the spectrometer", "unblock the light"]


def test_calibrate_refuses_a_saturated_lamp(lamp, capsys, tmp_path):
    out = tmp_path / "sat_OOIIrrad.cal"
    err = one_line_error(capsys, [*CALIBRATE, "--integration-ms", "500", "--out-cal", str(out)])
    assert "the lamp saturates the spectrometer" in err and not out.exists()


CAL_HEADER = "Spectrometer:\tFLMS01234\nIntegration Time (sec):\t1.000000E-2\nFiber (micron):\t3900\n"


@pytest.mark.parametrize(
    "name, text, option, expected",
    [
        ("empty_OOIIrrad.cal", CAL_HEADER + "[uJoule/count]\n", "calibration", "no wavelength rows"),
        ("bare_OOIIrrad.cal", CAL_HEADER + "[uJoule/count]\n1e-7\n2e-7\n3e-7\n", "calibration", "no wavelengths"),
        ("twice_OOIIrrad.cal", CAL_HEADER + "[uJoule/count]\n400\t1e-7\n400\t2e-7\n", "calibration", "repeats"),
        ("negative.LMP", "300\t10\n700\t-1\n1100\t10\n", "lamp", "negative irradiance -1 µW/cm²/nm at 700 nm"),
        ("backwards.LMP", "300\t10\n1100\t10\n700\t10\n", "lamp", "wavelength 700 nm is below the previous"),
        ("short.LMP", "400\t10\n900\t10\n", "lamp", "covers 400–900 nm, the spectrometer 340–1057.41 nm"),
        ("headless.txt", "Integration Time (sec): 1E-2\n400\t1\n500\t2\n", "lamp-spectrum", "no >>>>>Begin Spectral"),
    ],
)
def test_bad_files_one_line_exit_2(lamp, capsys, tmp_path, name, text, option, expected):
    path = tmp_path / name
    path.write_text(text)
    out = tmp_path / "out_OOIIrrad.cal"
    if option == "calibration":
        argv = [*SPECTRUM, "--calibration", str(path), "--out", str(tmp_path / "s.csv")]
    elif option == "lamp":
        argv = ["spectrometer", "calibrate", "--lamp", str(path), "--out-cal", str(out)]
    else:
        argv = [*CALIBRATE, "--lamp-spectrum", str(path), "--dark-spectrum", DARK_EXPORT, "--out-cal", str(out)]
    err = one_line_error(capsys, argv)
    assert f"{option} = " in err and expected in err
    assert not out.exists() and not (tmp_path / "s.csv").exists() and not lamp.is_open


def test_exports_at_different_integration_times_are_refused(capsys, tmp_path):
    dark = tmp_path / "dark.txt"
    dark.write_text(
        open(DARK_EXPORT).read().replace("Integration Time (usec): 10000", "Integration Time (usec): 20000")
    )
    err = one_line_error(
        capsys, [*CALIBRATE, "--lamp-spectrum", LAMP_EXPORT, "--dark-spectrum", str(dark), "--out-csv", "x.csv"]
    )
    assert "taken at 0.02 s, the lamp at 0.01 s" in err


def test_outputs_are_never_replaced(lamp, capsys, tmp_path):
    existing = tmp_path / "old_OOIIrrad.cal"
    existing.write_text("keep")
    err = one_line_error(capsys, [*CALIBRATE, "--out-cal", str(existing)])
    assert "--out-cal" in err and existing.read_text() == "keep" and lamp.integration_us is None
    assert "give --out-cal" in one_line_error(capsys, CALIBRATE)


def test_sim_needs_no_device(capsys):
    reading = run_json(capsys, [*SPECTRUM, "--sim", "--raw"])
    assert reading["serial"] == "FLMS01234" and max(reading["counts"]) < 65535
    assert "needs --instrument" in one_line_error(capsys, ["spectrum", "--port", "/dev/null", "--sim"])
    assert optical(SimulatedDevice()).sum() == 2048 - 16
