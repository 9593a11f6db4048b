"""Instrument interfaces: a dimmable `Light` and a `Spectrometer`, whatever protocol they speak.

A new instrument is a new subclass; `uwlab.drivers.serial.open_light` / `open_spectrometer` pick
the class by protocol name. Values are checked here, before anything is sent, and refused with a
`ConfigError` naming the key: level in [0, 1], integration time in `INTEGRATION_MS_RANGE`,
averaging in `AVERAGING_RANGE`. Spectra are returned in SI-derived units: wavelength in nm and
spectral irradiance in W/m²/nm.
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np

from uwlab.errors import ConfigError

LEVEL_RANGE = (0.0, 1.0)
INTEGRATION_MS_RANGE = (1.0, 10000.0)
AVERAGING_RANGE = (1, 100)


def check_level(level: float) -> float:
    """The light level as a float in [0, 1], or `ConfigError` on ``level``."""
    return _check_range("level", level, *LEVEL_RANGE)


def check_integration_ms(integration_ms: float) -> float:
    return _check_range("integration_ms", integration_ms, *INTEGRATION_MS_RANGE)


def check_averaging(averaging: int) -> int:
    if isinstance(averaging, bool) or not isinstance(averaging, (int, np.integer)):
        raise ConfigError("averaging", averaging, "must be an integer")
    return int(_check_range("averaging", averaging, *AVERAGING_RANGE))


def _check_range(key: str, value: float, low: float, high: float) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ConfigError(key, value, "must be a number") from None
    if not (math.isfinite(number) and low <= number <= high):
        raise ConfigError(key, value, f"must be within [{low:g}, {high:g}]")
    return number


class _Instrument(ABC):
    port: str

    @abstractmethod
    def identity(self) -> str:
        """The instrument's identification string (``*IDN?`` for SCPI-style instruments)."""

    @abstractmethod
    def reset(self) -> None:
        """Return the instrument to its power-on state."""

    @abstractmethod
    def close(self) -> None:
        """Release the port; safe to call twice."""

    def __enter__(self):
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()


class Light(_Instrument):
    """A dimmable light: output on/off and a level in [0, 1], each with its read-back."""

    @abstractmethod
    def set_output(self, on: bool) -> None: ...

    @abstractmethod
    def output(self) -> bool: ...

    @abstractmethod
    def set_level(self, level: float) -> None: ...

    @abstractmethod
    def level(self) -> float: ...


class Spectrometer(_Instrument):
    """A spectroradiometer returning calibrated spectral irradiance."""

    last_saturated: bool = False

    @abstractmethod
    def set_integration_ms(self, integration_ms: float) -> None: ...

    @abstractmethod
    def integration_ms(self) -> float: ...

    @abstractmethod
    def set_averaging(self, averaging: int) -> None: ...

    @abstractmethod
    def averaging(self) -> int: ...

    @abstractmethod
    def read_spectrum(self) -> tuple[np.ndarray, np.ndarray]:
        """One (averaged) acquisition: (wavelength_nm, irradiance_w_m2_nm); sets `last_saturated`."""
