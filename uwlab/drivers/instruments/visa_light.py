"""A light over VISA, driven by its instrument definition (`uwlab.drivers.instruments.definition`).

Safety, in this order: the level is checked in [0, 1] and the drive against the definition's ``max_drive`` (and
the rig's lower maximum, ``max_drive`` of `open_visa_light`) before anything is sent — and checked again as it will
be sent, after formatting (``.0f`` would turn 1.5 A into ``2``: refused, as is a format that cannot express the
value within the read-back tolerance); after every set the driver waits the settle time, reads the error queue (a
non-zero SCPI error is refused naming the instrument and the error) and reads the setting back (a drive or output
that reads back further than `LightDefinition.tolerance` is refused naming both values); on close, whatever the
exit, the output is switched off (the safe state) and `safe_state_reached` records it — unless the caller set
`keep_output` and the block ended normally (``uwlab light --on`` leaves the light on; an error or Ctrl-C still
switches it off).

A CV/CC supply (a definition with ``[constant_current]``, `ConstantCurrent`) is put in constant-current mode when
it is opened: its voltage limit set to the compliance voltage (the LED's maximum forward voltage plus the margin,
never above the supply's rating), over-voltage and over-current protection where it has them, each read back or
error-checked. A drive found set above the rig's limit when the light is opened (a supply's reset state is often
its full current) is set to 0 with the output off first. After every set and switch-on with the output on it must
then deliver: the mode is CC, the measured current within tolerance of the set current, the measured voltage not
that of a short (`VisaLight.delivery`); otherwise the output is switched off and the set refused in one line
(``measured 0.000 A for 0.300 A set: open circuit or voltage limit 5.0 V?``).
"""

from __future__ import annotations

import time
import warnings
from typing import Any

from uwlab.drivers.instruments.definition import LightDefinition, load_light_definition
from uwlab.drivers.instruments.discovery import visa_manager
from uwlab.drivers.serial.base import Light, check_level
from uwlab.errors import ConfigError, DeviceError, said

TRUE_TOKENS = ("1", "ON")
FALSE_TOKENS = ("0", "OFF")


def _open_resource(resource: str, visa_library: str | None, definition: LightDefinition) -> Any:
    import pyvisa

    manager = visa_manager(visa_library)
    try:
        handle = manager.open_resource(
            resource,
            read_termination=definition.read_termination,
            write_termination=definition.write_termination,
            timeout=definition.timeout_ms,
        )
    except (OSError, ValueError, pyvisa.errors.Error) as exc:
        if not manager.list_opened_resources():
            manager.close()
        raise ConfigError("resource", resource, f"cannot be opened ({said(exc)})") from None
    return manager, handle


def _reason(exc: Exception) -> str:
    """A PyVISA error in a few words: its VISA abbreviation (e.g. VI_ERROR_TMO), else its message."""
    return str(getattr(exc, "abbreviation", "") or exc)


def _amps(value: float) -> str:
    """A current for a one-line message: three decimals (``0.300``), or three significant digits when smaller."""
    return f"{value:.3f}" if value == 0.0 or abs(value) >= 0.01 else f"{value:.3g}"


def ieee488_fields(answer: str) -> bool:
    """Whether an ``*IDN?`` answer has the four IEEE 488.2 fields (maker, model, serial, firmware; IEEE Std
    488.2-1992, 10.14: four comma-separated fields, the serial and firmware may be ``0``), each non-empty."""
    fields = answer.split(",")
    return len(fields) == 4 and all(field.strip() for field in fields)


