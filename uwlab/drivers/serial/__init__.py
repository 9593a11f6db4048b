"""Serial instruments: the light controller and the spectrometer of the tank rig.

`open_light` / `open_spectrometer` return a driver for the named protocol (``uwlab-ascii`` is the
only one so far; another protocol is another `Light` / `Spectrometer` subclass registered here).
"""

from __future__ import annotations

from uwlab.drivers.serial.ascii import PROTOCOL as ASCII_PROTOCOL
from uwlab.drivers.serial.ascii import AsciiLight, AsciiSpectrometer
from uwlab.drivers.serial.base import Light, Spectrometer
from uwlab.errors import ConfigError

LIGHT_DRIVERS: dict[str, type[Light]] = {ASCII_PROTOCOL: AsciiLight}
SPECTROMETER_DRIVERS: dict[str, type[Spectrometer]] = {ASCII_PROTOCOL: AsciiSpectrometer}
PROTOCOLS = tuple(LIGHT_DRIVERS)


def open_light(port: str, protocol: str = ASCII_PROTOCOL, **options) -> Light:
    """Open the light on ``port``; ``options`` go to the driver (e.g. ``timeout_s``, ``retries``)."""
    return _driver(LIGHT_DRIVERS, protocol)(port, **options)


def open_spectrometer(port: str, protocol: str = ASCII_PROTOCOL, **options) -> Spectrometer:
    """Open the spectrometer on ``port``; ``options`` go to the driver."""
    return _driver(SPECTROMETER_DRIVERS, protocol)(port, **options)


def _driver(registry: dict, protocol: str):
    if protocol not in registry:
        raise ConfigError("protocol", protocol, f"must be one of {', '.join(sorted(registry))}")
    return registry[protocol]


__all__ = ["Light", "Spectrometer", "open_light", "open_spectrometer", "PROTOCOLS"]
