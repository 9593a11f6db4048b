"""A simulated Ocean Insight spectrometer (a Flame-S) on a bench, behind python-seabreeze's own ``Spectrometer``.

What is simulated sits below seabreeze's public class, where a backend would be: `SimSeaBreezeDevice` has the shape
of a backend's ``SeaBreezeDevice`` (``serial_number``, ``model``, ``is_open``, ``open``/``close``, ``features``
and the accessor ``f`` with the ``spectrometer`` and ``nonlinearity_coefficients`` features, as
``seabreeze.types`` declares them), and `spectrometer_class` returns a subclass of
``seabreeze.spectrometers.Spectrometer`` whose only change is where it finds devices (the attached simulated ones,
instead of the USB bus). Everything a caller uses — ``intensities`` with seabreeze's own dark and nonlinearity
corrections, ``integration_time_micros`` with its error mapping, ``wavelengths``, ``max_intensity``, ``f`` — is
seabreeze's code running on the simulated device. Chosen by ``uwlab spectrum --sim`` and ``uwlab spectrometer
--sim``; the real driver never imports this module (it takes a spectrometer class from its caller).

The detector (`SimulatedDevice`, from what the manuals and seabreeze say a device reports): each optical pixel
collects ``signal_counts_per_s`` (light) plus ``dark_counts_per_s`` (thermal) for the integration time — linear
counts x — and reads ``electric_dark_counts + x / (1 + a·x)`` (a sublinear response, exactly undone by seabreeze's
correction ``x' = x / p(x)`` with the stored coefficients ``[1, −a]``), clipped at ``max_intensity``; the masked
pixels ``dark_pixel_indices`` read the electric-dark level only. A device without masked pixels is nonlinear in its
whole raw reading ``r ↦ r / (1 + a·r)``, since seabreeze evaluates the polynomial on raw counts when there is no
electric-dark level to subtract. Readings are noise-free.

The bench (`SimBench`): light of spectral irradiance E(λ) reaches a collecting optic of area A (a CC-3 cosine
corrector unless told otherwise); each pixel, of wavelength spread dλ, collects the energy E·A·dλ per second, and
one count stands for the instrument's energy per count `response_uj_per_count` (the truth a calibration must
recover, which uwlab's calibration code never sees): counts/s = E [µW/cm²/nm] · A [cm²] · dλ [nm] / C [µJ/count]
(OceanView manual, "Absolute Irradiance": the definition of C). Its default light is a quartz-tungsten-halogen
calibration lamp: a blackbody at `LAMP_TEMPERATURE_K` (Planck's law, CODATA 2018 constants) scaled to
`LAMP_W_M2_NM_AT_560` at 560 nm; `SimBench.light_from_table` lights it with a lamp file's irradiance instead.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import numpy as np
from seabreeze.spectrometers import SeaBreezeError
from seabreeze.spectrometers import Spectrometer as SeabreezeSpectrometer

H_J_S = 6.62607015e-34
C_M_S = 299792458.0
K_B_J_K = 1.380649e-23
LAMP_TEMPERATURE_K = 3100.0
LAMP_W_M2_NM_AT_560 = 0.1
CC3_AREA_CM2 = np.pi * 0.195**2
"""A CC-3 cosine corrector's 3.9 mm diffuser [cm²]."""
UW_CM2_PER_W_M2 = 100.0
"""1 W/m² = 1e6 µW / 1e4 cm² = 100 µW/cm²."""


def planck_w_m2_sr_nm(wavelength_nm, temperature_k: float) -> np.ndarray:
    """Blackbody spectral radiance [W/(m² sr nm)]: 2hc²/λ⁵ / (exp(hc/λkT) − 1)."""
    lam = np.asarray(wavelength_nm, dtype=float) * 1e-9
    return 2 * H_J_S * C_M_S**2 / lam**5 / np.expm1(H_J_S * C_M_S / (lam * K_B_J_K * temperature_k)) * 1e-9


def lamp_w_m2_nm(wavelength_nm) -> np.ndarray:
    """The default calibration lamp's spectral irradiance at the optic [W/m²/nm]."""
    return (
        LAMP_W_M2_NM_AT_560
        * planck_w_m2_sr_nm(wavelength_nm, LAMP_TEMPERATURE_K)
        / planck_w_m2_sr_nm(560.0, LAMP_TEMPERATURE_K)
    )


