"""``uwlab-ascii`` drivers (SCPI-style, docs/serial-protocol.md) for the light and the spectrometer.

Each driver remembers the identity (``*IDN?``) found at open and the settings it sent. Whenever the
transport finds that the instrument may have lost them — an unrequested reset (a banner line) or a
reopened port (the instrument, or its USB adapter, restarted) — the driver first checks that the same
instrument answers (a reopened device path may now lead to another one: USB re-enumeration, a reused
pseudo-terminal), letting go of the port and trying again until ``reopen_s`` has passed; then it sends
every setting again and reads each one back, until the read-backs agree with no further reset in between
(at most `RESTORE_ATTEMPTS` times), then retries the interrupted command. A restored state that still
disagrees, or another instrument on the port, is one `DeviceError`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import cast

import numpy as np

from uwlab.drivers.serial.base import (
    Light,
    Spectrometer,
    check_averaging,
    check_integration_ms,
    check_level,
)
from uwlab.drivers.serial.protocol import (
    format_float,
    parse_bool,
    parse_float,
    parse_int,
    parse_spectrum_lines,
)
from uwlab.drivers.serial.transport import BAUDRATE, LineTransport
from uwlab.errors import DeviceError

PROTOCOL = "uwlab-ascii"
SPECTRUM_MARGIN_S = 2.0
RESTORE_ATTEMPTS = 3
IDENTITY_RETRY_S = 0.2
READBACK_TOLERANCE = 1e-9


@dataclass(frozen=True)
class _Setting:
    """One remembered setting: the command that applies it, the query that reads it back, the value sent."""

    command: str
    query: str
    parse: Callable[[str], object]
    value: object

    def agrees(self, reported: object) -> bool:
        if isinstance(self.value, bool) or isinstance(self.value, int):
            return reported == self.value
        got, want = float(cast(float, reported)), float(cast(float, self.value))  # parsed numbers
        return abs(got - want) <= READBACK_TOLERANCE * max(1.0, abs(want))


class _AsciiInstrument:
    """Transport, remembered settings and the commands every ``uwlab-ascii`` instrument has."""

    def __init__(
        self, port: str, *, timeout_s: float = 1.0, retries: int = 3, reopen_s: float = 5.0, baudrate: int = BAUDRATE
    ):
        self.port = port
        self._settings: dict[str, _Setting] = {}
        self.transport = LineTransport(
            port, baudrate=baudrate, timeout_s=timeout_s, retries=retries, reopen_s=reopen_s, on_recover=self._restore
        ).open()
        try:
            self.identity_at_open = self.identity()
        except BaseException:
            self.transport.close()
            raise

    @property
    def recoveries(self) -> int:
        return self.transport.recoveries

    def identity(self) -> str:
        return self.transport.query("*IDN?")

    def reset(self) -> None:
        self.transport.reset()
        self._settings.clear()

    def close(self) -> None:
        self.transport.close()

    def _set(self, header: str, argument: str, query: str, parse: Callable[[str], object], value: object) -> None:
        command = f"{header} {argument}"
        self.transport.command(command)
        self._settings[header] = _Setting(command, query, parse, value)

    def _restore(self) -> None:
        """Check the instrument's identity, send every remembered setting again and read each back (called by
        the transport after a recovery)."""
        self._check_identity()
        disagreeing: list[str] = []
        for _ in range(RESTORE_ATTEMPTS):
            recoveries = self.transport.recoveries
            for setting in list(self._settings.values()):
                self.transport.command(setting.command)
            disagreeing = []
            for setting in list(self._settings.values()):
                reported = self.transport.query(setting.query, setting.parse)
                if not setting.agrees(reported):
                    disagreeing.append(f"{setting.query} {reported!r} (sent {setting.command!r})")
            if not disagreeing and self.transport.recoveries == recoveries:
                return
        detail = "; ".join(disagreeing) or "the instrument kept resetting"
        raise DeviceError(
            f"{self.port}: settings not restored after a reset or reopen ({RESTORE_ATTEMPTS} attempts): {detail}"
        )

    def _check_identity(self) -> None:
        deadline = time.monotonic() + self.transport.reopen_s
        while (found := self.identity()) != self.identity_at_open:
            if time.monotonic() > deadline:
                raise DeviceError(
                    f"{self.port}: another instrument answers after a reopen ({found!r}; this port's "
                    f"was {self.identity_at_open!r})"
                )
            self.transport.close()
            time.sleep(IDENTITY_RETRY_S)


class AsciiLight(_AsciiInstrument, Light):
    """Light controller: ``OUTP ON|OFF``, ``OUTP?``, ``LEV <x>``, ``LEV?``."""

    def set_output(self, on: bool) -> None:
        self._set("OUTP", "ON" if on else "OFF", "OUTP?", parse_bool, bool(on))

    def output(self) -> bool:
        return self.transport.query("OUTP?", parse_bool)

    def set_level(self, level: float) -> None:
        level = check_level(level)
        self._set("LEV", format_float(level), "LEV?", parse_float, level)

    def level(self) -> float:
        return self.transport.query("LEV?", parse_float)


class AsciiSpectrometer(_AsciiInstrument, Spectrometer):
    """Spectrometer: ``SPEC:INT <ms>``, ``SPEC:INT?``, ``SPEC:AVG <n>``, ``SPEC:AVG?``, ``SPEC:READ?``."""

    def __init__(self, port: str, **kwargs):
        super().__init__(port, **kwargs)
        self.last_saturated = False

    def set_integration_ms(self, integration_ms: float) -> None:
        integration_ms = check_integration_ms(integration_ms)
        self._set("SPEC:INT", format_float(integration_ms), "SPEC:INT?", parse_float, integration_ms)

    def integration_ms(self) -> float:
        return self.transport.query("SPEC:INT?", parse_float)

    def set_averaging(self, averaging: int) -> None:
        averaging = check_averaging(averaging)
        self._set("SPEC:AVG", str(averaging), "SPEC:AVG?", parse_int, averaging)

    def averaging(self) -> int:
        return self.transport.query("SPEC:AVG?", parse_int)

    def read_spectrum(self) -> tuple[np.ndarray, np.ndarray]:
        acquisition_s = self.integration_ms() * self.averaging() / 1000.0
        timeout_s = self.transport.timeout_s + acquisition_s + SPECTRUM_MARGIN_S
        saturated, (wavelength_nm, irradiance) = self.transport.query_block(
            "SPEC:READ?", timeout_s, parse_spectrum_lines
        )
        self.last_saturated = saturated
        return wavelength_nm, irradiance
