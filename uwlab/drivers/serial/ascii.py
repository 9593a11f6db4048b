"""``uwlab-ascii`` drivers (SCPI-style, docs/serial-protocol.md) for the light and the spectrometer.

Each driver remembers the settings it sent; after an unrequested reset (a banner line) it sends
them again before retrying the interrupted command, so a reset instrument ends up as commanded.
"""
from __future__ import annotations

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
from uwlab.drivers.serial.transport import LineTransport

PROTOCOL = "uwlab-ascii"
SPECTRUM_MARGIN_S = 2.0


class _AsciiInstrument:
    """Transport, remembered settings and the commands every ``uwlab-ascii`` instrument has."""

    def __init__(self, port: str, *, timeout_s: float = 1.0, retries: int = 3, reopen_s: float = 5.0):
        self.port = port
        self._settings: dict[str, str] = {}
        self.transport = LineTransport(
            port, timeout_s=timeout_s, retries=retries, reopen_s=reopen_s, on_reset=self._reapply
        ).open()

    def identity(self) -> str:
        return self.transport.query("*IDN?")

    def reset(self) -> None:
        self.transport.reset()
        self._settings.clear()

    def close(self) -> None:
        self.transport.close()

    def _set(self, header: str, argument: str) -> None:
        command = f"{header} {argument}"
        self.transport.command(command)
        self._settings[header] = command

    def _reapply(self) -> None:
        for command in list(self._settings.values()):
            self.transport.command(command)


class AsciiLight(_AsciiInstrument, Light):
    """Light controller: ``OUTP ON|OFF``, ``OUTP?``, ``LEV <x>``, ``LEV?``."""

    def set_output(self, on: bool) -> None:
        self._set("OUTP", "ON" if on else "OFF")

    def output(self) -> bool:
        return self.transport.query("OUTP?", parse_bool)

    def set_level(self, level: float) -> None:
        self._set("LEV", format_float(check_level(level)))

    def level(self) -> float:
        return self.transport.query("LEV?", parse_float)


class AsciiSpectrometer(_AsciiInstrument, Spectrometer):
    """Spectrometer: ``SPEC:INT <ms>``, ``SPEC:INT?``, ``SPEC:AVG <n>``, ``SPEC:AVG?``, ``SPEC:READ?``."""

    def __init__(self, port: str, **kwargs):
        super().__init__(port, **kwargs)
        self.last_saturated = False

    def set_integration_ms(self, integration_ms: float) -> None:
        self._set("SPEC:INT", format_float(check_integration_ms(integration_ms)))

    def integration_ms(self) -> float:
        return self.transport.query("SPEC:INT?", parse_float)

    def set_averaging(self, averaging: int) -> None:
        self._set("SPEC:AVG", str(check_averaging(averaging)))

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
