"""Instrument interfaces: a dimmable `Light` and a `Spectrometer`, whatever protocol they speak.

A new instrument is a new subclass; `uwlab.drivers.serial.open_light` / `open_spectrometer` pick
the class by protocol name. Values are checked here, before anything is sent, and refused with a
`ConfigError` naming the key: level in [0, 1], integration time in `INTEGRATION_MS_RANGE`,
averaging in `AVERAGING_RANGE`. Spectra are returned in SI-derived units: wavelength in nm and
spectral irradiance in W/m²/nm.

Every instrument exposes its read-backs (`Light.readback`, `Spectrometer.readback`: the settings the
instrument reports now, not what was sent) and `recoveries`, the number of times the driver found the
instrument reset or its port reopened and re-applied its settings. A caller that reads back before and
after a measurement and sees `recoveries` unchanged knows the settings held throughout.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from uwlab.model.schema import Fraction, check, quantity

INTEGRATION_MS_RANGE = (1.0, 10000.0)
AVERAGING_RANGE = (1, 100)
IntegrationMs = quantity(*INTEGRATION_MS_RANGE, "ms", hint="the spectrometer's range")
Averaging = quantity(*AVERAGING_RANGE, "spectra", hint="the spectrometer's range", integer=True)


def check_level(level: float) -> float:
    """The light level as a float in [0, 1], or `ConfigError` on ``level``."""
    return check(Fraction, level, "level")


def check_integration_ms(integration_ms: float) -> float:
    return check(IntegrationMs, integration_ms, "integration_ms")


def check_averaging(averaging: int) -> int:
    return check(Averaging, averaging, "averaging")


@dataclass(frozen=True)
class LightReadback:
    """What the light reports now: output on/off and level in [0, 1]."""

    on: bool
    level: float


@dataclass(frozen=True)
class SpectrometerReadback:
    """What the spectrometer reports now: integration time [ms] and number of spectra averaged."""

    integration_ms: float
    averaging: int


class _Instrument(ABC):
    port: str

    @property
    @abstractmethod
    def recoveries(self) -> int:
        """How many times the instrument was found reset (or its port reopened) and its settings re-applied."""

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

    def readback(self) -> LightReadback:
        return LightReadback(self.output(), self.level())


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

    def readback(self) -> SpectrometerReadback:
        return SpectrometerReadback(self.integration_ms(), self.averaging())

    @abstractmethod
    def read_spectrum(self) -> tuple[np.ndarray, np.ndarray]:
        """One (averaged) acquisition: (wavelength_nm, irradiance_w_m2_nm); sets `last_saturated`."""
