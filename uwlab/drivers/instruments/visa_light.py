"""A light over VISA, driven by its instrument definition (`uwlab.drivers.instruments.definition`).

Safety, in this order: the level is checked in [0, 1] and the drive against the definition's ``max_drive`` (and
the rig's lower maximum, ``max_drive`` of `open_visa_light`) before anything is sent; after every set the driver
waits the settle time, reads the error queue (a non-zero SCPI error is refused naming the instrument and the
error) and reads the setting back (a drive or output that reads back different is refused naming both values);
on close, whatever the exit, the output is switched off (the safe state) and `safe_state_reached` records it —
unless the caller set `keep_output` and the block ended normally (``uwlab light --on`` leaves the light on; an
error or Ctrl-C still switches it off).
"""

from __future__ import annotations

import time
import warnings
from typing import Any

from uwlab.drivers.instruments.definition import LightDefinition, load_light_definition
from uwlab.drivers.serial.base import Light, check_level
from uwlab.errors import ConfigError, DeviceError, said

TRUE_TOKENS = ("1", "ON")
FALSE_TOKENS = ("0", "OFF")


def _open_resource(resource: str, visa_library: str | None, definition: LightDefinition) -> Any:
    import pyvisa

    try:
        manager = pyvisa.ResourceManager(visa_library or "@py")
    except (OSError, ValueError, pyvisa.errors.Error) as exc:
        raise ConfigError("visa-library", visa_library, f"cannot be loaded ({said(exc)})") from None
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
    ) -> None:
        self.definition, self.name, self.port = definition, name, port
        self._resource, self._manager = resource, manager
        self.max_drive = definition.max_drive if max_drive is None else min(max_drive, definition.max_drive)
        self.safe_state_reached: bool | None = None
        self.keep_output = False
        self._identity = self._query(definition.commands.identity)
        if not self._identity:
            raise ConfigError("resource", port, f"does not answer {definition.commands.identity}")
        missing = [word for word in definition.identity_contains if word.lower() not in self._identity.lower()]
        if missing:
            raise ConfigError("instrument", name, f"{port} answers *IDN? {self._identity!r}, not {' '.join(missing)}")
        for command in definition.commands.setup:
            self._set(command)

    @property
    def recoveries(self) -> int:
        return 0

    @property
    def level_tolerance(self) -> float:
        """The level read-back's tolerance: the definition's drive tolerance over the full-scale drive."""
        return self.definition.readback_tolerance / self.max_drive

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
        d = self.definition
        command = d.commands.set_output.format(state=d.on_token if on else d.off_token)
        self._set(command)
        if self.output() != on:
            raise DeviceError(f"{self.name} on {self.port}: output set {'on' if on else 'off'} reads back otherwise")

    def output(self) -> bool:
        text = self._query(self.definition.commands.query_output).upper()
        if text in TRUE_TOKENS:
            return True
        if text in FALSE_TOKENS:
            return False
        raise DeviceError(f"{self.name} on {self.port}: output state {text!r} is neither on nor off")

    def set_drive(self, value: float) -> None:
        """Set the drive [A or V]; refused before sending beyond [0, max_drive]."""
        if not 0.0 <= value <= self.max_drive:
            raise ConfigError(self.definition.drive, value, f"must be in [0, {self.max_drive:g}] for {self.name}")
        command = self.definition.commands.set_drive.format(value=format(value, self.definition.drive_format))
        self._set(command)
        read = self.drive()
        if abs(read - value) > self.definition.readback_tolerance:
            raise DeviceError(f"{self.name} on {self.port}: {self.definition.drive} set {value:g} reads back {read:g}")

    def drive(self) -> float:
        return self._number(self.definition.commands.query_drive)

    def measured(self) -> float | None:
        """The measured drive (e.g. the LED current), None where the instrument does not measure."""
        command = self.definition.commands.measure
        return None if command is None else self._number(command)

    def set_level(self, level: float) -> None:
        self.set_drive(check_level(level) * self.max_drive)

    def level(self) -> float:
        return self.drive() / self.max_drive

    def state(self) -> dict[str, Any]:
        """The read-back: ``on``, ``level``, the drive (e.g. ``current_a``) and the measured drive where there is
        one (e.g. ``measured_current_a``)."""
        drive = self.drive()
        state: dict[str, Any] = {"on": self.output(), "level": drive / self.max_drive, self.definition.drive: drive}
        if self.definition.commands.measure is not None:
            state[self.definition.measured_key] = self.measured()
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
    instrument: str, resource: str, visa_library: str | None = None, max_drive: float | None = None
) -> VisaLight:
    """Open the light `instrument` (a definition name or file) on the VISA `resource`; `visa_library` as PyVISA
    takes it (``@py``, the default; ``PATH.yaml@sim`` for pyvisa-sim; a vendor VISA's path); `max_drive` the rig's
    maximum (never above the definition's). `ConfigError` naming the instrument, resource or library when they do
    not answer or do not match."""
    definition = load_light_definition(instrument)
    manager, handle = _open_resource(resource, visa_library, definition)
    try:
        return VisaLight(definition, instrument, handle, manager, resource, max_drive)
    except BaseException:
        handle.close()
        if not manager.list_opened_resources():
            manager.close()
        raise