class VisaLight(Light):
    """A dimmable light on a VISA resource (module docstring). Use `open_visa_light`."""

    def __init__(
        self,
        definition: LightDefinition,
        name: str,
        resource: Any,
        manager: Any,
        port: str,
        max_drive: float | None = None,
        forward_voltage_v: float | None = None,
        identity_contains: tuple[str, ...] = (),
    ) -> None:
        self.definition, self.name, self.port = definition, name, port
        self._resource, self._manager = resource, manager
        self.max_drive = definition.max_drive if max_drive is None else min(max_drive, definition.max_drive)
        self.safe_state_reached: bool | None = None
        self.keep_output = False
        self.voltage_limit_v: float | None = None
        self._last_drive = self.max_drive
        self._identity = self._query(definition.commands.identity)
        if not self._identity:
            raise ConfigError("resource", port, f"does not answer {definition.commands.identity}")
        if not ieee488_fields(self._identity):
            raise ConfigError(
                "instrument",
                name,
                f"{port} answers *IDN? {self._identity!r}, not IEEE 488.2's maker,model,serial,firmware",
            )
        words = [*definition.identity_contains, *identity_contains]
        missing = [word for word in words if word.lower() not in self._identity.lower()]
        if missing:
            raise ConfigError("instrument", name, f"{port} answers *IDN? {self._identity!r}, not {' '.join(missing)}")
        for command in definition.commands.setup:
            self._set(command)
        if self.drive() > self.max_drive:  # set above this rig's limit (a reset state, an earlier run's): to 0 A, off
            if self.output():
                self.set_output(False)
            self.set_drive(0.0)
        if definition.constant_current is not None:
            self._constant_current(forward_voltage_v)

    def _constant_current(self, forward_voltage_v: float | None) -> None:
        """Put the supply in constant-current mode (module docstring): the voltage limit, OVP, OCP, protection on."""
        cc = self.definition.constant_current
        assert cc is not None
        forward = cc.forward_voltage_v if forward_voltage_v is None else forward_voltage_v
        compliance = forward + cc.compliance_margin_v
        if compliance > cc.voltage_rating_v:
            raise ConfigError(
                "forward_voltage_v",
                forward,
                f"plus the {cc.compliance_margin_v:g} V margin exceeds {self.name}'s {cc.voltage_rating_v:g} V rating",
            )
        text, self.voltage_limit_v = self._formatted(
            compliance, cc.voltage_format, cc.voltage_rating_v, "voltage_limit_v", 0.01
        )
        self._set(cc.set_voltage.format(value=text))
        read = self._number(cc.query_voltage)
        if abs(read - self.voltage_limit_v) > LightDefinition.deviation_allowed(self.voltage_limit_v, 0.01, 0.005):
            raise DeviceError(f"{self.name} on {self.port}: voltage limit set {text} V reads back {read:g} V")
        if cc.set_ovp is not None:
            ovp = min(self.voltage_limit_v + cc.ovp_margin_v, cc.voltage_rating_v)
            self._set(cc.set_ovp.format(value=self._formatted(ovp, cc.voltage_format, cc.voltage_rating_v, "ovp_v")[0]))
        if cc.set_ocp is not None:
            text = self._formatted(self.max_drive, self.definition.drive_format, self.max_drive, "ocp_a")[0]
            self._set(cc.set_ocp.format(value=text))
        for command in cc.protection_setup:
            self._set(command)

    def _formatted(
        self, value: float, spec: str, limit: float, key: str, absolute: float | None = None
    ) -> tuple[str, float]:
        """``value`` as it will be sent (``format(value, spec)``) and that text read as a number; `ConfigError` on
        ``key`` when what would be sent is above ``limit`` or further from ``value`` than its tolerance (the drive's,
        `LightDefinition.tolerance`, or ``absolute`` / 0.5 %)."""
        text = format(value, spec)
        sent = float(text)
        if sent > limit:
            raise ConfigError(key, value, f"is sent as {text} by the format {spec!r}, above the {limit:g} limit")
        allowed = (
            self.definition.tolerance(value)
            if absolute is None
            else LightDefinition.deviation_allowed(value, absolute, 0.005)
        )
        if abs(sent - value) > allowed:
            raise ConfigError(key, value, f"the format {spec!r} cannot express it (it would send {text})")
        return text, sent

    @property
    def recoveries(self) -> int:
        return 0

    @property
    def level_tolerance(self) -> float:
        """The level read-back's tolerance at the drive set last: the definition's drive tolerance there
        (`LightDefinition.tolerance`: absolute and relative, never more than a fraction of the set value) over the
        full-scale drive."""
        return self.definition.tolerance(self._last_drive) / self.max_drive

    def identity(self) -> str:
        return self._identity

    def reset(self) -> None:
        self.set_output(False)
        self.set_level(0.0)

    def _query(self, command: str) -> str:
        import pyvisa

        try:
            with warnings.catch_warnings():  # an unterminated answer is judged below, not printed
                warnings.simplefilter("ignore", UserWarning)
                return str(self._resource.query(command)).strip()
        except pyvisa.errors.Error as exc:
            raise DeviceError(f"{self.name} on {self.port}: no answer to {command!r} ({_reason(exc)})") from None

    def _write(self, command: str) -> None:
        import pyvisa

        try:
            self._resource.write(command)
        except pyvisa.errors.Error as exc:
            raise DeviceError(f"{self.name} on {self.port}: cannot send {command!r} ({_reason(exc)})") from None

    def _number(self, command: str) -> float:
        text = self._query(command)
        try:
            return float(text.split(",")[0])
        except ValueError:
            raise DeviceError(f"{self.name} on {self.port}: {command!r} answered {text!r}, not a number") from None

    def _check_errors(self, sent: str) -> None:
        query = self.definition.commands.error
        if query is None:
            return
        answer = self._query(query)
        code = answer.split(",")[0].strip()
        try:
            failed = int(float(code)) != 0
        except ValueError:
            failed = True
        if failed:
            raise DeviceError(f"{self.name} on {self.port}: {sent!r} gave the error {answer!r}")

    def _set(self, command: str) -> None:
        self._write(command)
        if self.definition.settle_s:
            time.sleep(self.definition.settle_s)
        self._check_errors(command)

    def set_output(self, on: bool) -> None:
        """Switch the output, read it back; switched on, a supply in constant-current mode must deliver
        (`delivery`)."""
        d = self.definition
        command = d.commands.set_output.format(state=d.on_token if on else d.off_token)
        self._set(command)
        if self.output() != on:
            tripped = " (a protection trip latched? clear it on the instrument)" if on else ""
            raise DeviceError(
                f"{self.name} on {self.port}: output set {'on' if on else 'off'} reads back otherwise{tripped}"
            )
        if on:
            self._check_delivery()

    def output(self) -> bool:
        text = self._query(self.definition.commands.query_output).upper()
        if text in TRUE_TOKENS:
            return True
        if text in FALSE_TOKENS:
            return False
        raise DeviceError(f"{self.name} on {self.port}: output state {text!r} is neither on nor off")

    def set_drive(self, value: float) -> None:
        """Set the drive [A or V]; refused before sending beyond [0, max_drive], or when it would be sent (after
        formatting) above ``max_drive`` or off its value; read back; with the output on, a supply in
        constant-current mode must deliver it (`delivery`)."""
        d = self.definition
        if not 0.0 <= value <= self.max_drive:
            raise ConfigError(d.drive, value, f"must be in [0, {self.max_drive:g}] for {self.name}")
        text, sent = self._formatted(value, d.drive_format, self.max_drive, d.drive)
        self._set(d.commands.set_drive.format(value=text))
        self._last_drive = sent
        read = self.drive()
        if abs(read - sent) > d.tolerance(sent):
            raise DeviceError(f"{self.name} on {self.port}: {d.drive} set {sent:g} reads back {read:g}")
        if d.constant_current is not None and self.output():
            self._check_delivery()

    def drive(self) -> float:
        return self._number(self.definition.commands.query_drive)

    def measured(self) -> float | None:
        """The measured drive (e.g. the LED current), None where the instrument does not measure."""
        command = self.definition.commands.measure
        return None if command is None else self._number(command)

    def mode(self) -> str | None:
        """The regulation mode a CV/CC supply reports (``CC``, ``CV``, ... as it answers; for a status register,
        ``CC`` when its CC bit is set, else ``not CC (register N)``), None where the definition has no mode query."""
        cc = self.definition.constant_current
        if cc is None or cc.query_mode is None:
            return None
        answer = self._query(cc.query_mode)
        if cc.cc_bit is None:
            return answer.strip().upper()
        try:
            register = int(float(answer))
        except ValueError:
            raise DeviceError(
                f"{self.name} on {self.port}: {cc.query_mode!r} answered {answer!r}, not a register"
            ) from None
        return "CC" if register >> cc.cc_bit & 1 else f"not CC (register {register})"

    def delivery(self, state: dict[str, Any]) -> str:
        """Whether a CV/CC supply delivers what was set, from its read-back ``state``: ``"ok"``, ``"off"`` (output
        off: nothing to check), or what is wrong in a few words: the measured current off the set current (an open
        circuit or a voltage limit below the LED's forward voltage), a mode other than CC, or a measured voltage of
        a short across the LED."""
        cc = self.definition.constant_current
        if cc is None or not state["on"]:
            return "off"
        current_set, measured = state["current_a"], state["measured_current_a"]
        allowed = LightDefinition.deviation_allowed(current_set, cc.measure_tolerance_a, cc.measure_relative)
        voltage = state.get("measured_voltage_v")
        at = "" if voltage is None else f" at {voltage:.2f} V"
        if measured < current_set - allowed:
            limit = f" {state['voltage_limit_v']:.1f} V?" if "voltage_limit_v" in state else "?"
            found = f"measured {_amps(measured)} A{at} for {_amps(current_set)} A set"
            return f"{found}: open circuit or voltage limit{limit}"
        if measured > current_set + allowed:
            return f"measured {_amps(measured)} A{at} for {_amps(current_set)} A set: more than set, not regulating"
        if current_set > allowed and state.get("mode") not in (None, "CC"):
            return f"in {state['mode']} mode, not CC, at {_amps(current_set)} A set{at}"
        if current_set > allowed and voltage is not None and voltage < cc.short_below_v:
            return f"measured {voltage:.2f} V at {_amps(measured)} A: a short across the LED?"
        return "ok"

    def _check_delivery(self) -> None:
        """Refuse (`DeviceError`, the output switched off first) a supply that does not deliver (`delivery`)."""
        if self.definition.constant_current is None or not self.definition.constant_current.check:
            return
        found = self.delivery(self.state())
        if found in ("ok", "off"):
            return
        try:
            self._write(self.definition.commands.set_output.format(state=self.definition.off_token))
            off = not self.output()
        except DeviceError:
            off = False
        raise DeviceError(
            f"{self.name} on {self.port}: {found}; "
            + ("output switched off" if off else "the output did not read back off: switch it off by hand")
        )

    def set_level(self, level: float) -> None:
        self.set_drive(check_level(level) * self.max_drive)

    def level(self) -> float:
        return self.drive() / self.max_drive

    def state(self) -> dict[str, Any]:
        """The read-back: ``on``, ``level``, the drive (e.g. ``current_a``) and the measured drive where there is
        one (e.g. ``measured_current_a``); for a CV/CC supply also ``measured_voltage_v`` (where it measures it),
        ``voltage_limit_v``, ``mode`` and ``delivery`` (`delivery`: ``ok``, ``off`` or what is wrong)."""
        drive = self.drive()
        state: dict[str, Any] = {"on": self.output(), "level": drive / self.max_drive, self.definition.drive: drive}
        if self.definition.commands.measure is not None:
            state[self.definition.measured_key] = self.measured()
        cc = self.definition.constant_current
        if cc is not None:
            if cc.measure_voltage is not None:
                state["measured_voltage_v"] = self._number(cc.measure_voltage)
            state["voltage_limit_v"] = self._number(cc.query_voltage)
            state["mode"] = self.mode()
            state["delivery"] = self.delivery(state) if cc.check else "unchecked"
        return state

    def __exit__(self, exc_type: Any, *exc_info: Any) -> None:
        if exc_type is None and self.keep_output:
            self._release()
        else:
            self.close()

    def _release(self) -> None:
        """Close the resource, and PyVISA's resource manager once nothing else is open through it (PyVISA shares
        one manager per library: two lights on one library must not close each other's sessions)."""
        if self._resource is not None:
            resource, self._resource = self._resource, None
            try:
                resource.close()
            finally:
                if not self._manager.list_opened_resources():
                    self._manager.close()

    def close(self) -> None:
        """Switch the output off (the safe state), record whether it read back off, release the resource."""
        if self._resource is None:
            return
        try:
            self._write(self.definition.commands.set_output.format(state=self.definition.off_token))
            self.safe_state_reached = not self.output()
        except (DeviceError, ConfigError):
            self.safe_state_reached = False
        finally:
            self._release()


