"""A light on a serial line speaking a line protocol with acknowledged commands (``uwlab-ascii``,
docs/serial-protocol.md), driven by its instrument definition (``adapter = "serial"``).

The definition names the line settings (baud rate, reply timeout, retries, how long a vanished port may take to
come back), what ``*IDN?`` must contain and the command strings; the driver is the ``uwlab-ascii`` one
(`uwlab.drivers.serial.ascii.AsciiLight`: every command answered ``OK`` or ``ERR``, resets and reopened ports
recovered and the settings restored and read back), sending the definition's strings. The level is the drive:
``LEV <x>`` with x in [0, 1]. After every set the setting is read back and a disagreement refused; on close the
output is switched off (the safe state) and read back (`safe_state_reached`).
"""

from __future__ import annotations

from typing import Any

from uwlab.drivers.instruments.definition import SerialLightDefinition
from uwlab.drivers.serial.ascii import AsciiLight
from uwlab.drivers.serial.base import check_level
from uwlab.drivers.serial.protocol import format_float, parse_bool, parse_float
from uwlab.errors import ConfigError, DeviceError

LEVEL_TOLERANCE = 1e-9


class SerialLight(AsciiLight):
    """A ``uwlab-ascii`` light whose command strings and line settings come from its definition."""

    def __init__(self, definition: SerialLightDefinition, name: str, port: str) -> None:
        self.definition, self.name = definition, name
        self.safe_state_reached: bool | None = None
        self.keep_output = False
        self._closed = False
        super().__init__(
            port,
            timeout_s=definition.timeout_ms / 1000.0,
            retries=definition.retries,
            reopen_s=definition.reopen_s,
            baudrate=definition.baudrate,
        )
        missing = [w for w in definition.identity_contains if w.lower() not in self.identity_at_open.lower()]
        if missing:
            self._closed = True
            super().close()
            raise ConfigError(
                "instrument", name, f"{port} answers *IDN? {self.identity_at_open!r}, not {' '.join(missing)}"
            )

    @property
    def level_tolerance(self) -> float:
        return LEVEL_TOLERANCE

    def identity(self) -> str:
        return self.transport.query(self.definition.commands.identity)

    def set_output(self, on: bool) -> None:
        c = self.definition.commands
        header, _, argument = c.set_output.format(state=c.on_token if on else c.off_token).partition(" ")
        self._set(header, argument, c.query_output, parse_bool, bool(on))
        if self.output() != bool(on):
            raise DeviceError(f"{self.name} on {self.port}: output set {'on' if on else 'off'} reads back otherwise")

    def output(self) -> bool:
        return self.transport.query(self.definition.commands.query_output, parse_bool)

    def set_level(self, level: float) -> None:
        c = self.definition.commands
        level = check_level(level)
        header, _, argument = c.set_drive.format(value=format_float(level)).partition(" ")
        self._set(header, argument, c.query_drive, parse_float, level)
        read = self.level()
        if abs(read - level) > LEVEL_TOLERANCE:
            raise DeviceError(f"{self.name} on {self.port}: level set {level:g} reads back {read:g}")

    def level(self) -> float:
        return self.transport.query(self.definition.commands.query_drive, parse_float)

    def state(self) -> dict[str, Any]:
        """The read-back: ``on`` and ``level`` (the protocol has no drive current to report)."""
        return {"on": self.output(), "level": self.level()}

    def __exit__(self, exc_type: Any, *exc_info: Any) -> None:
        if exc_type is None and self.keep_output:
            self._closed = True
            super().close()
        else:
            self.close()

    def close(self) -> None:
        """Switch the output off (the safe state), record whether it read back off, release the port; once."""
        if self._closed:
            return
        self._closed = True
        try:
            self.transport.command(self.definition.commands.set_output.format(state=self.definition.commands.off_token))
            self.safe_state_reached = not self.output()
        except (DeviceError, ConfigError):
            self.safe_state_reached = False
        finally:
            super().close()
