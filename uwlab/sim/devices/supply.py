"""A simulated programmable DC supply (or LED driver) with an LED load: a twin with physics, not constants.

The twin answers SCPI as four instruments' manuals say they do (the dialects, `DIALECTS`), and its measured current
and voltage come from the load (`uwlab.sim.devices.led_load`): what the supply regulates depends on what is
connected, as on a bench.

**CV/CC operating point** (any CV/CC bench supply; e.g. Keysight E36100 Series User's Guide, "Constant voltage /
constant current operation"; RIGOL DP800 Programming Guide, :OUTPut:MODE?): with setpoints V_set and I_set and a
load drawing I_load(V),

- if I_load(V_set) > I_set the supply is in **CC**: I = I_set, V = V_load(I_set) (≤ V_set, the load curve being
  monotonic);
- otherwise it is in **CV**: V = V_set, I = I_load(V_set);
- output off: 0 V, 0 A.

An LED driver (Thorlabs DC2200) is a current source with a compliance voltage: I = I_set while V_load(I_set) ≤ the
compliance voltage, else it sits at the compliance voltage with I = I_load(V_compliance).

**Measurements** (``MEAS:CURR?``, ``MEAS:VOLT?``, ``SENS3:CURR:DATA?``) read the operating point with a seeded
Gaussian error: 0.02 % of the reading plus 10 µA / 0.5 mV (assumed; within the readback accuracy the data sheets
give, e.g. DP832 "0.05 % + 2 mA", E36103A "0.1 % + 2 mA").

**Dialects** (each row: reset state from the manual; assumed where the manual found did not say):

- ``rigol-dp800`` — RIGOL DP800 Series Programming Guide, ch. 2 "Command System" (channel CH1 of a DP832, 30 V /
  3 A; settable to 32 V / 3.2 A). :APPLy's table gives the defaults: 0 V, 3 A. :OUTPut[:STATe] [CH1,]{ON|OFF} →
  ``ON``/``OFF``; :OUTPut:MODE? [CH1] → ``CV``/``CC``/``UR`` (UR, unregulated, is not reached by this load);
  [:SOURce[1]]:VOLTage|CURRent[:LEVel][:IMMediate][:AMPLitude]; :MEASure[:VOLTage][:DC]?, :MEASure:CURRent[:DC]?,
  :MEASure:ALL?; :OUTPut:OVP|OCP[:STATe], :VALue, :QUES? (``YES``/``NO``), :CLEar — OVP and OCP off at reset
  (OCP[:STATe] default OFF), OVP value 33 V, OCP value 3.3 A (their maxima; assumed). Channels CH2/CH3 are not
  modelled (``-224``). ``:SYST:ERR?`` → ``0,"No error"``.
- ``keysight-e36100`` — Keysight E36100 Series Programming Guide (E36100-90005), SCPI Command Reference and "Status
  Tutorial" (an E36103A, 20 V / 2 A). Reset: output off, 0 V, current 2 A (assumed: the rated current, as the
  E3631A's and E3632A's *RST sets it), OVP 22 V (assumed), OCP off. OUTPut[:STATe] → ``0``/``1``;
  STATus:OPERation:CONDition? bit 8 (256) CV, bit 10 (1024) CC; STATus:QUEStionable:CONDition? bit 0 (1) OV, bit 1
  (2) OC, bit 10 (1024) UNR. With CURRent:PROTection:STATe ON, entering CC disables the output and sets OC
  (Keysight's OCP). OUTPut:PROTection:CLEar clears the latch; the output stays off (assumed). ``SYST:ERR?`` →
  ``+0,"No error"``.
- ``scpi`` — a generic SCPI-1999 supply (SCPI-1999 Vol. 2: OUTPut, SOURce:VOLTage/CURRent, MEASure, STATus,
  SYSTem:ERRor; Vol. 1 §9 the status registers). Its ``*IDN?`` is settable (`SupplyTwin` ``idn``; four IEEE 488.2
  §10.14 fields). Rating 30 V / 3 A, reset 0 V and 0.1 A (assumed: SCPI leaves *RST values to the device).
  STATus:QUEStionable bit 0 VOLTage (OVP), bit 1 CURRent (OCP) are SCPI-1999's; OPERation bits 8–12 are the
  instrument's: CV bit 8 and CC bit 10, as Keysight and Agilent supplies use them.
- ``thorlabs-dc2200`` — Thorlabs DC2200 Operation Manual, "Computer Interface" > "SCPI Commands" and "Error
  Reporting" (Standard Operation register: bit 9 LEDST "LED output state is ON", bit 11 LEDON "LED output is
  currently ON"; Questionable Data register: bit 0 LEDC, bit 1 LEDV, bit 2 LEDT). SOURce[1]:MODE {CC|…} (only CC is
  modelled: another mode gives no light), SOURce[1]:CCURent[:CURRent][:LEVel][:IMMediate][:AMPLitude],
  SOURce[1]:CURRent:LIMit[:AMPLitude] (a setpoint above the limit is ``-222``), OUTPut[1][:STATe] → ``1``/``0``,
  SENSe3:CURRent[:DC]:DATA? (LED current), SENSe4:VOLTage[:DC]:DATA? (LED voltage; assumed header). Reset (assumed):
  output off, mode CC, 0 A, limit 1 A; compliance 50 V (assumed). An **open LED** with the output on: the driver
  switches the output off and queues ``-300,"Device-specific error; LED open"`` (assumed: the manual found lists
  the register bits, not this code); a compliance-limited LED sets LEDV (bit 1).

**Faults and what tests see**: `SupplyTwin.set_fault` (``"open"``, ``"short"``, None); `SupplyTwin.trip`
(``"ovp"``/``"ocp"``, a protection trip: output off, the flag latched until the manual's clear command, or ``*RST``
on the DC2200, which has none); `SupplyTwin.voltage_limit_v` (the voltage setpoint of a CV/CC supply, the
compliance voltage of the DC2200: a limit below the LED's forward voltage leaves it in CV below the requested
current); all safe from another thread. `SupplyTwin.received` lists every line received (raw: without its ``\\n``,
bytes as Latin-1 characters). `serve` puts a twin on the wire (TCP on the loopback or a pseudo-terminal) and
yields its VISA resource string.
"""

