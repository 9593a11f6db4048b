"""Drivers against the simulators through real pseudo-terminals and pyserial: round trips, spectra, faults."""

from __future__ import annotations

import termios

import numpy as np
import pytest

from uwlab.drivers.serial import open_light, open_spectrometer
from uwlab.drivers.serial.base import LightReadback
from uwlab.sim.rig_state import RigState
from uwlab.sim.devices.serial_instruments import DetectorModel
from uwlab.sim.devices.serial_sim import SerialRig, SerialSimSettings
from uwlab.errors import ConfigError, DeviceError
from uwlab.experiments.acquisition.light_calibration import measure_unsaturated

GAMMA = 2.2
PEAK_W_M2_NM = 0.3
CAMERA_FACTOR = 0.3
TIMEOUT_S = 0.75


def known_spectrum(position: str, flux_fraction: float):
    """A Gaussian at 550 nm (σ 40 nm), 0.3 W/m²/nm at full flux on the target, 30 % of it at the camera."""
    wavelength_nm = np.arange(350.0, 801.0, 0.5)
    scale = PEAK_W_M2_NM * flux_fraction * (CAMERA_FACTOR if position == "camera" else 1.0)
    return wavelength_nm, scale * np.exp(-0.5 * ((wavelength_nm - 550.0) / 40.0) ** 2)


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    with SerialRig(
        tmp_path_factory.mktemp("serial"),
        SerialSimSettings(light_gamma=GAMMA),
        spectrum=known_spectrum,
        seed=7,
        command_log=True,
    ) as rig:
        yield rig


@pytest.fixture
def light(rig):
    with open_light(rig.ports["light"], timeout_s=TIMEOUT_S) as light:
        light.transport.command("SIM:FAULT NONE")
        light.set_output(True)
        light.set_level(1.0)
        yield light


@pytest.fixture
def spectrometer(rig):
    with open_spectrometer(rig.ports["spectrometer"], timeout_s=TIMEOUT_S) as spectrometer:
        spectrometer.transport.command("SIM:FAULT NONE")
        spectrometer.transport.command("SIM:POS target")
        spectrometer.set_integration_ms(20)
        spectrometer.set_averaging(1)
        yield spectrometer


def received(rig, name: str) -> list[str]:
    return rig.log_path(name).read_text().splitlines()


def test_identity_and_round_trips(light, spectrometer):
    assert light.identity().startswith("UWLAB,SIM-LIGHT")
    for level in (0.0, 0.125, 0.7, 1.0):
        light.set_level(level)
        assert light.level() == level
    light.set_output(False)
    assert light.output() is False
    light.set_output(True)
    assert light.output() is True
    for integration_ms, averaging in ((1.0, 1), (12.5, 3), (250.0, 100)):
        spectrometer.set_integration_ms(integration_ms)
        spectrometer.set_averaging(averaging)
        assert (spectrometer.integration_ms(), spectrometer.averaging()) == (integration_ms, averaging)


def test_light_writes_rig_state(rig, light):
    light.set_level(0.5)
    state = RigState(rig.rig_state_path).light
    assert state.on and state.level == 0.5 and state.flux_fraction == pytest.approx(0.5**GAMMA)


def test_spectrum_equals_injected_spectrum_within_noise(light, spectrometer):
    spectrometer.set_integration_ms(50)
    spectrometer.set_averaging(4)
    wavelength_nm, measured = spectrometer.read_spectrum()
    true = np.interp(wavelength_nm, *known_spectrum("target", 1.0))
    detector = DetectorModel()
    sigma = detector.expected_sigma_w_m2_nm(true, 0.05, 4)
    z = (measured - true - detector.dark_residual_w_m2_nm(0.05)) / sigma
    assert wavelength_nm[0] == 380.0 and wavelength_nm[-1] == 780.0 and len(wavelength_nm) == 401
    assert not spectrometer.last_saturated
    assert np.max(np.abs(z)) < 6 and abs(np.mean(z)) < 0.3 and 0.8 < np.std(z) < 1.2


def test_dimming_the_light_changes_what_the_spectrometer_reads(light, spectrometer):
    spectrometer.set_averaging(4)
    full = spectrometer.read_spectrum()[1].sum()
    light.set_level(0.5)
    half = spectrometer.read_spectrum()[1].sum()
    light.set_output(False)
    dark = spectrometer.read_spectrum()[1].sum()
    assert (half - dark) / (full - dark) == pytest.approx(0.5**GAMMA, rel=0.02)
    assert abs(dark) < 0.05 * full
    light.set_output(True)
    light.set_level(1.0)
    spectrometer.transport.command("SIM:POS camera")
    camera = spectrometer.read_spectrum()[1].sum()
    assert (camera - dark) / (full - dark) == pytest.approx(CAMERA_FACTOR, rel=0.02)


def test_saturation_reported_and_autoranged(light, spectrometer):
    spectrometer.set_integration_ms(400)
    spectrometer.read_spectrum()
    assert spectrometer.last_saturated
    measure_unsaturated(spectrometer)
    assert not spectrometer.last_saturated and spectrometer.integration_ms() == 200


