"""The supply twin reached as real supplies are: plain pyvisa with pyvisa-py (``@py``) over raw SCPI on the loopback
(``TCPIP::127.0.0.1::PORT::SOCKET``) and over a serial line on a pseudo-terminal (``ASRL/dev/pts/N::INSTR``); and
``uwlab sim supply`` as a process. Commands are the manuals' (not uwlab's driver's)."""

from __future__ import annotations

import signal

import pytest
import pyvisa

from tests.support.cli_process import finish, read_line, uwlab
from uwlab.sim.devices.led_load import LedLoad
from uwlab.sim.devices.supply import DIALECTS, SupplyTwin, serve

TIMEOUT_MS = 20_000  # generous: the machine is shared; nothing here measures time
# set V, set I, output on, measure I, measure V, mode query and its CV / CC answers (per manual)
FORMS = {
    "rigol-dp800": (":SOUR1:VOLT {}", ":SOUR1:CURR {}", ":OUTP CH1,ON", ":MEAS:CURR? CH1", ":MEAS:VOLT? CH1"),
    "keysight-e36100": ("VOLT {}", "CURR {}", "OUTP ON", "MEAS:CURR?", "MEAS:VOLT?"),
    "scpi": ("SOURce:VOLTage {}", "SOURce:CURRent {}", "OUTPut:STATe ON", "MEASure:CURRent?", "MEASure:VOLTage?"),
    "thorlabs-dc2200": (None, "SOUR1:CCUR {}", "OUTP1 ON", "SENS3:CURR:DATA?", "SENS4:VOLT:DATA?"),
}


def mode(instrument, dialect: str) -> str:
    """CV or CC as the instrument reports it: RIGOL's :OUTP:MODE?, the others' Operation Condition register."""
    if dialect == "rigol-dp800":
        return instrument.query(":OUTP:MODE? CH1")
    condition = int(instrument.query("STAT:OPER:COND?"))
    if dialect == "thorlabs-dc2200":  # LEDON (bit 11): the LED driver only regulates current
        return "CC" if condition & 2048 else "OFF"
    return {256: "CV", 1024: "CC"}.get(condition & (256 | 1024), "OFF")


@pytest.fixture(params=["tcp", "pty"])
def transport(request):
    return request.param


@pytest.fixture
def visa():
    manager = pyvisa.ResourceManager("@py")
    yield manager
    manager.close()


def open_twin(visa, resource: str):
    return visa.open_resource(resource, read_termination="\n", write_termination="\n", timeout=TIMEOUT_MS)


@pytest.mark.parametrize("dialect", DIALECTS)
def test_requested_current_in_cc_then_zero_volts_open_and_short(visa, transport, dialect):
    twin = SupplyTwin(dialect)
    set_v, set_i, on, meas_i, meas_v = FORMS[dialect]
    with serve(twin, transport=transport) as resource:
        instrument = open_twin(visa, resource)
        try:
            assert "," in instrument.query("*IDN?")
            instrument.write("*RST")
            if set_v:
                instrument.write(set_v.format(12))
            else:
                instrument.write("SOUR1:MODE CC")
            instrument.write(set_i.format(0.35))
            instrument.write(on)
            assert float(instrument.query(meas_i)) == pytest.approx(0.35, rel=0.01)
            assert float(instrument.query(meas_v)) == pytest.approx(LedLoad().voltage_v(0.35), rel=0.01)
            assert mode(instrument, dialect) == "CC"

            if set_v:  # at 0 V a CV/CC supply is in CV with no current
                instrument.write(set_v.format(0))
                assert mode(instrument, dialect) == "CV"
                assert abs(float(instrument.query(meas_i))) < 1e-3
                instrument.write(set_v.format(12))

            twin.set_fault("open")
            assert abs(float(instrument.query(meas_i))) < 1e-3
            if set_v:
                assert mode(instrument, dialect) == "CV"
            else:  # the DC2200 switches an open LED off and says so
                assert instrument.query("OUTP1?") == "0"
                assert instrument.query("SYST:ERR?").startswith("-300,")

            twin.set_fault("short")
            if not set_v:
                instrument.write(on)  # back on, into the short
            assert float(instrument.query(meas_i)) == pytest.approx(0.35, rel=0.01)
            assert abs(float(instrument.query(meas_v))) < 0.01
            assert mode(instrument, dialect) == "CC"
            assert instrument.query("SYST:ERR?").lstrip("+").startswith("0,")
        finally:
            instrument.close()
    assert twin.received[:2] == ["*IDN?", "*RST"]
    assert on in twin.received


def test_error_queue_over_the_wire(visa, transport):
    twin = SupplyTwin("keysight-e36100")
    with serve(twin, transport=transport) as resource:
        instrument = open_twin(visa, resource)
        try:
            instrument.write("CURR 5")  # E36103A: 2 A
            instrument.write("APPL:NONSENSE")
            assert instrument.query("SYST:ERR?").startswith("-222,")
            assert instrument.query("SYST:ERR?").startswith("-113,")
            assert instrument.query("SYST:ERR?") == '+0,"No error"'
            assert float(instrument.query("CURR?")) == 2.0  # *RST value, untouched by the refused 5 A
        finally:
            instrument.close()


def test_cli_serves_a_twin_until_ctrl_c(visa):
    process = uwlab("sim", "supply", "--dialect", "rigol-dp800", "--fault", "open")
    try:
        resource = read_line(process.stdout, 120, "the VISA resource").strip()
        assert resource.startswith("TCPIP::127.0.0.1::") and resource.endswith("::SOCKET")
        instrument = open_twin(visa, resource)
        try:
            assert instrument.query("*IDN?").startswith("RIGOL TECHNOLOGIES,DP832,")
            instrument.write(":SOUR1:VOLT 5;:SOUR1:CURR 0.5;:OUTP CH1,ON")
            assert abs(float(instrument.query(":MEAS:CURR? CH1"))) < 1e-3  # --fault open
            assert instrument.query(":OUTP:MODE? CH1") == "CV"
        finally:
            instrument.close()
        process.send_signal(signal.SIGINT)
    finally:
        code, out, err = finish(process, 60)
    assert code == 130
    assert err.strip() == "uwlab sim: interrupted"
    assert out == ""  # the resource line (read above) was all it printed
