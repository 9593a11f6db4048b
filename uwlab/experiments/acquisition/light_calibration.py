"""Light calibration: spectral irradiance measured at N light levels (the level → irradiance curve).

The light is switched on and stepped through ``levels`` evenly spaced in [0, 1]; at each level the
spectrometer reads one spectrum. If the spectrometer saturates, its integration time is halved and the
reading repeated (down to the instrument minimum). The light's output state and level are restored
afterwards, whatever happens.

What is not a calibration is refused (`NotACalibration`, nothing written), by the noise of the readings themselves:
each spectrum's integrated noise σ is estimated from its bin-to-bin scatter (`integrated_noise_w_m2`). Refused:
a highest level no more than `NOISE_SIGMAS` σ of the zero level's (dark) noise above the zero level (no response:
the light does not reach the spectrometer), a zero level reading more than `NOISE_SIGMAS` σ and more than
`DARK_FRACTION` of the response (not dark: stray light, or a light that stays on at level 0), and a curve that falls
between two levels by more than `NOISE_SIGMAS` times their combined noise (not monotonic).

File format (CSV, docs/serial-protocol.md "Light calibration file"): ``#`` comment lines (provenance),
then a header ``level,irradiance_w_m2,illuminance_lux,irradiance_w_m2_nm_<λ>,...`` with one column per
wavelength [nm], and one row per level in increasing order. `load_light_calibration` reads it back.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path
from collections.abc import Callable, Sequence

import numpy as np
import pandas as pd

from uwlab.drivers.serial.base import Light, Spectrometer
from uwlab.errors import ConfigError, DeviceError, UwlabError
from uwlab.experiments.acquisition.spectra import illuminance_lux, irradiance_w_m2
from uwlab.model.data import MAX_CSV_BYTES, read_text

SPECTRAL_PREFIX = "irradiance_w_m2_nm_"
CURVE_COLUMNS = ("level", "irradiance_w_m2", "illuminance_lux")
MAX_LEVELS = 1000
NOISE_SIGMAS = 5.0
DARK_FRACTION = 0.01
NOISE_WINDOW_BINS = 31

Progress = Callable[[int, int], None]


class NotACalibration(UwlabError):
    """The measured curve is not a light calibration (no response, a zero level that is not dark, or not
    monotonic); the message names the levels."""


@dataclass(frozen=True)
class LightCalibration:
    """Per level ``i``: ``irradiance_w_m2_nm[i]`` on ``wavelength_nm`` and its integrals."""

    level: np.ndarray
    irradiance_w_m2: np.ndarray
    illuminance_lux: np.ndarray
    wavelength_nm: np.ndarray
    irradiance_w_m2_nm: np.ndarray


def calibration_levels(count: int) -> np.ndarray:
    """``count`` levels evenly spaced over [0, 1], both ends included."""
    if isinstance(count, bool) or not isinstance(count, int) or not 2 <= count <= MAX_LEVELS:
        raise ConfigError("levels", count, f"must be an integer in [2, {MAX_LEVELS}]")
    return np.linspace(0.0, 1.0, count)


def calibrate_light(
    light: Light, spectrometer: Spectrometer, levels: np.ndarray, progress: Progress | None = None
) -> LightCalibration:
    """Measure one spectrum per level; ``progress(done, total)`` is called after each."""
    initial_output, initial_level = light.output(), light.level()
    spectra: list = []
    try:
        light.set_output(True)
        for index, level in enumerate(levels):
            light.set_level(float(level))
            wavelength_nm, irradiance = measure_unsaturated(spectrometer)
            if spectra and not np.array_equal(wavelength_nm, spectra[0][0]):
                raise DeviceError(f"{spectrometer.port}: the wavelength grid changed during the calibration")
            spectra.append((wavelength_nm, irradiance))
            if progress is not None:
                progress(index + 1, len(levels))
    finally:
        light.set_level(initial_level)
        light.set_output(initial_output)
    calibration = _calibration(np.asarray(levels, dtype=float), spectra[0][0], np.array([e for _, e in spectra]))
    check_calibration(calibration)
    return calibration


def integrated_noise_w_m2(wavelength_nm: np.ndarray, irradiance_w_m2_nm: np.ndarray) -> float:
    """The standard deviation [W/m²] of ∫E dλ (trapezoid, as `irradiance_w_m2`) from one spectrum's own scatter.

    Independent bins of standard deviation σᵢ give σ² = Σ wᵢ² σᵢ² with the trapezoid weights wᵢ. σᵢ is the
    local scale of the second differences dᵢ = (Eᵢ₋₁ − 2Eᵢ + Eᵢ₊₁)/√6 (σ each for noise that varies slowly with
    wavelength, and blind to the spectrum's own slope): 1.4826 × their median |d| over `NOISE_WINDOW_BINS` bins
    (the median absolute deviation, which an edge or a line barely moves). Where a spectrum curves more per bin than
    its noise (a narrow line on a coarse grid) this is an upper bound, which only makes the checks more lenient."""
    wavelength_nm = np.asarray(wavelength_nm, dtype=float)
    spectrum = np.asarray(irradiance_w_m2_nm, dtype=float)
    steps = np.diff(wavelength_nm)
    weights = np.zeros_like(wavelength_nm)
    weights[:-1] += steps / 2
    weights[1:] += steps / 2
    scatter = np.abs(np.diff(spectrum, 2)) / np.sqrt(6)
    half = NOISE_WINDOW_BINS // 2
    padded = np.pad(scatter, (half + 1, half + 1), mode="edge")
    windows = np.lib.stride_tricks.sliding_window_view(padded, NOISE_WINDOW_BINS)[: len(spectrum)]
    sigma = 1.4826 * np.median(windows, axis=1)
    return float(np.sqrt(np.sum((weights * sigma) ** 2)))


def check_calibration(calibration: LightCalibration) -> None:
    """Refuse (`NotACalibration`) a curve with no response above the dark's noise, a zero level that is not
    dark, or a fall between levels beyond the noise (the module docstring gives the rules)."""
    level, irradiance = calibration.level, calibration.irradiance_w_m2
    noise = np.array([integrated_noise_w_m2(calibration.wavelength_nm, e) for e in calibration.irradiance_w_m2_nm])
    dark, full, response = irradiance[0], irradiance[-1], irradiance[-1] - irradiance[0]
    if response <= NOISE_SIGMAS * noise[0]:
        raise NotACalibration(
            f"not a light calibration: level {level[-1]:g} reads {full:.4g} W/m² and level {level[0]:g} "
            f"{dark:.4g} W/m², no response above the dark's noise ({NOISE_SIGMAS:g} σ = "
            f"{NOISE_SIGMAS * noise[0]:.2g} W/m²): is the light reaching the spectrometer?"
        )
    if level[0] == 0 and abs(dark) > max(NOISE_SIGMAS * noise[0], DARK_FRACTION * response):
        raise NotACalibration(
            f"not a light calibration: level 0 reads {dark:.4g} W/m², {abs(dark) / response:.1%} of the response "
            f"at level {level[-1]:g} ({full:.4g} W/m²): the zero level is not dark (stray light, or a light that "
            "stays on at level 0?)"
        )
    falls = irradiance[:-1] - irradiance[1:] > NOISE_SIGMAS * np.hypot(noise[:-1], noise[1:])
    if np.any(falls):
        i = int(np.argmax(falls))
        raise NotACalibration(
            f"not a light calibration: the irradiance falls from {irradiance[i]:.4g} W/m² at level {level[i]:g} "
            f"to {irradiance[i + 1]:.4g} W/m² at level {level[i + 1]:g}, beyond the noise: the curve must rise "
            "with the level"
        )


def measure_unsaturated(spectrometer: Spectrometer) -> tuple[np.ndarray, np.ndarray]:
    """Read a spectrum, halving the integration time while the reading saturates."""
    while True:
        wavelength_nm, irradiance = spectrometer.read_spectrum()
        if not spectrometer.last_saturated:
            return wavelength_nm, irradiance
        integration_ms, minimum_ms = spectrometer.integration_ms(), spectrometer.integration_ms_limits()[0]
        if integration_ms <= minimum_ms:
            raise DeviceError(f"{spectrometer.port}: saturated even at the minimum integration time")
        spectrometer.set_integration_ms(max(minimum_ms, integration_ms / 2))


def _calibration(levels: np.ndarray, wavelength_nm: np.ndarray, spectra: np.ndarray) -> LightCalibration:
    return LightCalibration(
        level=levels,
        irradiance_w_m2=np.array([irradiance_w_m2(wavelength_nm, e) for e in spectra]),
        illuminance_lux=np.array([illuminance_lux(wavelength_nm, e) for e in spectra]),
        wavelength_nm=wavelength_nm,
        irradiance_w_m2_nm=spectra,
    )


def save_light_calibration(path: str | Path, calibration: LightCalibration, comments: Sequence[str] = ()) -> Path:
    """Write a new calibration file; an existing file is never replaced (`ConfigError` on ``out``)."""
    path = Path(path)
    header = [*CURVE_COLUMNS, *(f"{SPECTRAL_PREFIX}{w!r}" for w in calibration.wavelength_nm.tolist())]
    curve = np.column_stack([calibration.level, calibration.irradiance_w_m2, calibration.illuminance_lux])
    try:
        with open(path, "x", newline="") as fh:
            fh.writelines(f"# {line}\n" for line in comments)
            writer = csv.writer(fh)
            writer.writerow(header)
            writer.writerows(
                [repr(v) for v in row] for row in np.hstack([curve, calibration.irradiance_w_m2_nm]).tolist()
            )
    except FileExistsError:
        raise ConfigError("out", str(path), "file exists; refusing to overwrite it") from None
    except OSError as exc:
        raise ConfigError("out", str(path), f"cannot write ({exc.strerror})") from None
    return path


def load_light_calibration(path: str | Path) -> LightCalibration:
    """Read a file written by `save_light_calibration`."""
    text = read_text(path, "light_calibration", MAX_CSV_BYTES, "CSV")
    try:
        table = pd.read_csv(io.StringIO(text), comment="#")
    except ValueError as exc:
        raise ConfigError("light_calibration", str(path), f"cannot read ({exc})") from None
    spectral = [c for c in table.columns if c.startswith(SPECTRAL_PREFIX)]
    missing = [c for c in CURVE_COLUMNS if c not in table.columns]
    if missing or len(spectral) < 2 or len(table) < 1:
        reason = f"not a light calibration file (missing {missing or 'spectral columns'})"
        raise ConfigError("light_calibration", str(path), reason)
    try:
        wavelength_nm = np.array([float(c[len(SPECTRAL_PREFIX) :]) for c in spectral])
        values = table.to_numpy(dtype=float)
    except ValueError as exc:
        raise ConfigError("light_calibration", str(path), f"non-numeric entry ({exc})") from None
    if not np.all(np.isfinite(values)) or np.any(np.diff(wavelength_nm) <= 0):
        raise ConfigError("light_calibration", str(path), "non-finite values or unsorted wavelengths")
    return LightCalibration(
        level=table["level"].to_numpy(dtype=float),
        irradiance_w_m2=table["irradiance_w_m2"].to_numpy(dtype=float),
        illuminance_lux=table["illuminance_lux"].to_numpy(dtype=float),
        wavelength_nm=wavelength_nm,
        irradiance_w_m2_nm=table[spectral].to_numpy(dtype=float),
    )