def open_visa_light(
    instrument: str,
    resource: str,
    visa_library: str | None = None,
    max_drive: float | None = None,
    forward_voltage_v: float | None = None,
    identity_contains: tuple[str, ...] = (),
) -> VisaLight:
    """Open the light `instrument` (a definition name or file) on the VISA `resource`; `visa_library` as PyVISA
    takes it (``@py``, the default; ``PATH.yaml@sim`` for pyvisa-sim; a vendor VISA's path); `max_drive` the rig's
    maximum (never above the definition's), `forward_voltage_v` its LED's maximum forward voltage (a CV/CC supply's
    compliance voltage: this plus the definition's margin), `identity_contains` words its ``*IDN?`` must contain
    besides the definition's (the rig pins its instrument). `ConfigError` naming the instrument, resource or library
    when they do not answer or do not match."""
    definition = load_light_definition(instrument)
    if max_drive is not None and max_drive > definition.max_drive:
        raise ConfigError("max_current_a", max_drive, f"above {instrument}'s own maximum {definition.max_drive:g}")
    if forward_voltage_v is not None and definition.constant_current is None:
        raise ConfigError("forward_voltage_v", forward_voltage_v, f"{instrument} has no [constant_current] section")
    manager, handle = _open_resource(resource, visa_library, definition)
    try:
        return VisaLight(
            definition, instrument, handle, manager, resource, max_drive, forward_voltage_v, identity_contains
        )
    except BaseException:
        handle.close()
        if not manager.list_opened_resources():
            manager.close()
        raise
