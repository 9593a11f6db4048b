"""`uwlab light`, `uwlab light calibrate`, `uwlab spectrum` and `uwlab sim serial` end to end."""

from __future__ import annotations

import json
import os
import signal
import subprocess

import numpy as np
import pytest

from uwlab.cli.main import main
from uwlab.drivers.serial import open_light, open_spectrometer
from uwlab.sim.rig_state import RigState
from uwlab.sim.scene import RigScene
from uwlab.sim.devices.serial_sim import SerialRig, SerialSimSettings
from uwlab.experiments.acquisition.light_calibration import load_light_calibration
from uwlab.experiments.acquisition.spectra import irradiance_w_m2

from tests.support.cli import one_line_error
from tests.support.cli_process import read_line, uwlab
from tests.support.paths import DATA

GAMMA = 1.8
SEKONIC_SAMPLE = DATA / "sekonic_c7000_synthetic.csv"
SPECTRUM_KEYS = {
    "wavelength_nm",
    "irradiance_w_m2_nm",
    "irradiance_w_m2",
    "illuminance_lux",
    "photon_flux_m2_s",
    "cct_k",
    "saturated",
}


def flat_spectrum(position: str, flux_fraction: float):
    """0.2 W/m²/nm from 400 to 700 nm at full flux: 60 W/m²."""
    wavelength_nm = np.arange(380.0, 781.0)
    return wavelength_nm, np.where((wavelength_nm >= 400) & (wavelength_nm <= 700), 0.2 * flux_fraction, 0.0)


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    with SerialRig(
        tmp_path_factory.mktemp("cli"), SerialSimSettings(light_gamma=GAMMA), spectrum=flat_spectrum, seed=3
    ) as rig:
        yield rig


def run_json(capsys, argv: list[str]) -> dict:
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert out.count("\n") == 1
    return json.loads(out)


def test_light_cli_sets_and_reads_back(rig, capsys):
    port = rig.ports["light"]
    state = run_json(capsys, ["light", "--port", port, "--on", "--level", "0.25", "--json"])
    assert state == {"port": port, "identity": "UWLAB,SIM-LIGHT,0001,1.0", "on": True, "level": 0.25}
    assert RigState(rig.rig_state_path).light.flux_fraction == pytest.approx(0.25**GAMMA)
    assert run_json(capsys, ["light", "--port", port, "--off", "--json"])["on"] is False
    assert "level = 1.5" in one_line_error(capsys, ["light", "--port", port, "--level", "1.5"])
    assert "--port" in one_line_error(capsys, ["light"])


def test_spectrum_cli_measures_and_writes_csv(rig, capsys, tmp_path):
    run_json(capsys, ["light", "--port", rig.ports["light"], "--on", "--level", "1", "--json"])
    out = tmp_path / "spectrum.csv"
    summary = run_json(
        capsys,
        [
            "spectrum",
            "--port",
            rig.ports["spectrometer"],
            "--integration-ms",
            "50",
            "--average",
            "2",
            "--out",
            str(out),
            "--json",
        ],
    )
    assert set(summary) == SPECTRUM_KEYS and summary["saturated"] is False
    assert summary["irradiance_w_m2"] == pytest.approx(60.0, rel=0.01)
    assert len(summary["wavelength_nm"]) == len(summary["irradiance_w_m2_nm"]) == 401
    assert out.read_text().startswith("wavelength_nm,irradiance_w_m2_nm\n")
    assert "refusing to overwrite" in one_line_error(
        capsys, ["spectrum", "--port", rig.ports["spectrometer"], "--out", str(out)]
    )
    # 500 ms: the peak (~0.2 W/m²/nm at 1e6 counts per W/m²/nm/s) exceeds the 65535-count full scale
    assert (
        run_json(capsys, ["spectrum", "--port", rig.ports["spectrometer"], "--integration-ms", "500", "--json"])[
            "saturated"
        ]
        is True
    )
    assert main(["spectrum", "--port", rig.ports["spectrometer"], "--integration-ms", "500"]) == 0
    assert "saturated       yes" in capsys.readouterr().out
    assert "integration_ms" in one_line_error(
        capsys, ["spectrum", "--port", rig.ports["spectrometer"], "--integration-ms", "0.1"]
    )


def test_spectrum_cli_imports_sekonic(capsys):
    summary = run_json(capsys, ["spectrum", "--import", str(SEKONIC_SAMPLE), "--json"])
    assert set(summary) == SPECTRUM_KEYS and summary["saturated"] is None  # the export does not say
    assert summary["wavelength_nm"][:2] == [380.0, 381.0] and len(summary["wavelength_nm"]) == 401
    assert summary["cct_k"] == pytest.approx(3000.0, rel=3e-3)


