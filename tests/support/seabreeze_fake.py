"""A simulated Ocean Insight spectrometer behind python-seabreeze's own API, and the lamp truth the tests use.

`fake_seabreeze(*devices)` returns a class with the public API of ``seabreeze.spectrometers.Spectrometer``
(``from_serial_number``, ``wavelengths``, ``intensities``, ``max_intensity``, ``integration_time_micros``,
``integration_time_micros_limits``, ``f`` …) whose instances read a `SimulatedDevice`. `api_mismatches()` compares
every public member of the fake (and of the feature objects behind ``f``) with seabreeze's classes by
`inspect.signature`: a renamed method or parameter in a new seabreeze release fails the tests that use the fake.

The simulated detector: each optical pixel collects ``signal_counts_per_s`` (light) plus ``dark_counts_per_s``
(thermal) for the integration time — linear counts x — and reads ``electric_dark_counts + x / (1 + a·x)`` (a
sublinear response, exactly undone by seabreeze's correction ``x' = x / p(x)`` with the stored coefficients
``[1, −a]``), clipped at ``max_intensity``; the masked pixels ``dark_pixel_indices`` read the electric-dark level
only. A device without masked pixels is nonlinear in its whole raw reading ``r ↦ r / (1 + a·r)``, since seabreeze
evaluates the polynomial on raw counts when there is no electric-dark level to subtract: either way the stored
coefficients are exact under seabreeze's correction, which is what they are for.

The lamp: a blackbody at `LAMP_TEMPERATURE_K` (Planck's law, CODATA 2018 constants) scaled to
`LAMP_W_M2_NM_AT_560` at 560 nm — a quartz-tungsten-halogen calibration lamp's shape; the calibration file
``tests/data/ocean_insight_calibration_3100k.csv`` tabulates `calibration_uj_per_count` (a smooth instrument
response, the energy per count) on 335–1065 nm in 1 nm steps.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass, field

import numpy as np
from seabreeze.spectrometers import SeaBreezeError
from seabreeze.spectrometers import Spectrometer as SeabreezeSpectrometer
from seabreeze.types import SeaBreezeNonlinearityCoefficientsFeature, SeaBreezeSpectrometerFeature

H_J_S = 6.62607015e-34
C_M_S = 299792458.0
K_B_J_K = 1.380649e-23
LAMP_TEMPERATURE_K = 3100.0
LAMP_W_M2_NM_AT_560 = 0.1
CC3_AREA_CM2 = np.pi * 0.195**2  # CC-3: 3.9 mm diameter diffuser


def planck_w_m2_sr_nm(wavelength_nm, temperature_k: float) -> np.ndarray:
    """Blackbody spectral radiance [W/(m² sr nm)]: 2hc²/λ⁵ / (exp(hc/λkT) − 1)."""
    lam = np.asarray(wavelength_nm, dtype=float) * 1e-9
    return 2 * H_J_S * C_M_S**2 / lam**5 / np.expm1(H_J_S * C_M_S / (lam * K_B_J_K * temperature_k)) * 1e-9


def lamp_w_m2_nm(wavelength_nm) -> np.ndarray:
    """The calibration lamp's spectral irradiance at the cosine corrector [W/m²/nm]."""
    return (
        LAMP_W_M2_NM_AT_560
        * planck_w_m2_sr_nm(wavelength_nm, LAMP_TEMPERATURE_K)
        / planck_w_m2_sr_nm(560.0, LAMP_TEMPERATURE_K)
    )


def calibration_uj_per_count(wavelength_nm) -> np.ndarray:
    """The simulated instrument's energy per count [µJ/count]: least (most sensitive) near 550 nm."""
    lam = np.asarray(wavelength_nm, dtype=float)
    return 2e-7 / (0.2 + np.exp(-(((lam - 550.0) / 250.0) ** 2)))