from __future__ import annotations

import math
import random
import threading
from dataclasses import dataclass

from uwlab.sim.devices.led_load import LOAD_FAULTS, LedLoad, LoadState
from uwlab.sim.devices.scpi_parser import (
    Command,
    ErrorQueue,
    Handler,
    ScpiError,
    command_table,
    execute,
    expect_arguments,
    parse_bool,
    parse_number,
)
from uwlab.sim.devices.scpi_server import serve

__all__ = ["DIALECTS", "MODELS", "SupplyModel", "SupplyTwin", "operating_point", "current_source_point", "serve"]

DIALECTS = ("rigol-dp800", "keysight-e36100", "scpi", "thorlabs-dc2200")
PROTECTIONS = ("ovp", "ocp")
RELATIVE_NOISE = 2e-4
CURRENT_NOISE_A = 1e-5
VOLTAGE_NOISE_V = 5e-4


@dataclass(frozen=True)
class SupplyModel:
    """One instrument's identity, ranges and reset state (sources in the module docstring)."""

    idn: str
    max_voltage_v: float
    max_current_a: float
    reset_voltage_v: float
    reset_current_a: float
    ovp_v: float
    ocp_a: float
    ovp_on: bool = False
    compliance_v: float = math.inf


MODELS = {
    "rigol-dp800": SupplyModel("RIGOL TECHNOLOGIES,DP832,DP8C000000001,00.01.16", 32.0, 3.2, 0.0, 3.0, 33.0, 3.3),
    "keysight-e36100": SupplyModel("Keysight Technologies,E36103A,MY00000001,1.0.4", 20.0, 2.0, 0.0, 2.0, 22.0, 2.0),
    "scpi": SupplyModel("uwlab,SCPI DC supply twin,SIM0001,1.0", 30.0, 3.0, 0.0, 0.1, 33.0, 3.0, ovp_on=True),
    "thorlabs-dc2200": SupplyModel(
        "Thorlabs,DC2200,M00000001,1.3.0", 50.0, 10.0, 0.0, 0.0, 50.0, 1.0, compliance_v=50.0
    ),
}


@dataclass(frozen=True)
class OperatingPoint:
    voltage_v: float
    current_a: float
    mode: str  # "CV", "CC" or "OFF"