def response_uj_per_count(wavelength_nm) -> np.ndarray:
    """The simulated instrument's energy per count [µJ/count]: least (most sensitive) near 550 nm."""
    lam = np.asarray(wavelength_nm, dtype=float)
    return 2e-7 / (0.2 + np.exp(-(((lam - 550.0) / 250.0) ** 2)))


def flame_wavelengths_nm(pixels: int = 2048) -> np.ndarray:
    """A Flame-like wavelength calibration: a quadratic in the pixel index, 340–1057 nm."""
    i = np.arange(pixels, dtype=float)
    return 340.0 + 0.33 * i + 1e-5 * i**2


def neighbour_spread_nm(wavelength_nm: np.ndarray) -> np.ndarray:
    """Each pixel's wavelength spread: the mean distance to its two neighbours, one neighbour at the ends."""
    n = len(wavelength_nm)
    spread = np.empty(n)
    for i in range(n):
        sides = []
        if i > 0:
            sides.append(wavelength_nm[i] - wavelength_nm[i - 1])
        if i < n - 1:
            sides.append(wavelength_nm[i + 1] - wavelength_nm[i])
        spread[i] = sum(sides) / len(sides)
    return spread


@dataclass
class SimulatedDevice:
    """What the simulated spectrometer measures (module docstring); ``light_on`` False blocks the light."""

    serial: str = "FLMS01234"
    model: str = "FLAMES"
    wavelength_nm: np.ndarray = field(default_factory=flame_wavelengths_nm)
    signal_counts_per_s: np.ndarray | None = None
    dark_counts_per_s: float = 0.0
    electric_dark_counts: float = 1500.0
    dark_pixel_indices: list[int] = field(default_factory=lambda: list(range(2, 18)))
    nonlinearity_a: float | None = 1e-6
    max_intensity: float = 65535.0
    limits_us: tuple[int, int] = (1000, 65_000_000)
    light_on: bool = True
    integration_us: int | None = None
    acquisitions: int = 0
    is_open: bool = False

    def raw(self) -> np.ndarray:
        if self.integration_us is None:
            raise SeaBreezeError("integration time never set")  # a caller must set it: the device's is unknown
        self.acquisitions += 1
        t_s = self.integration_us * 1e-6
        signal = np.zeros_like(self.wavelength_nm) if self.signal_counts_per_s is None else self.signal_counts_per_s
        x = (signal * self.light_on + self.dark_counts_per_s) * t_s
        offset = self.electric_dark_counts
        if self.nonlinearity_a is not None and self.dark_pixel_indices:
            x = x / (1.0 + self.nonlinearity_a * x)
        raw = offset + x
        if self.nonlinearity_a is not None and not self.dark_pixel_indices:
            raw = raw / (1.0 + self.nonlinearity_a * raw)
        raw[self.dark_pixel_indices] = offset
        return np.minimum(raw, self.max_intensity)


class SpectrometerFeature:
    """seabreeze's spectrometer feature (``f.spectrometer``) of a `SimulatedDevice`."""

    def __init__(self, device: SimulatedDevice) -> None:
        self._device = device
        self._spectrum_length = device.wavelength_nm.size

    def set_trigger_mode(self, mode: int) -> None:
        if mode != 0:
            raise SeaBreezeError(f"trigger mode {mode} is not simulated (only 0, free running)")

    def set_integration_time_micros(self, integration_time_micros: int) -> None:
        low, high = self._device.limits_us
        if not low <= integration_time_micros <= high:
            raise SeaBreezeError("Specified integration time is out of range.")
        self._device.integration_us = int(integration_time_micros)

    def get_integration_time_micros_limits(self) -> tuple[int, int]:
        return self._device.limits_us

    def get_maximum_intensity(self) -> float:
        return self._device.max_intensity

    def get_electric_dark_pixel_indices(self) -> list[int]:
        return list(self._device.dark_pixel_indices)

    def get_wavelengths(self):
        return self._device.wavelength_nm.copy()

    def get_intensities(self):
        return self._device.raw()


class NonlinearityFeature:
    """seabreeze's ``f.nonlinearity_coefficients`` of a `SimulatedDevice`: c₀, c₁ of ``1 − a·x``."""

    def __init__(self, device: SimulatedDevice) -> None:
        self._device = device

    def get_nonlinearity_coefficients(self) -> list[float]:
        assert self._device.nonlinearity_a is not None
        return [1.0, -self._device.nonlinearity_a]


