"""OceanView's irradiance calibration of an Ocean Insight spectrometer against a lamp (docs/spectrometers.md).

A lamp of known spectral irradiance (its ``.LMP`` file) is read, then a dark at the same integration time, and

    C(λ) [µJ/count] = E_lamp(λ) [µW/cm²/nm] · T [s] · A [cm²] · dλ [nm] / (S(λ) − D(λ)) [counts]

(`uwlab.drivers.ocean_insight.radiometry.lamp_calibration`, the absolute-irradiance relation solved for C). The
readings come from the spectrometer (`measure_lamp_calibration`) or from two OceanView/SpectraSuite exports
(`lamp_calibration_from_exports`); `LampCalibration.write` writes Ocean's ``*_OOIIrrad.cal`` and uwlab's CSV.
"""

from __future__ import annotations

import datetime
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from uwlab.drivers.ocean_insight.device import OceanInsightSpectrometer
from uwlab.drivers.ocean_insight.files import read_oceanview_spectrum, write_calibration_csv, write_ocean_calibration
from uwlab.drivers.ocean_insight.radiometry import check_lamp_covers, lamp_calibration
from uwlab.errors import ConfigError

EXPORT_INTEGRATION_MATCH = 1e-6
"""The lamp and dark exports' integration times must agree within this fraction."""


@dataclass(frozen=True)
class LampCalibration:
    """C(λ) [µJ/count] on the spectrometer's pixels and what it was made with."""

    wavelength_nm: np.ndarray
    uj_per_count: np.ndarray
    serial: str
    integration_ms: float
    averaging: int | None
    area_cm2: float
    source: str
    peak_fraction: float | None
    """The lamp reading's highest raw count over full scale (None from exports)."""

    @property
    def fiber_um(self) -> float:
        """The diameter [µm] of the circular optic of area A (Ocean's ``Fiber (micron)``): 2·√(A/π)."""
        return 2.0 * math.sqrt(self.area_cm2 / math.pi) * 1e4

    def header(self, lamp_source: str) -> dict[str, str]:
        """The ``Key: value`` header of Ocean's layout (OceanView's keys, then the lamp and the writer)."""
        return {
            "Date": datetime.datetime.now(datetime.UTC).strftime("%a %b %d %H:%M:%S UTC %Y"),
            "Spectrometer": self.serial,
            "Integration Time (sec)": f"{self.integration_ms / 1000.0:.6E}",
            "Fiber (micron)": f"{self.fiber_um:.1f}",
            "Lamp": lamp_source,
            "Created by": "uwlab spectrometer calibrate",
        }

    def write(self, out_cal: str | Path | None, out_csv: str | Path | None, lamp_source: str) -> None:
        """Write Ocean's ``*_OOIIrrad.cal`` and/or uwlab's CSV (the header and the area as comment lines); an
        existing file is never replaced."""
        header = self.header(lamp_source)
        if out_cal is not None:
            write_ocean_calibration(out_cal, self.wavelength_nm, self.uj_per_count, header)
        if out_csv is not None:
            comments = [f"{k}: {v}" for k, v in header.items()] + [f"collection area: {self.area_cm2!r} cm²"]
            write_calibration_csv(out_csv, self.wavelength_nm, self.uj_per_count, comments)


def measure_lamp_calibration(
    spectrometer: OceanInsightSpectrometer,
    lamp: tuple[np.ndarray, np.ndarray],
    lamp_source: str,
    block: Callable[[], None],
    unblock: Callable[[], None],
    *,
    auto_integration: bool = False,
) -> LampCalibration:
    """Read the lamp, ``block`` the light, read the dark at the same integration time and averaging, ``unblock``
    it, read the lamp less the dark and return C. ``spectrometer`` is open with a measured dark mode and the area
    A of the optic in the lamp's port. `ConfigError` when the lamp file does not cover the pixels (checked before
    anything is read), the lamp saturates the spectrometer, or a pixel that sees light has no lamp signal."""
    check_lamp_covers(spectrometer.wavelength_nm, lamp[0], lamp_source)
    if auto_integration:
        spectrometer.auto_integration()
    raw, saturated = spectrometer.read_raw()
    if saturated:
        raise ConfigError(
            "integration_ms",
            spectrometer.integration_ms(),
            "the lamp saturates the spectrometer; lower --integration-ms or use --auto-integration",
        )
    block()
    dark = spectrometer.measure_dark()
    spectrometer.use_dark(dark, "dark")
    unblock()
    signal, saturated = spectrometer.read_counts()
    if saturated:
        raise ConfigError("integration_ms", spectrometer.integration_ms(), "the lamp saturates the spectrometer")
    factor = lamp_calibration(
        spectrometer.wavelength_nm,
        signal,
        spectrometer.integration_ms() / 1000.0,
        spectrometer.area_cm2,
        lamp,
        spectrometer.electric_dark_pixels,
        lamp_source,
    )
    return LampCalibration(
        spectrometer.wavelength_nm.copy(),
        factor,
        spectrometer.serial,
        spectrometer.integration_ms(),
        spectrometer.averaging(),
        spectrometer.area_cm2,
        f"{spectrometer.model} {spectrometer.serial}",
        float(np.max(raw) / spectrometer.max_intensity),
    )


def lamp_calibration_from_exports(
    lamp_spectrum: str | Path,
    dark_spectrum: str | Path,
    lamp: tuple[np.ndarray, np.ndarray],
    lamp_source: str,
    area_cm2: float,
) -> LampCalibration:
    """C from OceanView/SpectraSuite exports of the lamp and of the dark, in counts, at one integration time (from
    their headers) on the same pixels; `ConfigError` naming the export otherwise."""
    lit = read_oceanview_spectrum(lamp_spectrum, "lamp-spectrum")
    dark = read_oceanview_spectrum(dark_spectrum, "dark-spectrum")
    for export, key, path in ((lit, "lamp-spectrum", lamp_spectrum), (dark, "dark-spectrum", dark_spectrum)):
        if export.integration_s is None:
            raise ConfigError(key, str(path), "no Integration Time (sec) or (usec) line in its header")
    assert lit.integration_s is not None and dark.integration_s is not None
    if abs(dark.integration_s / lit.integration_s - 1) > EXPORT_INTEGRATION_MATCH:
        raise ConfigError(
            "dark-spectrum",
            str(dark_spectrum),
            f"taken at {dark.integration_s:g} s, the lamp at {lit.integration_s:g} s; a dark must match the "
            "integration time",
        )
    if lit.wavelength_nm.shape != dark.wavelength_nm.shape or np.any(lit.wavelength_nm != dark.wavelength_nm):
        raise ConfigError("dark-spectrum", str(dark_spectrum), "its wavelengths are not the lamp export's")
    factor = lamp_calibration(
        lit.wavelength_nm, lit.values - dark.values, lit.integration_s, area_cm2, lamp, (), lamp_source
    )
    return LampCalibration(
        lit.wavelength_nm,
        factor,
        lit.header.get("Spectrometer") or lit.header.get("Spectrometers") or "unknown",
        lit.integration_s * 1000.0,
        None,
        area_cm2,
        f"{lamp_spectrum} less {dark_spectrum}",
        None,
    )