def test_out_of_range_never_sent(rig, light, spectrometer):
    for call, value in (
        (light.set_level, 1.5),
        (light.set_level, -0.01),
        (spectrometer.set_integration_ms, 0.2),
        (spectrometer.set_integration_ms, 1e5),
        (spectrometer.set_averaging, 0),
    ):
        with pytest.raises(ConfigError):
            call(value)
    assert light.level() == 1.0 and spectrometer.averaging() == 1
    sent = received(rig, "light") + received(rig, "spectrometer")
    assert not any(
        line.startswith(("LEV 1.5", "LEV -0.01", "SPEC:INT 0.2", "SPEC:INT 100000", "SPEC:AVG 0")) for line in sent
    )


@pytest.mark.parametrize("fault", ["noreply", "garbage", "partial", "busy"])
def test_light_recovers_from_fault(rig, light, fault):
    light.transport.command(f"SIM:FAULT {fault}")
    light.set_level(0.3)
    assert light.level() == 0.3
    assert received(rig, "light")[-3:-1] == ["LEV 0.3", "LEV 0.3"]


def test_a_port_gone_while_its_read_timeout_is_set_is_recovered(rig, light, monkeypatch):
    """Setting the read timeout reconfigures the port (termios): when the instrument vanishes just then (a restart
    between the command and its reply, as the random-restart sweep found), that is a lost port like a failed read,
    recovered by reopening, not a raw termios error."""
    port = light.transport._serial
    real = port._reconfigure_port
    failures = []

    def gone_once(*args, **kwargs):
        if not failures:
            failures.append(1)
            raise termios.error(5, "Input/output error")
        return real(*args, **kwargs)

    monkeypatch.setattr(port, "_reconfigure_port", gone_once)
    recoveries = light.recoveries
    light.set_level(0.3)
    assert failures and light.recoveries == recoveries + 1
    assert light.level() == 0.3


def test_reopened_port_gets_the_full_state_again_verified_by_read_back(rig, light):
    recoveries = light.recoveries
    light.transport.command("SIM:FAULT vanish")
    light.set_level(0.3)
    assert light.readback() == LightReadback(True, 0.3) and light.recoveries == recoveries + 1
    assert received(rig, "light")[-9:] == [
        "LEV 0.3",
        "*IDN?",
        "OUTP ON",
        "LEV 1.0",
        "OUTP?",
        "LEV?",
        "LEV 0.3",
        "OUTP?",
        "LEV?",
    ]


@pytest.mark.parametrize("fault", ["noreply", "garbage", "partial", "vanish", "reset"])
def test_spectrometer_read_recovers_from_fault(spectrometer, fault):
    spectrometer.set_integration_ms(33)
    spectrometer.transport.command(f"SIM:FAULT {fault}")
    wavelength_nm, irradiance = spectrometer.read_spectrum()
    assert len(wavelength_nm) == len(irradiance) == 401
    assert spectrometer.integration_ms() == 33


def test_reset_mid_command_restores_commanded_state(rig, light):
    light.set_level(0.4)
    light.transport.command("SIM:FAULT reset")
    assert light.level() == 0.4 and light.output() is True
    assert RigState(rig.rig_state_path).light.level == 0.4


def test_spontaneous_reset_restores_commanded_state(light):
    light.set_level(0.6)
    light.transport.command("SIM:RESET")
    assert light.level() == 0.6 and light.output() is True


def test_requested_reset_forgets_settings(light):
    light.set_level(0.6)
    light.reset()
    assert light.level() == 0.0 and light.output() is False


def test_err_reply_is_one_clear_error(light):
    light.transport.command("SIM:FAULT err")
    with pytest.raises(DeviceError) as info:
        light.set_level(0.2)
    message = str(info.value)
    assert light.port in message and "'LEV 0.2'" in message and "ERR 300" in message
    assert light.level() == 1.0


def test_persistent_silence_is_one_clear_error(rig, light):
    light.transport.command(f"SIM:FAULT noreply {light.transport.retries + 1}")
    with pytest.raises(DeviceError) as info:
        light.level()
    message = str(info.value)
    assert light.port in message and "'LEV?'" in message and "4 attempts" in message
    assert received(rig, "light")[-4:] == ["LEV?"] * 4
    assert light.level() == 1.0


def test_port_gone_for_good_is_one_clear_error(tmp_path):
    rig = SerialRig(tmp_path, spectrum=known_spectrum)
    simulator = rig.simulators["light"]
    with simulator, open_light(simulator.port, timeout_s=TIMEOUT_S, reopen_s=1.0) as light:
        light.set_level(0.5)
        simulator.stop()
        with pytest.raises(DeviceError) as info:
            light.level()
    message = str(info.value)
    assert simulator.port in message and "'LEV?'" in message and "did not come back" in message


def test_missing_port_is_one_clear_error(tmp_path):
    with pytest.raises(DeviceError) as info:
        open_light(str(tmp_path / "nothing"))
    assert str(tmp_path / "nothing") in str(info.value)


def test_second_open_of_a_port_is_refused(light):
    with pytest.raises(DeviceError, match="lock"):
        open_light(light.port)
