"""uwlab-ascii reply parsing (fuzzed), value checks, and the simulated instruments without a port."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uwlab.drivers.serial.base import check_averaging, check_integration_ms, check_level
from uwlab.drivers.serial.protocol import (
    Reply,
    ReplyParseError,
    format_float,
    parse_block_header,
    parse_bool,
    parse_float,
    parse_int,
    parse_reply,
    parse_spectrum_lines,
)
from uwlab.sim.rig_state import RigState
from uwlab.sim.devices.serial_instruments import DetectorModel, SimLight, SimSpectrometer
from uwlab.errors import ConfigError


@pytest.mark.parametrize(
    ("raw", "expected"),
    [
        (b"OK\n", Reply("ok")),
        (b"OK\r\n", Reply("ok")),
        (b"0.25\n", Reply("value", "0.25")),
        (b"ERR 102 1.5 outside [0, 1]\n", Reply("error", "1.5 outside [0, 1]", 102)),
        (b"ERR 200\n", Reply("error", "", 200)),
        (b"# UWLAB,SIM-LIGHT,0001,1.0 ready\n", Reply("banner", "UWLAB,SIM-LIGHT,0001,1.0 ready")),
    ],
)
def test_parse_reply_known_lines(raw, expected):
    assert parse_reply(raw) == expected


@pytest.mark.parametrize("raw", [b"\n", b"\x00\xff\n", b"ERR x boom\n", b"ERR\n", b"caf\xc3\xa9\n", b"a\x1bb\n"])
def test_parse_reply_rejects_garbage(raw):
    with pytest.raises(ReplyParseError):
        parse_reply(raw)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=200))
def test_parse_reply_fuzz_only_raises_parse_error(raw):
    try:
        reply = parse_reply(raw)
    except ReplyParseError:
        return
    assert reply.kind in ("ok", "value", "error", "banner")
    assert all(0x20 <= ord(c) <= 0x7E for c in reply.text)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.text(max_size=40), max_size=8))
def test_value_parsers_fuzz_only_raise_parse_error(lines):
    for parser in (parse_float, parse_int, parse_bool, parse_block_header):
        for line in lines:
            try:
                parser(line)
            except ReplyParseError:
                pass
    try:
        parse_spectrum_lines(lines)
    except ReplyParseError:
        pass


@given(st.floats(allow_nan=False, allow_infinity=False))
def test_number_format_round_trips(value):
    assert parse_float(format_float(value)) == value


def test_spectrum_lines_round_trip_and_order_check():
    wavelength_nm, irradiance = parse_spectrum_lines(["400.0 1e-3", "401.0 2.5e-3"])
    assert wavelength_nm.tolist() == [400.0, 401.0] and irradiance.tolist() == [1e-3, 2.5e-3]
    with pytest.raises(ReplyParseError):
        parse_spectrum_lines(["401.0 1", "400.0 1"])
    assert parse_block_header("BEGIN 401 1") == (401, True)


@pytest.mark.parametrize(
    ("check", "value", "key"),
    [
        (check_level, 1.01, "level"),
        (check_level, -0.1, "level"),
        (check_level, float("nan"), "level"),
        (check_integration_ms, 0.5, "integration_ms"),
        (check_integration_ms, 20000, "integration_ms"),
        (check_averaging, 0, "averaging"),
        (check_averaging, 2.5, "averaging"),
        (check_averaging, 101, "averaging"),
    ],
)
def test_out_of_range_values_refused(check, value, key):
    with pytest.raises(ConfigError) as info:
        check(value)
    assert info.value.key == key


def test_sim_light_publishes_gamma_curve():
    rig = RigState()
    light = SimLight(rig, gamma=2.0)
    assert light.handle("OUTP ON") == ["OK"] and light.handle("LEV 0.5") == ["OK"]
    assert rig.light.on and rig.light.level == 0.5 and rig.light.flux_fraction == pytest.approx(0.25)
    assert light.handle("LEV 1.5")[0].startswith("ERR 102")
    assert light.handle("SYST:ERR?")[0].startswith("102 ")
    assert light.handle("SYST:ERR?") == ["0 No error"]
    assert light.handle("BOGUS")[0].startswith("ERR 100")
    assert light.handle("*RST") == [light.banner, "OK"] and not rig.light.on and rig.light.level == 0.0


def test_detector_noise_matches_its_model():
    detector = DetectorModel()
    irradiance = np.full(20000, 0.1)
    measured, saturated = detector.measure(irradiance, 0.1, 4, np.random.default_rng(1))
    sigma = detector.expected_sigma_w_m2_nm(irradiance, 0.1, 4)
    residual = detector.dark_residual_w_m2_nm(0.1)
    assert not saturated and residual > 0
    assert np.mean(measured) == pytest.approx(0.1 + residual, abs=4 * sigma[0] / np.sqrt(irradiance.size))
    assert np.std(measured) == pytest.approx(sigma[0], rel=0.03)


def test_detector_saturates_above_full_scale():
    detector = DetectorModel()
    bright = np.full(10, 2 * detector.full_scale_counts / (detector.counts_per_w_m2_nm_s * 0.1))
    measured, saturated = detector.measure(bright, 0.1, 1, np.random.default_rng(0))
    assert saturated and np.all(measured < bright)


def test_sim_spectrometer_limits_and_block():
    spectrometer = SimSpectrometer(RigState(), lambda position, f: (np.array([300.0, 900.0]), np.full(2, f)), seed=0)
    assert spectrometer.handle("SPEC:INT 0.5")[0].startswith("ERR 102")
    assert spectrometer.handle("SPEC:INT 20000")[0].startswith("ERR 102")
    assert spectrometer.handle("SPEC:AVG 0")[0].startswith("ERR 102")
    assert spectrometer.handle("SPEC:INT 1") == ["OK"] and spectrometer.handle("SPEC:INT?") == ["1.0"]
    block = spectrometer.handle("SPEC:READ?")
    count, saturated = parse_block_header(block[0])
    assert count == len(block) - 2 == 401 and block[-1] == "END" and not saturated


def test_sim_spectrometer_blocked_reads_the_dark_until_unblocked():
    """1 W/m²/nm at full light; blocked (through a reset too) it reads the dark's residual, 2 % of the 1002-count dark
    at 10 ms over 10⁴ counts per W/m²/nm (2.0e-3 W/m²/nm), within its noise."""
    spectrometer = SimSpectrometer(RigState(), lambda position, f: (np.array([300.0, 900.0]), np.full(2, f)), seed=0)

    def mean_read() -> float:
        return float(np.mean([float(line.split()[1]) for line in spectrometer.handle("SPEC:READ?")[1:-1]]))

    assert spectrometer.handle("SPEC:INT 10") == ["OK"] and mean_read() == pytest.approx(1.0, rel=0.01)
    assert spectrometer.handle("SIM:BLOCK ON") == ["OK"] and spectrometer.handle("SIM:BLOCK?") == ["ON"]
    spectrometer.power_on()
    assert spectrometer.handle("SIM:BLOCK?") == ["ON"] and spectrometer.handle("SPEC:INT 10") == ["OK"]
    assert mean_read() == pytest.approx(2.004e-3, abs=2e-4)
    assert spectrometer.handle("SIM:BLOCK maybe")[0].startswith("ERR 101")
    assert spectrometer.handle("SIM:BLOCK OFF") == ["OK"] and mean_read() == pytest.approx(1.0, rel=0.01)