class SimSeaBreezeDevice:
    """A backend ``SeaBreezeDevice`` (``seabreeze.types.SeaBreezeDevice``) of a `SimulatedDevice`."""

    def __init__(self, device: SimulatedDevice) -> None:
        self._device = device
        spectrometer = SpectrometerFeature(device)
        nonlinearity = None if device.nonlinearity_a is None else NonlinearityFeature(device)
        self.features: dict[str, list[Any]] = {
            "spectrometer": [spectrometer],
            "nonlinearity_coefficients": [] if nonlinearity is None else [nonlinearity],
        }
        self.f = SimpleNamespace(spectrometer=spectrometer, nonlinearity_coefficients=nonlinearity)

    @property
    def serial_number(self) -> str:
        return self._device.serial

    @property
    def model(self) -> str:
        return self._device.model

    @property
    def is_open(self) -> bool:
        return self._device.is_open

    def open(self) -> None:
        self._device.is_open = True

    def close(self) -> None:
        self._device.is_open = False


def spectrometer_class(*devices: SimulatedDevice) -> type[SeabreezeSpectrometer]:
    """seabreeze's ``Spectrometer`` finding ``devices`` (what it would find on the USB bus); its other methods are
    seabreeze's own."""
    backend = SimpleNamespace(SeaBreezeDevice=SimSeaBreezeDevice, SeaBreezeError=SeaBreezeError)

    def list_devices() -> list[SimSeaBreezeDevice]:
        return [SimSeaBreezeDevice(device) for device in devices]

    def from_first_available(cls):
        for dev in list_devices():
            if not dev.is_open:
                return cls(dev)
        raise SeaBreezeError("No unopened device found.")

    def from_serial_number(cls, serial: str | None = None):
        if serial is None:
            return cls.from_first_available()
        for dev in list_devices():
            if dev.serial_number == str(serial):
                if dev.is_open:
                    raise SeaBreezeError("Device already opened.")
                return cls(dev)
        raise SeaBreezeError(f"No device attached with serial number '{serial}'.")

    return type(
        "Spectrometer",
        (SeabreezeSpectrometer,),
        {
            "_backend": backend,
            "from_first_available": classmethod(from_first_available),
            "from_serial_number": classmethod(from_serial_number),
            "attached": devices,
        },
    )


@dataclass
class SimBench:
    """A `SimulatedDevice` behind a collecting optic of ``area_cm2``, lit by ``light_w_m2_nm`` (module docstring);
    ``log`` receives what the bench does when it is told to block or unblock the light."""

    device: SimulatedDevice = field(default_factory=lambda: SimulatedDevice(dark_counts_per_s=400.0))
    area_cm2: float = CC3_AREA_CM2
    light_w_m2_nm: Callable[[np.ndarray], np.ndarray] = lamp_w_m2_nm
    log: Callable[[str], None] = field(default=lambda message: print(message, file=sys.stderr))

    def __post_init__(self) -> None:
        self.illuminate()

    def illuminate(self) -> None:
        """The device's counts per second from the light: E [µW/cm²/nm] · A · dλ / C."""
        wavelength_nm = self.device.wavelength_nm
        e_uw_cm2_nm = self.light_w_m2_nm(wavelength_nm) * UW_CM2_PER_W_M2
        self.device.signal_counts_per_s = (
            e_uw_cm2_nm * self.area_cm2 * neighbour_spread_nm(wavelength_nm) / response_uj_per_count(wavelength_nm)
        )

    def light_from_table(self, wavelength_nm: np.ndarray, uw_cm2_nm: np.ndarray) -> None:
        """Light the bench with a tabulated lamp [µW/cm²/nm] (linear between rows, dark outside them)."""
        table_nm, table_w = np.asarray(wavelength_nm, float), np.asarray(uw_cm2_nm, float) / UW_CM2_PER_W_M2
        self.light_w_m2_nm = lambda nm: np.interp(nm, table_nm, table_w, left=0.0, right=0.0)
        self.illuminate()

    def block(self) -> None:
        self.device.light_on = False
        self.log("sim: light blocked")

    def unblock(self) -> None:
        self.device.light_on = True
        self.log("sim: light unblocked")

    def spectrometer_class(self) -> type[SeabreezeSpectrometer]:
        return spectrometer_class(self.device)