def flame_wavelengths_nm(pixels: int = 2048) -> np.ndarray:
    """A Flame-like wavelength calibration: a quadratic in the pixel index, 340–1057 nm."""
    i = np.arange(pixels, dtype=float)
    return 340.0 + 0.33 * i + 1e-5 * i**2


@dataclass
class SimulatedDevice:
    """What the fake spectrometer measures (see the module docstring); ``light_on`` False blocks the light."""

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
            raise SeaBreezeError("integration time never set")  # the test's guard: the driver sets it on opening
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


class _SpectrometerFeature:
    """The parts of seabreeze's spectrometer feature (``f.spectrometer``) the driver reads."""

    def __init__(self, device: SimulatedDevice) -> None:
        self._device = device

    def get_electric_dark_pixel_indices(self) -> list[int]:
        return list(self._device.dark_pixel_indices)

    def get_integration_time_micros_limits(self) -> tuple[int, int]:
        return self._device.limits_us

    def get_maximum_intensity(self) -> float:
        return self._device.max_intensity

    def get_wavelengths(self):
        return self._device.wavelength_nm.copy()


class _NonlinearityFeature:
    def __init__(self, device: SimulatedDevice) -> None:
        self._device = device

    def get_nonlinearity_coefficients(self) -> list[float]:
        return [1.0, -self._device.nonlinearity_a]


class _Features:
    def __init__(self, device: SimulatedDevice) -> None:
        self.spectrometer = _SpectrometerFeature(device)
        self.nonlinearity_coefficients = None if device.nonlinearity_a is None else _NonlinearityFeature(device)


class FakeSpectrometer:
    """seabreeze's ``Spectrometer`` over a `SimulatedDevice` (subclassed by `fake_seabreeze` with the devices
    attached)."""

    attached: tuple[SimulatedDevice, ...] = ()

    def __init__(self, device: SimulatedDevice) -> None:
        self._dev = device
        self.open()

    @classmethod
    def from_first_available(cls) -> FakeSpectrometer:
        for device in cls.attached:
            if not device.is_open:
                return cls(device)
        raise SeaBreezeError("No unopened device found.")

    @classmethod
    def from_serial_number(cls, serial: str | None = None) -> FakeSpectrometer:
        if serial is None:
            return cls.from_first_available()
        for device in cls.attached:
            if device.serial == str(serial):
                if device.is_open:
                    raise SeaBreezeError("Device already opened.")
                return cls(device)
        raise SeaBreezeError(f"No device attached with serial number '{serial}'.")

    def wavelengths(self):
        return self._dev.wavelength_nm.copy()

    def intensities(self, correct_dark_counts: bool = False, correct_nonlinearity: bool = False):
        if correct_dark_counts and not self._dev.dark_pixel_indices:
            raise SeaBreezeError("This device does not support dark count correction.")
        if correct_nonlinearity and self._dev.nonlinearity_a is None:
            raise SeaBreezeError("This device does not support nonlinearity correction.")
        out = self._dev.raw()
        if correct_dark_counts or correct_nonlinearity:
            offset = np.mean(out[self._dev.dark_pixel_indices]) if self._dev.dark_pixel_indices else 0.0
            out = out - offset
            if correct_nonlinearity:
                out = out / np.polyval([-self._dev.nonlinearity_a, 1.0], out)
            if not correct_dark_counts:
                out = out + offset
        return out

    @property
    def max_intensity(self) -> float:
        return self._dev.max_intensity

    def integration_time_micros(self, integration_time_micros: int) -> None:
        low, high = self._dev.limits_us
        if not low <= integration_time_micros <= high:
            raise SeaBreezeError("[Fix] Specified integration time is out of range.")
        self._dev.integration_us = int(integration_time_micros)

    @property
    def integration_time_micros_limits(self) -> tuple[int, int]:
        return self._dev.limits_us

    @property
    def serial_number(self) -> str:
        return self._dev.serial

    @property
    def model(self) -> str:
        return self._dev.model

    @property
    def pixels(self) -> int:
        return self._dev.wavelength_nm.size

    @property
    def f(self) -> _Features:
        return _Features(self._dev)

    def open(self) -> None:
        self._dev.is_open = True

    def close(self) -> None:
        self._dev.is_open = False