def operating_point(load: LoadState, voltage_set_v: float, current_set_a: float) -> OperatingPoint:
    """Where a CV/CC supply with these setpoints settles on ``load`` (output on); see the module docstring."""
    drawn_a = load.current_a(voltage_set_v)
    if drawn_a > current_set_a:
        return OperatingPoint(load.voltage_v(current_set_a), current_set_a, "CC")
    return OperatingPoint(voltage_set_v, drawn_a, "CV")


def current_source_point(load: LoadState, current_set_a: float, compliance_v: float) -> OperatingPoint:
    """Where a current source with a compliance voltage settles on ``load`` (output on)."""
    needed_v = load.voltage_v(current_set_a)
    if needed_v <= compliance_v:
        return OperatingPoint(needed_v, current_set_a, "CC")
    return OperatingPoint(compliance_v, load.current_a(compliance_v), "CV")


class SupplyTwin:
    """A CV/CC supply (or the DC2200 LED driver) of ``dialect`` driving ``led``; thread-safe.

    ``idn`` replaces the model's ``*IDN?`` answer (four comma-separated fields); ``seed`` fixes the measurement
    noise. `handle` takes one received line and returns the response line (None when the line held no query)."""

    def __init__(self, dialect: str = "scpi", *, led: LedLoad | None = None, idn: str | None = None, seed: int = 0):
        if dialect not in DIALECTS:
            raise ValueError(f"dialect must be one of {', '.join(DIALECTS)}, got {dialect!r}")
        self.dialect = dialect
        self.model = MODELS[dialect]
        self.idn = idn if idn is not None else self.model.idn
        if len(self.idn.split(",")) != 4:
            raise ValueError(f"*IDN? must have four comma-separated fields, got {self.idn!r}")
        self.received: list[str] = []
        self._load = LoadState(led if led is not None else LedLoad())
        self._lock = threading.RLock()
        self._random = random.Random(seed)
        self.errors = ErrorQueue()
        self._operation_event = 0
        self._questionable_event = 0
        self._commands = self._table()
        self._reset()

    # ------------------------------------------------------------------ state
    def _reset(self) -> None:
        """*RST and power-on: output off, setpoints and protection to the model's reset values, latches cleared."""
        model = self.model
        self.output_on = False
        self.voltage_set_v = model.reset_voltage_v
        self.current_set_a = model.reset_current_a
        self.ovp_v = model.ovp_v
        self.ovp_on = model.ovp_on
        self.ocp_a = model.ocp_a  # DC2200: the LED current limit
        self.ocp_on = False
        self.compliance_v = model.compliance_v
        self.dc2200_mode = "CC"
        self.tripped = {"ovp": False, "ocp": False}

    @property
    def fault(self) -> str | None:
        return self._load.fault

    def set_fault(self, fault: str | None) -> None:
        """Open or short the load, or restore the LED (None); the output reacts as the instrument would."""
        if fault not in (None, *LOAD_FAULTS):
            raise ValueError(f"fault must be None or one of {', '.join(LOAD_FAULTS)}, got {fault!r}")
        with self._lock:
            self._load = LoadState(self._load.led, fault)
            self.point()

    @property
    def voltage_limit_v(self) -> float:
        """The voltage the output may not exceed: V_set of a CV/CC supply, the DC2200's compliance voltage."""
        return self.compliance_v if self.dialect == "thorlabs-dc2200" else self.voltage_set_v

    @voltage_limit_v.setter
    def voltage_limit_v(self, value: float) -> None:
        with self._lock:
            if self.dialect == "thorlabs-dc2200":
                self.compliance_v = float(value)
            else:
                self.voltage_set_v = float(value)
            self.point()

    def trip(self, protection: str) -> None:
        """A protection trip (``"ovp"`` or ``"ocp"``), as if the protection circuit fired: output off, latched."""
        if protection not in PROTECTIONS:
            raise ValueError(f"protection must be one of {', '.join(PROTECTIONS)}, got {protection!r}")
        with self._lock:
            self.tripped[protection] = True
            self.output_on = False

    def point(self) -> OperatingPoint:
        """The true operating point now; applies the protections (and the DC2200's open-LED shut-down) first."""
        with self._lock:
            if not self.output_on:
                return OperatingPoint(0.0, 0.0, "OFF")
            if self.dialect == "thorlabs-dc2200":
                if self.dc2200_mode != "CC":
                    return OperatingPoint(0.0, 0.0, "OFF")
                if self._load.fault == "open":
                    self.output_on = False
                    self.errors.push(ScpiError(-300, "LED open"))
                    return OperatingPoint(0.0, 0.0, "OFF")
                return current_source_point(self._load, self.current_set_a, self.compliance_v)
            point = operating_point(self._load, self.voltage_set_v, self.current_set_a)
            if self.ovp_on and point.voltage_v > self.ovp_v:
                self.trip("ovp")
            elif self.ocp_on and (
                point.current_a > self.ocp_a if self.dialect == "rigol-dp800" else point.mode == "CC"
            ):
                self.trip("ocp")
            else:
                return point
            return OperatingPoint(0.0, 0.0, "OFF")

    def _measure(self, value: float, absolute_noise: float) -> float:
        return value * (1 + self._random.gauss(0.0, RELATIVE_NOISE)) + self._random.gauss(0.0, absolute_noise)

    def measured_current_a(self) -> float:
        return self._measure(self.point().current_a, CURRENT_NOISE_A)

    def measured_voltage_v(self) -> float:
        return self._measure(self.point().voltage_v, VOLTAGE_NOISE_V)

    # ------------------------------------------------------------------ wire
    def handle(self, line: str) -> str | None:
        """Record ``line`` (raw: without its ``\\n``, with any ``\\r``) and run it; the response line or None."""
        with self._lock:
            self.received.append(line)
            return execute(self._commands, self.errors, line.strip())

    def overlong(self, limit: int) -> None:
        """A line longer than ``limit`` bytes arrived (and was dropped by the transport): recorded and queued."""
        with self._lock:
            self.received.append(f"<line longer than {limit} bytes>")
            self.errors.push(ScpiError(-223))

    def _condition_registers(self) -> tuple[int, int]:
        """(STATus:OPERation:CONDition, STATus:QUEStionable:CONDition) of this dialect (module docstring)."""
        point = self.point()
        if self.dialect == "thorlabs-dc2200":
            operation = (512 if self.output_on else 0) | (2048 if point.current_a > 0 else 0)
            return operation, (2 if self.output_on and point.mode == "CV" else 0)
        operation = {"CV": 256, "CC": 1024}.get(point.mode, 0)
        return operation, (1 if self.tripped["ovp"] else 0) | (2 if self.tripped["ocp"] else 0)

    def _event(self, register: str) -> str:
        operation, questionable = self._condition_registers()
        self._operation_event |= operation
        self._questionable_event |= questionable
        value = self._operation_event if register == "operation" else self._questionable_event
        if register == "operation":
            self._operation_event = 0
        else:
            self._questionable_event = 0
        return self._integer(value)

    def _integer(self, value: int) -> str:
        return f"+{value}" if self.dialect == "keysight-e36100" else str(value)

    def _real(self, value: float, decimals: int) -> str:
        if self.dialect == "rigol-dp800":
            return f"{value:.{decimals}f}"
        return f"{value:+.8E}" if self.dialect == "keysight-e36100" else f"{value:.6E}"

    def _error(self) -> str:
        code, text = self.errors.pop()
        number = f"+{code}" if self.dialect == "keysight-e36100" and code == 0 else str(code)
        return f'{number},"{text}"'

    def _table(self) -> list[Command]:
        common: list[tuple[str, Handler]] = [
            ("*IDN?", self._query(lambda: self.idn)),
            ("*RST", self._command(self._reset)),
            ("*CLS", self._command(self._clear_status)),
            ("*OPC?", self._query(lambda: "1")),
            ("*ESR?", self._query(self._read_event_status)),
            ("*STB?", self._query(lambda: self._integer(4 if self.errors.entries else 0))),  # bit 2: error queue
            ("SYSTem:ERRor[:NEXT]?", self._query(self._error)),
            ("SYSTem:VERSion?", self._query(lambda: "1999.0")),
        ]
        return command_table(common + getattr(self, "_" + self.dialect.replace("-", "_"))())

    @staticmethod
    def _command(function) -> Handler:
        """A command without parameters running ``function()``."""

        def command(arguments: list[str]) -> None:
            expect_arguments(arguments, 0)
            function()

        return command

    def _clear_status(self) -> None:
        self.errors.clear()
        self._operation_event = self._questionable_event = 0

    def _read_event_status(self) -> str:
        value, self.errors.event_status = self.errors.event_status, 0
        return self._integer(value)

    def _set(self, attribute: str, value: object) -> None:
        setattr(self, attribute, value)
        self.point()

    def _set_output(self, on: bool) -> None:
        """Output on is refused silently while a protection is latched (the output stays off until cleared)."""
        if on and any(self.tripped.values()):
            return
        self._set("output_on", on)

    def _level(self, attribute: str, maximum: float, default: float, decimals: int = 4) -> tuple[Handler, Handler]:
        """Setter and query of a numeric setting in [0, maximum] (DEF: ``default``); the query takes MIN or MAX too."""

        def setter(arguments: list[str]) -> None:
            self._set(attribute, parse_number(expect_arguments(arguments, 1)[0], 0.0, maximum, default))

        def query(arguments: list[str]) -> str:
            if arguments:
                value = parse_number(expect_arguments(arguments, 1)[0], 0.0, maximum)
                if arguments[0].strip().upper() not in ("MIN", "MINIMUM", "MAX", "MAXIMUM"):
                    raise ScpiError(-224, "expected MIN or MAX")
            else:
                value = getattr(self, attribute)
            return self._real(value, decimals)

        return setter, query

    def _boolean(self, attribute: str, on: str = "1", off: str = "0") -> tuple[Handler, Handler]:
        def setter(arguments: list[str]) -> None:
            self._set(attribute, parse_bool(expect_arguments(arguments, 1)[0]))

        def query(arguments: list[str]) -> str:
            expect_arguments(arguments, 0)
            return on if getattr(self, attribute) else off

        return setter, query

    def _query(self, function) -> Handler:
        """A query without parameters answering ``function()``."""

        def query(arguments: list[str]) -> str:
            expect_arguments(arguments, 0)
            return function()

        return query

    def _output(self, on: str = "1", off: str = "0") -> tuple[Handler, Handler]:
        def setter(arguments: list[str]) -> None:
            self._set_output(parse_bool(expect_arguments(arguments, 1)[0]))

        return setter, self._query(lambda: on if self.output_on else off)

    def _clear_protection(self, *kinds: str) -> Handler:
        def clear(arguments: list[str]) -> None:
            expect_arguments(arguments, 0)
            for kind in kinds:
                self.tripped[kind] = False

        return clear

    # ------------------------------------------------------------------ dialects
    def _rigol_dp800(self) -> list[tuple[str, Handler]]:
        def on_ch1(handler: Handler) -> Handler:
            """RIGOL's optional leading channel parameter: CH1 (the LED's channel) is dropped; CH2/CH3 are -224."""

            def with_channel(arguments: list[str]) -> str | None:
                if arguments and arguments[0].upper().startswith("CH"):
                    if arguments[0].upper() != "CH1":
                        raise ScpiError(-224, f"channel {arguments[0][:8]} is not modelled (the LED is on CH1)")
                    arguments = arguments[1:]
                return handler(arguments)

            return with_channel

        m = self.model
        volt, volt_query = self._level("voltage_set_v", m.max_voltage_v, m.reset_voltage_v, 3)
        curr, curr_query = self._level("current_set_a", m.max_current_a, m.reset_current_a, 4)
        out, out_query = self._output("ON", "OFF")
        mode = self._query(lambda: "CC" if self.point().mode == "CC" else "CV")

        def apply(arguments: list[str]) -> None:
            if not 1 <= len(arguments) <= 2:
                raise ScpiError(-109 if not arguments else -108)
            voltage = parse_number(arguments[0], 0.0, m.max_voltage_v, m.reset_voltage_v)
            current = parse_number(arguments[1], 0.0, m.max_current_a, m.reset_current_a) if arguments[1:] else None
            self.voltage_set_v = voltage
            self._set("current_set_a", self.current_set_a if current is None else current)

        def measure_all() -> str:
            volts, amps = self.measured_voltage_v(), self.measured_current_a()
            return f"{volts:.3f},{amps:.4f},{volts * amps:.3f}"

        entries: list[tuple[str, Handler]] = [
            ("OUTPut[:STATe]", out),
            ("OUTPut[:STATe]?", out_query),
            ("OUTPut:MODE?", mode),
            ("OUTPut:CVCC?", mode),
            ("[SOURce#:]VOLTage[:LEVel][:IMMediate][:AMPLitude]", volt),
            ("[SOURce#:]VOLTage[:LEVel][:IMMediate][:AMPLitude]?", volt_query),
            ("[SOURce#:]CURRent[:LEVel][:IMMediate][:AMPLitude]", curr),
            ("[SOURce#:]CURRent[:LEVel][:IMMediate][:AMPLitude]?", curr_query),
            ("APPLy", apply),
            ("APPLy?", self._query(lambda: f"CH1,{self.voltage_set_v:.3f},{self.current_set_a:.4f}")),
            ("MEASure[:VOLTage][:DC]?", self._query(lambda: f"{self.measured_voltage_v():.3f}")),
            ("MEASure:CURRent[:DC]?", self._query(lambda: f"{self.measured_current_a():.4f}")),
            ("MEASure:ALL[:DC]?", self._query(measure_all)),
        ]
        for kind, attribute, maximum, decimals in (("ovp", "ovp_v", m.ovp_v, 3), ("ocp", "ocp_a", m.ocp_a, 4)):
            state, state_query = self._boolean(f"{kind}_on", "ON", "OFF")
            value, value_query = self._level(attribute, maximum, maximum, decimals)
            tripped = self._query(lambda kind=kind: "YES" if self.tripped[kind] else "NO")
            entries += [
                (f"OUTPut:{kind.upper()}[:STATe]", state),
                (f"OUTPut:{kind.upper()}[:STATe]?", state_query),
                (f"OUTPut:{kind.upper()}:VALue", value),
                (f"OUTPut:{kind.upper()}:VALue?", value_query),
                (f"OUTPut:{kind.upper()}:QUEStion?", tripped),
                (f"OUTPut:{kind.upper()}:ALARm?", tripped),
                (f"OUTPut:{kind.upper()}:CLEar", self._clear_protection(kind)),
            ]
        return [(spec, on_ch1(handler)) for spec, handler in entries]

    def _keysight_e36100(self) -> list[tuple[str, Handler]]:
        m = self.model
        volt, volt_query = self._level("voltage_set_v", m.max_voltage_v, m.reset_voltage_v)
        curr, curr_query = self._level("current_set_a", m.max_current_a, m.reset_current_a)
        ovp, ovp_query = self._level("ovp_v", m.ovp_v, m.ovp_v)
        ocp, ocp_query = self._boolean("ocp_on")
        out, out_query = self._output()
        return [
            ("OUTPut[:STATe]", out),
            ("OUTPut[:STATe]?", out_query),
            ("OUTPut:PROTection:CLEar", self._clear_protection("ovp", "ocp")),
            ("[SOURce:]VOLTage[:LEVel][:IMMediate][:AMPLitude]", volt),
            ("[SOURce:]VOLTage[:LEVel][:IMMediate][:AMPLitude]?", volt_query),
            ("[SOURce:]CURRent[:LEVel][:IMMediate][:AMPLitude]", curr),
            ("[SOURce:]CURRent[:LEVel][:IMMediate][:AMPLitude]?", curr_query),
            ("[SOURce:]VOLTage:PROTection[:LEVel]", ovp),
            ("[SOURce:]VOLTage:PROTection[:LEVel]?", ovp_query),
            ("[SOURce:]VOLTage:PROTection:TRIPped?", self._query(lambda: "1" if self.tripped["ovp"] else "0")),
            ("[SOURce:]CURRent:PROTection:STATe", ocp),
            ("[SOURce:]CURRent:PROTection:STATe?", ocp_query),
            ("[SOURce:]CURRent:PROTection:TRIPped?", self._query(lambda: "1" if self.tripped["ocp"] else "0")),
            ("MEASure[:SCALar][:VOLTage][:DC]?", self._query(lambda: self._real(self.measured_voltage_v(), 4))),
            ("MEASure[:SCALar]:CURRent[:DC]?", self._query(lambda: self._real(self.measured_current_a(), 4))),
            *self._status_commands(),
        ]

    def _scpi(self) -> list[tuple[str, Handler]]:
        m = self.model
        volt, volt_query = self._level("voltage_set_v", m.max_voltage_v, m.reset_voltage_v)
        curr, curr_query = self._level("current_set_a", m.max_current_a, m.reset_current_a)
        ovp, ovp_query = self._level("ovp_v", m.ovp_v, m.ovp_v)
        ovp_state, ovp_state_query = self._boolean("ovp_on")
        ocp, ocp_query = self._boolean("ocp_on")
        out, out_query = self._output()
        return [
            ("OUTPut#[:STATe]", out),
            ("OUTPut#[:STATe]?", out_query),
            ("OUTPut#:PROTection:CLEar", self._clear_protection("ovp", "ocp")),
            ("OUTPut#:PROTection:TRIPped?", self._query(lambda: "1" if any(self.tripped.values()) else "0")),
            ("[SOURce#:]VOLTage[:LEVel][:IMMediate][:AMPLitude]", volt),
            ("[SOURce#:]VOLTage[:LEVel][:IMMediate][:AMPLitude]?", volt_query),
            ("[SOURce#:]CURRent[:LEVel][:IMMediate][:AMPLitude]", curr),
            ("[SOURce#:]CURRent[:LEVel][:IMMediate][:AMPLitude]?", curr_query),
            ("[SOURce#:]VOLTage:PROTection[:LEVel]", ovp),
            ("[SOURce#:]VOLTage:PROTection[:LEVel]?", ovp_query),
            ("[SOURce#:]VOLTage:PROTection:STATe", ovp_state),
            ("[SOURce#:]VOLTage:PROTection:STATe?", ovp_state_query),
            ("[SOURce#:]CURRent:PROTection:STATe", ocp),
            ("[SOURce#:]CURRent:PROTection:STATe?", ocp_query),
            ("MEASure[:SCALar][:VOLTage][:DC]?", self._query(lambda: self._real(self.measured_voltage_v(), 4))),
            ("MEASure[:SCALar]:CURRent[:DC]?", self._query(lambda: self._real(self.measured_current_a(), 4))),
            *self._status_commands(),
        ]

    def _thorlabs_dc2200(self) -> list[tuple[str, Handler]]:
        m = self.model
        out, out_query = self._output()

        def set_current(arguments: list[str]) -> None:
            value = parse_number(expect_arguments(arguments, 1)[0], 0.0, m.max_current_a, 0.0)
            if value > self.ocp_a:
                raise ScpiError(-222, f"{value:g} A above the LED current limit {self.ocp_a:g} A")
            self._set("current_set_a", value)

        _, current_query = self._level("current_set_a", m.max_current_a, m.reset_current_a)
        limit, limit_query = self._level("ocp_a", m.max_current_a, m.ocp_a)

        def set_limit(arguments: list[str]) -> None:
            limit(arguments)
            if self.current_set_a > self.ocp_a:  # the setpoint follows a lowered limit down (assumed)
                self._set("current_set_a", self.ocp_a)

        def set_mode(arguments: list[str]) -> None:
            word = expect_arguments(arguments, 1)[0].upper()
            modes = {"CC": "CC", "CB": "CB", "PWM": "PWM", "PULS": "PULS", "PULSE": "PULS", "INT": "INT"}
            modes |= {"TTL": "TTL", "MOD": "MOD"}
            if word not in modes:
                raise ScpiError(-224, f"mode {word[:16]}")
            self._set("dc2200_mode", modes[word])

        return [
            ("OUTPut#[:STATe]", out),
            ("OUTPut#[:STATe]?", out_query),
            ("SOURce#:MODE", set_mode),
            ("SOURce#:MODE?", self._query(lambda: self.dc2200_mode)),
            ("SOURce#:CCURent[:CURRent][:LEVel][:IMMediate][:AMPLitude]", set_current),
            ("SOURce#:CCURent[:CURRent][:LEVel][:IMMediate][:AMPLitude]?", current_query),
            ("SOURce#:CURRent:LIMit[:AMPLitude]", set_limit),
            ("SOURce#:CURRent:LIMit[:AMPLitude]?", limit_query),
            ("SENSe3:CURRent[:DC]:DATA?", self._query(lambda: self._real(self.measured_current_a(), 4))),
            ("SENSe4:VOLTage[:DC]:DATA?", self._query(lambda: self._real(self.measured_voltage_v(), 4))),
            *self._status_commands(),
        ]

    def _status_commands(self) -> list[tuple[str, Handler]]:
        return [
            ("STATus:OPERation:CONDition?", self._query(lambda: self._integer(self._condition_registers()[0]))),
            ("STATus:OPERation[:EVENt]?", self._query(lambda: self._event("operation"))),
            ("STATus:QUEStionable:CONDition?", self._query(lambda: self._integer(self._condition_registers()[1]))),
            ("STATus:QUEStionable[:EVENt]?", self._query(lambda: self._event("questionable"))),
        ]