def test_light_calibrate_curve_file_and_no_overwrite(rig, capsys, tmp_path):
    run_json(capsys, ["light", "--port", rig.ports["light"], "--on", "--level", "0.3", "--json"])
    out = tmp_path / "cal.csv"
    argv = [
        "light",
        "calibrate",
        "--light",
        rig.ports["light"],
        "--spectrometer",
        rig.ports["spectrometer"],
        "--levels",
        "5",
        "--out",
        str(out),
        "--json",
    ]
    result = run_json(capsys, argv)
    assert result["level"] == [0.0, 0.25, 0.5, 0.75, 1.0]
    irradiance = np.array(result["irradiance_w_m2"])
    assert np.all(np.diff(irradiance) > 0)
    dark = irradiance[0]
    np.testing.assert_allclose(
        (irradiance - dark) / (irradiance[-1] - dark), np.array(result["level"]) ** GAMMA, atol=0.01
    )
    calibration = load_light_calibration(out)
    np.testing.assert_array_equal(calibration.level, result["level"])
    np.testing.assert_array_equal(calibration.irradiance_w_m2, irradiance)
    assert calibration.irradiance_w_m2_nm.shape == (5, 401)
    np.testing.assert_allclose(
        [irradiance_w_m2(calibration.wavelength_nm, e) for e in calibration.irradiance_w_m2_nm], irradiance, rtol=1e-12
    )
    with open_light(rig.ports["light"]) as light:
        assert light.output() is True and light.level() == 0.3
    before = out.read_bytes()
    assert "refusing to overwrite" in one_line_error(capsys, argv)
    assert out.read_bytes() == before


def test_light_calibrate_refuses_a_light_that_does_not_reach_the_spectrometer(rig, capsys, tmp_path):
    """The spectrometer capped (``SIM:BLOCK ON``): the same dark at every level is no calibration; nothing is
    written and the light is back as it was."""
    run_json(capsys, ["light", "--port", rig.ports["light"], "--on", "--level", "0.3", "--json"])
    out = tmp_path / "cal.csv"
    argv = ["light", "calibrate", "--light", rig.ports["light"], "--spectrometer", rig.ports["spectrometer"]]
    with open_spectrometer(rig.ports["spectrometer"]) as spectrometer:
        spectrometer.transport.command("SIM:BLOCK ON")
    try:
        error = one_line_error(capsys, [*argv, "--levels", "3", "--out", str(out)])
    finally:
        with open_spectrometer(rig.ports["spectrometer"]) as spectrometer:
            spectrometer.transport.command("SIM:BLOCK OFF")
    assert "level 1 reads" in error and "and level 0" in error and "no response above the dark's noise" in error
    assert not out.exists()
    with open_light(rig.ports["light"]) as light:
        assert light.output() is True and light.level() == 0.3
    assert main([*argv, "--levels", "3", "--out", str(out)]) == 0  # unblocked, the same light is a calibration
    assert load_light_calibration(out).irradiance_w_m2[-1] == pytest.approx(60.0, rel=0.01)


def test_sim_serial_bad_config_is_one_line(capsys, tmp_path):
    missing = str(tmp_path / "none.toml")
    assert missing in one_line_error(capsys, ["sim", "serial", "--config", missing])


def test_sim_serial_subprocess_ports_work_and_sigterm_cleans_up():
    process = uwlab("sim", "serial", "--json")
    try:
        info = json.loads(read_line(process.stdout, 120, "uwlab sim serial"))
        assert list(info)[:2] == ["light", "spectrometer"]
        scene = RigScene.from_toml(None)
        expected = irradiance_w_m2(*scene.spectral_irradiance("target", 1.0))
        with open_light(info["light"]) as light, open_spectrometer(info["spectrometer"]) as spectrometer:
            light.set_output(True)
            light.set_level(1.0)
            spectrometer.set_integration_ms(10)
            spectrometer.set_averaging(4)
            full = irradiance_w_m2(*spectrometer.read_spectrum())
            light.set_level(0.5)
            half = irradiance_w_m2(*spectrometer.read_spectrum())
            light.set_output(False)
            dark = irradiance_w_m2(*spectrometer.read_spectrum())
        assert full - dark == pytest.approx(expected, rel=0.01)
        assert (half - dark) / (full - dark) == pytest.approx(0.5**scene.sim.light_gamma, rel=0.02)
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=30) == 0
        assert not any(os.path.lexists(info[key]) for key in ("light", "spectrometer", "rig_state"))
        assert process.stdout.read() == ""
    finally:
        if process.poll() is None:
            process.terminate()
            try:
                process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait(timeout=30)
        process.stdout.close()
        process.stderr.close()
