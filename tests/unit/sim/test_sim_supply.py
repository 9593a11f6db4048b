"""The supply twin in process: LED curve, CV/CC physics, reset states, faults, protections, the SCPI error queue.

Expected values come from the LED's closed-form V(I) (`LedLoad.voltage_v`), white-power-LED data-sheet ranges and
the manuals' command sets and status bits (cited in uwlab/sim/devices/supply.py), never from uwlab's driver."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from uwlab.sim.devices.led_load import SHORT_RESISTANCE_OHM, LedLoad, LoadState
from tests.support.cli import one_line_error
from uwlab.sim.devices.scpi_parser import header_pattern
from uwlab.sim.devices.scpi_server import MAX_LINE_BYTES, LineSplitter
from uwlab.sim.devices.supply import DIALECTS, SupplyTwin

LED = LedLoad()
# How each manual spells: set V, set I, output on, measure I, measure V (the DC2200 has no voltage setpoint)
FORMS = {
    "rigol-dp800": (":SOUR1:VOLT {}", ":SOUR1:CURR {}", ":OUTP CH1,ON", ":MEAS:CURR? CH1", ":MEAS:VOLT? CH1"),
    "keysight-e36100": ("VOLT {}", "CURR {}", "OUTP ON", "MEAS:CURR?", "MEAS:VOLT?"),
    "scpi": ("VOLT {}", "CURR {}", "OUTP ON", "MEAS:CURR?", "MEAS:VOLT?"),
    "thorlabs-dc2200": (None, "SOUR1:CCUR {}", "OUTP1 ON", "SENS3:CURR:DATA?", "SENS4:VOLT:DATA?"),
}
SUPPLIES = [d for d in DIALECTS if d != "thorlabs-dc2200"]


def drive(twin: SupplyTwin, voltage_v: float | None, current_a: float) -> None:
    set_v, set_i, on, _, _ = FORMS[twin.dialect]
    assert twin.handle("*RST") is None
    if set_v is not None and voltage_v is not None:
        twin.handle(set_v.format(voltage_v))
    if twin.dialect == "thorlabs-dc2200":
        twin.handle("SOUR1:MODE CC")
    twin.handle(set_i.format(current_a))
    twin.handle(on)
    assert twin.handle("SYST:ERR?").lstrip("+").startswith("0,")


def measured(twin: SupplyTwin) -> tuple[float, float]:
    _, _, _, meas_i, meas_v = FORMS[twin.dialect]
    return float(twin.handle(meas_i)), float(twin.handle(meas_v))


# ---------------------------------------------------------------- the LED


def test_led_forward_voltage_lies_in_white_power_led_data_sheet_ranges():
    # Cree XP-G / Lumileds Luxeon class: ~2.8-3.1 V at 350 mA, ~3.0-3.4 V at 1 A (25 °C)
    assert 2.8 <= LED.voltage_v(0.35) <= 3.1
    assert 3.0 <= LED.voltage_v(1.0) <= 3.4
    assert LED.voltage_v(0.0) == LED.v_knee_v


@pytest.mark.parametrize("current_a", [1e-6, 1e-3, 0.05, 0.35, 0.7, 1.0, 3.0])
def test_led_current_inverts_the_closed_form_voltage(current_a):
    assert LED.current_a(LED.voltage_v(current_a)) == pytest.approx(current_a, rel=1e-9, abs=1e-12)


def test_led_curve_is_monotonic_and_dark_below_its_knee():
    volts = np.linspace(0.0, 4.0, 401)
    amps = np.array([LED.current_a(v) for v in volts])
    assert np.all(np.diff(amps) >= 0)
    assert np.all(amps[volts <= LED.v_knee_v] == 0)


def test_load_faults():
    assert LoadState(LED, "open").current_a(30.0) == 0.0
    assert LoadState(LED, "short").voltage_v(1.0) == pytest.approx(SHORT_RESISTANCE_OHM)
    with pytest.raises(ValueError):
        LoadState(LED, "melted")


# ---------------------------------------------------------------- CV/CC physics


@pytest.mark.parametrize("dialect", SUPPLIES)
def test_constant_current_when_the_led_would_draw_more_than_the_setpoint(dialect):
    twin = SupplyTwin(dialect)
    drive(twin, 12.0, 0.5)
    amps, volts = measured(twin)
    assert amps == pytest.approx(0.5, rel=0.01)
    assert volts == pytest.approx(LED.voltage_v(0.5), rel=0.01)  # the LED's voltage, not the 12 V setpoint
    assert twin.point().mode == "CC"


@pytest.mark.parametrize("dialect", SUPPLIES)
def test_constant_voltage_below_the_forward_voltage_of_the_set_current(dialect):
    twin = SupplyTwin(dialect)
    drive(twin, 2.9, 1.0)  # V_led(1 A) ≈ 3.2 V: the voltage limit wins
    amps, volts = measured(twin)
    assert twin.point().mode == "CV"
    assert volts == pytest.approx(2.9, rel=0.01)
    assert LED.voltage_v(amps) == pytest.approx(2.9, abs=0.01)  # the current the LED draws at 2.9 V
    assert amps < 0.9


@pytest.mark.parametrize("dialect", SUPPLIES)
def test_mode_changes_at_the_forward_voltage_of_the_set_current(dialect):
    twin = SupplyTwin(dialect)
    knee_v = LED.voltage_v(0.5)
    for voltage_v, mode in ((knee_v - 0.01, "CV"), (knee_v + 0.01, "CC")):
        drive(twin, round(voltage_v, 3), 0.5)
        assert twin.point().mode == mode


@pytest.mark.parametrize("dialect", SUPPLIES)
def test_zero_volts_is_constant_voltage_with_no_current(dialect):
    twin = SupplyTwin(dialect)
    drive(twin, 0.0, 0.5)
    amps, volts = measured(twin)
    assert twin.point().mode == "CV"
    assert abs(amps) < 1e-4 and abs(volts) < 5e-3


def test_dc2200_is_a_current_source_with_a_compliance_voltage():
    twin = SupplyTwin("thorlabs-dc2200")
    drive(twin, None, 0.7)
    amps, volts = measured(twin)
    assert amps == pytest.approx(0.7, rel=0.01)
    assert volts == pytest.approx(LED.voltage_v(0.7), rel=0.01)
    twin.voltage_limit_v = 3.0  # compliance below the LED's 3.1 V at 0.7 A
    amps, _ = measured(twin)
    assert amps < 0.6
    assert int(twin.handle("STAT:QUES:COND?")) & 2  # LEDV


# ---------------------------------------------------------------- reset state and status


@pytest.mark.parametrize("dialect", DIALECTS)
def test_reset_state_is_output_off_at_zero(dialect):
    twin = SupplyTwin(dialect)
    drive(twin, 5.0, 0.5)
    twin.handle("*RST")
    assert not twin.output_on and twin.voltage_set_v == 0.0
    output_query = {"rigol-dp800": ":OUTP? CH1", "thorlabs-dc2200": "OUTP1?"}.get(dialect, "OUTP?")
    assert twin.handle(output_query) in ("OFF", "0")
    amps, volts = measured(twin)
    assert abs(amps) < 1e-4 and abs(volts) < 5e-3


def test_reset_currents_follow_the_manuals():
    assert SupplyTwin("rigol-dp800").current_set_a == 3.0  # DP800 :APPLy table, CH1 default 3 A
    assert float(SupplyTwin("rigol-dp800").handle(":SOUR1:CURR?")) == 3.0
    assert SupplyTwin("thorlabs-dc2200").current_set_a == 0.0


def test_rigol_mode_query_answers_cv_or_cc():
    twin = SupplyTwin("rigol-dp800")
    drive(twin, 12.0, 0.5)
    assert twin.handle(":OUTP:MODE? CH1") == "CC"
    assert twin.handle(":OUTPut:MODE?") == "CC"
    twin.handle(":SOUR1:VOLT 2.8")
    assert twin.handle(":OUTP:MODE? CH1") == "CV"


@pytest.mark.parametrize("dialect", ["keysight-e36100", "scpi"])
def test_operation_condition_has_the_cv_and_cc_bits(dialect):
    twin = SupplyTwin(dialect)
    drive(twin, 12.0, 0.5)
    assert int(twin.handle("STAT:OPER:COND?")) == 1024  # bit 10 CC
    twin.handle("VOLT 2.8")
    assert int(twin.handle("STATus:OPERation:CONDition?")) == 256  # bit 8 CV
    twin.handle("OUTP OFF")
    assert int(twin.handle("STAT:OPER:COND?")) == 0


def test_dc2200_operation_register_reports_output_state_and_led_on():
    twin = SupplyTwin("thorlabs-dc2200")
    drive(twin, None, 0.5)
    assert int(twin.handle("STAT:OPER:COND?")) == 512 | 2048  # LEDST | LEDON


# ---------------------------------------------------------------- faults and protections


@pytest.mark.parametrize("dialect", SUPPLIES)
def test_open_led_gives_no_current_in_constant_voltage(dialect):
    twin = SupplyTwin(dialect)
    drive(twin, 5.0, 0.5)
    twin.set_fault("open")
    amps, volts = measured(twin)
    assert abs(amps) < 1e-4 and volts == pytest.approx(5.0, rel=0.01)
    assert twin.point().mode == "CV"


@pytest.mark.parametrize("dialect", DIALECTS)
def test_short_gives_the_set_current_at_almost_no_voltage(dialect):
    twin = SupplyTwin(dialect)
    twin.set_fault("short")
    drive(twin, 5.0, 0.5)
    amps, volts = measured(twin)
    assert amps == pytest.approx(0.5, rel=0.01) and abs(volts) < 0.01
    assert twin.point().mode == "CC"


def test_dc2200_open_led_switches_off_with_an_error():
    twin = SupplyTwin("thorlabs-dc2200")
    drive(twin, None, 0.5)
    twin.set_fault("open")
    assert twin.handle("OUTP1?") == "0"
    assert twin.handle("SYST:ERR?").startswith("-300,")
    assert abs(float(twin.handle("SENS3:CURR:DATA?"))) < 1e-4


def test_fault_set_from_another_thread_reaches_the_next_measurement():
    twin = SupplyTwin("scpi")
    drive(twin, 5.0, 0.5)
    worker = threading.Thread(target=twin.set_fault, args=("open",))
    worker.start()
    worker.join()
    assert abs(float(twin.handle("MEAS:CURR?"))) < 1e-4


def test_rigol_ovp_trips_the_output_off_and_latches():
    twin = SupplyTwin("rigol-dp800")
    twin.handle(":OUTP:OVP:VAL CH1,3.0;:OUTP:OVP CH1,ON")
    twin.handle(":SOUR1:VOLT 5;:SOUR1:CURR 0.1")
    twin.handle(":OUTP CH1,ON")  # open load → 5 V at the terminals > 3 V
    twin.set_fault("open")
    assert twin.handle(":OUTP? CH1") == "OFF"
    assert twin.handle(":OUTP:OVP:QUES? CH1") == "YES"
    twin.handle(":OUTP CH1,ON")
    assert twin.handle(":OUTP? CH1") == "OFF"  # latched
    twin.handle(":OUTP:OVP:CLE CH1;:OUTP:OVP CH1,OFF;:OUTP CH1,ON")
    assert twin.handle(":OUTP? CH1") == "ON"


def test_keysight_ocp_trips_when_the_output_enters_cc():
    twin = SupplyTwin("keysight-e36100")
    twin.handle("CURR:PROT:STAT ON")
    drive(twin, 2.8, 0.5)
    assert twin.handle("OUTP?") == "1"  # CV: no trip (drive() reset OCP off; set again below)
    twin.handle("CURR:PROT:STAT ON;VOLT 12")
    assert twin.handle("OUTP?") == "0"
    assert int(twin.handle("STAT:QUES:COND?")) == 2  # OC
    assert twin.handle("CURR:PROT:TRIP?") == "1"


def test_trip_from_a_test_turns_the_output_off():
    twin = SupplyTwin("scpi")
    drive(twin, 12.0, 0.5)
    twin.trip("ovp")
    assert twin.handle("OUTP?") == "0" and int(twin.handle("STAT:QUES:COND?")) == 1
    assert abs(float(twin.handle("MEAS:CURR?"))) < 1e-4


def test_low_voltage_limit_from_the_front_panel_drops_the_current():
    twin = SupplyTwin("keysight-e36100")
    drive(twin, 12.0, 0.5)
    twin.voltage_limit_v = 2.7
    assert twin.point().mode == "CV"
    assert float(twin.handle("MEAS:CURR?")) < 0.2


# ---------------------------------------------------------------- SCPI parsing and the error queue


@pytest.mark.parametrize(
    "command",
    [
        "CURR 0.25",
        "curr 0.25",
        "Current 0.25",
        "SOUR:CURR 0.25",
        "SOURCE:CURRENT:LEVEL:IMMEDIATE:AMPLITUDE 0.25",
        ":source:curr:lev:imm:ampl 250 mA",
        "CURR 2.5E-1",
    ],
)
def test_short_long_and_case_forms_set_the_same_current(command):
    twin = SupplyTwin("keysight-e36100")
    twin.handle(command)
    assert twin.current_set_a == pytest.approx(0.25)
    assert twin.handle("SYST:ERR?") == '+0,"No error"'


def test_header_pattern_refuses_partial_long_forms():
    assert not header_pattern("CURRent").match("CURRE")
    assert header_pattern("SENSe3:CURRent[:DC]:DATA?").match("sense3:curr:data?")
    assert not header_pattern("SENSe3:CURRent[:DC]:DATA?").match("SENS:CURR:DATA?")


@pytest.mark.parametrize(
    ("dialect", "command", "code"),
    [
        ("keysight-e36100", "FOO:BAR 1", -113),
        ("keysight-e36100", "CURR 2.5", -222),  # E36103A: 2 A
        ("rigol-dp800", ":SOUR1:CURR 3.5", -222),  # DP832 CH1: 3.2 A
        ("rigol-dp800", ":OUTP CH2,ON", -224),
        ("scpi", "CURR abc", -104),
        ("scpi", "CURR", -109),
        ("scpi", "OUTP MAYBE", -224),
        ("thorlabs-dc2200", "SOUR1:CCUR 1.5", -222),  # above the 1 A LED limit
    ],
)
def test_refusals_land_in_the_error_queue(dialect, command, code):
    twin = SupplyTwin(dialect)
    before = (twin.current_set_a, twin.output_on)
    assert twin.handle(command) is None
    assert int(twin.handle("SYST:ERR?").split(",")[0]) == code
    assert twin.handle("SYST:ERR?").lstrip("+").startswith("0,")
    assert (twin.current_set_a, twin.output_on) == before


def test_error_queue_is_fifo_overflows_and_clears():
    twin = SupplyTwin("scpi")
    twin.handle("CURR 9")
    twin.handle("NOPE")
    assert twin.handle("SYST:ERR?").startswith("-222,")
    assert twin.handle("SYST:ERR:NEXT?").startswith("-113,")
    for _ in range(25):
        twin.handle("NOPE")
    codes = [int(twin.handle("SYST:ERR?").split(",")[0]) for _ in range(21)]
    assert codes == [-113] * 19 + [-350, 0]
    twin.handle("NOPE;*CLS")  # a command error discards the rest of the message: *CLS does not run
    twin.handle("*CLS")
    assert twin.handle("SYST:ERR?") == '0,"No error"'


def test_several_units_in_one_line_answer_in_one_line():
    twin = SupplyTwin("scpi")
    assert twin.handle("*RST;VOLT 5;CURR 0.5;OUTP ON;OUTP?;CURR?") == "1;5.000000E-01"
    assert twin.received == ["*RST;VOLT 5;CURR 0.5;OUTP ON;OUTP?;CURR?"]


def test_measurements_are_seeded_and_within_a_tenth_of_a_percent():
    readings = []
    for _ in range(2):
        twin = SupplyTwin("scpi", seed=7)
        drive(twin, 12.0, 0.5)
        readings.append([float(twin.handle("MEAS:CURR?")) for _ in range(50)])
    assert readings[0] == readings[1]
    assert np.all(np.abs(np.array(readings[0]) - 0.5) < 0.5e-3)
    assert np.std(readings[0]) > 0


def test_idn_is_settable_with_four_fields():
    idn = "Keysight Technologies,E36103A,MY00000001,1.0"
    assert SupplyTwin("scpi", idn=idn).handle("*IDN?") == idn
    with pytest.raises(ValueError):
        SupplyTwin("scpi", idn="just one field")


def test_an_overlong_line_is_recorded_refused_and_the_next_line_answered():
    twin = SupplyTwin("scpi")
    splitter = LineSplitter(twin)
    assert splitter.feed(b"X" * (MAX_LINE_BYTES + 10)) == b""
    assert splitter.feed(b"YYY\n*IDN?\r\n") == twin.idn.encode() + b"\n"
    assert twin.received == [f"<line longer than {MAX_LINE_BYTES} bytes>", "*IDN?\r"]  # raw, as received
    assert twin.handle("SYST:ERR?").startswith("-223,")


@pytest.mark.parametrize(
    ("argv", "named"),
    [
        (["sim", "supply", "--tcp", "70000"], "tcp"),
        (["sim", "supply", "--idn", "only,three,fields"], "idn"),
    ],
)
def test_cli_bad_input_is_one_line(capsys, argv, named):
    assert named in one_line_error(capsys, argv)