def fake_seabreeze(*devices: SimulatedDevice) -> type[FakeSpectrometer]:
    """A `FakeSpectrometer` class with ``devices`` attached (what ``seabreeze.spectrometers.Spectrometer`` would
    find on the USB bus)."""
    return type("Spectrometer", (FakeSpectrometer,), {"attached": tuple(devices)})


def _public(cls) -> dict[str, object]:
    return {
        name: inspect.getattr_static(cls, name) for name in dir(cls) if not name.startswith("_") and name != "attached"
    }


def _signature(member) -> list[tuple]:
    function = member.__func__ if isinstance(member, (classmethod, staticmethod)) else member
    return [(p.name, p.kind, p.default) for p in inspect.signature(function).parameters.values()]


def _mismatches(fake, real, label: str) -> list[str]:
    problems = []
    for name, member in _public(fake).items():
        if not hasattr(real, name):
            problems.append(f"{label}.{name}: not in seabreeze")
            continue
        original = inspect.getattr_static(real, name)
        if isinstance(member, property) != isinstance(original, property) or isinstance(
            member, classmethod
        ) != isinstance(original, classmethod):
            problems.append(f"{label}.{name}: {type(member).__name__} here, {type(original).__name__} in seabreeze")
        elif callable(member) or isinstance(member, classmethod):
            if _signature(member) != _signature(original):
                problems.append(
                    f"{label}.{name}{inspect.signature(member)}: seabreeze has {inspect.signature(original)}"
                )
    return problems


def api_mismatches() -> list[str]:
    """Where the fake's public API differs from seabreeze's (empty: it matches)."""
    from seabreeze.types import SeaBreezeFeatureAccessor

    accessor = SeaBreezeFeatureAccessor.__annotations__
    return (
        _mismatches(FakeSpectrometer, SeabreezeSpectrometer, "Spectrometer")
        + _mismatches(_SpectrometerFeature, SeaBreezeSpectrometerFeature, "f.spectrometer")
        + _mismatches(_NonlinearityFeature, SeaBreezeNonlinearityCoefficientsFeature, "f.nonlinearity_coefficients")
        + [f"f.{name}: not a seabreeze feature" for name in vars(_Features(SimulatedDevice())) if name not in accessor]
    )


def neighbour_spread_nm(wavelength_nm: np.ndarray) -> np.ndarray:
    """The pixel's wavelength spread, written out: mean distance to the two neighbours, one neighbour at the ends."""
    n = len(wavelength_nm)
    spread = np.empty(n)
    for i in range(n):
        left = wavelength_nm[i] - wavelength_nm[i - 1] if i > 0 else None
        right = wavelength_nm[i + 1] - wavelength_nm[i] if i < n - 1 else None
        sides = [d for d in (left, right) if d is not None]
        spread[i] = sum(sides) / len(sides)
    return spread


def lamp_counts_per_s(device: SimulatedDevice, area_cm2: float = CC3_AREA_CM2) -> np.ndarray:
    """Counts per second the lamp gives each pixel: the inverse relation S/T = E[µW/cm²/nm] · A · dλ / C."""
    wavelength_nm = device.wavelength_nm
    e_uw_cm2_nm = lamp_w_m2_nm(wavelength_nm) * 1e6 / 1e4  # W/m² → µW/cm²
    return e_uw_cm2_nm * area_cm2 * neighbour_spread_nm(wavelength_nm) / calibration_uj_per_count(wavelength_nm)


def optical(device: SimulatedDevice) -> np.ndarray:
    """The pixels that see light (not the masked electric-dark ones)."""
    mask = np.ones(device.wavelength_nm.size, dtype=bool)
    mask[device.dark_pixel_indices] = False
    return mask
