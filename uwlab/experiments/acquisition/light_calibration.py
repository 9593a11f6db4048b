"""Light calibration: spectral irradiance measured at N light levels (the level → irradiance curve).

The light is switched on and stepped through ``levels`` evenly spaced in [0, 1]; at each level the
spectrometer reads one spectrum. If the spectrometer saturates, its integration time is halved and the
reading repeated (down to the instrument minimum). The light's output state and level are restored
afterwards, whatever happens.

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
from uwlab.errors import ConfigError, DeviceError
from uwlab.experiments.acquisition.spectra import illuminance_lux, irradiance_w_m2
from uwlab.model.data import MAX_CSV_BYTES, read_text

SPECTRAL_PREFIX = "irradiance_w_m2_nm_"
CURVE_COLUMNS = ("level", "irradiance_w_m2", "illuminance_lux")
MAX_LEVELS = 1000

Progress = Callable[[int, int], None]


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
    return _calibration(np.asarray(levels, dtype=float), spectra[0][0], np.array([e for _, e in spectra]))


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
