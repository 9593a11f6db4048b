"""Counts → spectral irradiance for Ocean Insight spectrometers: OceanView's absolute-irradiance relation.

OceanView's absolute irradiance (OceanView Installation and Operation Manual, "Absolute Irradiance" and the
irradiance-calibration appendix; Ocean Insight's irradiance calibration documentation, e.g. the Ocean ST
Installation & Operation Manual, "Irradiance Calibrations") turns a pixel's counts into spectral irradiance with

    E(λ) [µW/cm²/nm] = (S(λ) − D(λ)) · C(λ) / (T · A · dλ)

- S(λ) the counts of the pixel at λ (linearised: `linearize`), D(λ) the dark counts (the device's electric dark,
  or a dark spectrum at the same integration time with the light blocked);
- C(λ) [µJ/count] the lamp calibration: the energy one count stands for, from the user's calibration file
  (OceanView's ``*_OOIIrrad.cal``, or uwlab's CSV with columns ``wavelength_nm, uJ_per_count``:
  `read_calibration_file`) interpolated linearly to the device's pixels (`calibration_on`), refused where the file
  does not cover them; OceanView's irradiance calibration finds it from a lamp of known irradiance by the same
  relation solved for C (`uj_per_count_from_lamp`, `lamp_calibration`);
- T [s] the integration time; A [cm²] the collection area of the cosine corrector or bare fibre;
- dλ [nm] the wavelength spread of the pixel: the mean distance to its two neighbours, one-sided at the ends
  (`wavelength_spread_nm`).

1 µW/cm² = 1e-6 W / 1e-4 m² = 0.01 W/m², so `irradiance_w_m2_nm` returns E · 0.01 in W/m²/nm.

Saturation (`saturated`): any *raw* pixel within 1 % of the device's full scale (seabreeze's ``max_intensity``,
to which the backends rescale the ADC's saturation level). Automatic integration (`next_integration_us`):
the longest integration whose raw peak stays under 80 % of full scale.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from uwlab.drivers.ocean_insight.files import is_ocean_calibration, read_ocean_calibration
from uwlab.errors import ConfigError
from uwlab.model.data import MAX_CSV_BYTES, read_csv_columns, read_text

UW_CM2_TO_W_M2 = 0.01
"""1 µW/cm² in W/m²."""
SATURATION_FRACTION = 0.99
"""A raw pixel at or above this fraction of ``max_intensity`` is saturated (within 1 % of full scale)."""
AUTO_FRACTION = 0.8
"""Automatic integration keeps the raw peak under this fraction of ``max_intensity``."""
CALIBRATION_COLUMNS = ("wavelength_nm", "uJ_per_count")


def wavelength_spread_nm(wavelength_nm) -> np.ndarray:
    """dλ [nm] of each pixel: the mean distance to its two neighbours; the first and last pixels use their one
    neighbour (OceanView's pixel wavelength spread).

    >>> wavelength_spread_nm([400.0, 401.0, 403.0, 406.0]).tolist()
    [1.0, 1.5, 2.5, 3.0]
    """
    wavelength_nm = np.asarray(wavelength_nm, dtype=float)
    if wavelength_nm.ndim != 1 or wavelength_nm.size < 2 or not np.all(np.diff(wavelength_nm) > 0):
        raise ConfigError("wavelength_nm", wavelength_nm.size, "needs ≥ 2 strictly increasing wavelengths")
    return np.gradient(wavelength_nm)  # central differences (λ[i+1] − λ[i−1]) / 2, one-sided at the ends


@dataclass(frozen=True)
class Calibration:
    """A lamp calibration C(λ) [µJ/count], with the collection area its file states (an ``OOIIrrad.cal``'s
    ``Fiber (micron)``; None for uwlab's CSV, which states none)."""

    wavelength_nm: np.ndarray
    uj_per_count: np.ndarray
    area_cm2: float | None
    source: str


def read_calibration_file(path: str | Path) -> Calibration:
    """A calibration file in either layout: Ocean's ``*_OOIIrrad.cal`` (suffix ``.cal`` or a ``[uJoule/count]``
    line: `uwlab.drivers.ocean_insight.files.read_ocean_calibration`) or uwlab's CSV (columns ``wavelength_nm,
    uJ_per_count``, ``#`` comment lines allowed). `ConfigError` on ``calibration`` for missing columns or
    wavelength rows, fewer than 2 rows, or factors that are negative, zero or not finite (a count always stands for
    some energy)."""
    path = Path(path)
    text = read_text(path, "calibration", MAX_CSV_BYTES, "calibration")
    if is_ocean_calibration(path, text):
        ocean = read_ocean_calibration(path, "calibration", text)
        return Calibration(ocean.wavelength_nm, ocean.uj_per_count, ocean.area_cm2, str(path))
    columns = read_csv_columns(path, CALIBRATION_COLUMNS, "calibration")
    wavelength_nm, factor = columns["wavelength_nm"], columns["uJ_per_count"]
    if wavelength_nm.size < 2:
        raise ConfigError("calibration", str(path), "needs at least 2 rows")
    bad = ~np.isfinite(factor) | (factor <= 0) | ~np.isfinite(wavelength_nm)
    if bad.any():
        i = int(np.argmax(bad))
        raise ConfigError(
            "calibration",
            str(path),
            f"uJ_per_count must be positive and finite; at {wavelength_nm[i]:g} nm it is {factor[i]:g}",
        )
    return Calibration(wavelength_nm, factor, None, str(path))


def read_calibration(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(wavelength_nm, C [µJ/count]) of a calibration file in either layout (`read_calibration_file`)."""
    calibration = read_calibration_file(path)
    return calibration.wavelength_nm, calibration.uj_per_count


def calibration_on(
    calibration_nm: np.ndarray, uj_per_count: np.ndarray, device_nm: np.ndarray, source: str = "calibration"
) -> np.ndarray:
    """C [µJ/count] linearly interpolated to the device's pixel wavelengths; `ConfigError` on ``source`` when the
    calibration does not cover the device's range (no extrapolation)."""
    device_nm = np.asarray(device_nm, dtype=float)
    if device_nm[0] < calibration_nm[0] or device_nm[-1] > calibration_nm[-1]:
        raise ConfigError(
            "calibration",
            source,
            f"covers {calibration_nm[0]:g}–{calibration_nm[-1]:g} nm, the device {device_nm[0]:g}–{device_nm[-1]:g} nm",
        )
    return np.interp(device_nm, calibration_nm, uj_per_count)


def irradiance_w_m2_nm(
    counts, dark_counts, uj_per_count, integration_s: float, area_cm2: float, wavelength_nm
) -> np.ndarray:
    """Spectral irradiance [W/m²/nm] = (S − D) · C / (T · A · dλ) [µW/cm²/nm] × 0.01 (module docstring).

    ``counts`` S and ``dark_counts`` D [counts] (D may be a scalar), ``uj_per_count`` C [µJ/count] on the same
    pixels, ``integration_s`` T [s], ``area_cm2`` A [cm²], ``wavelength_nm`` the pixels' wavelengths (for dλ).

    >>> irradiance_w_m2_nm([1100.0, 1100.0], 100.0, [2e-6, 2e-6], 0.1, 0.5, [500.0, 502.0]).tolist()
    [0.0002, 0.0002]
    """
    spread_nm = wavelength_spread_nm(wavelength_nm)
    signal = np.asarray(counts, dtype=float) - np.asarray(dark_counts, dtype=float)
    return signal * np.asarray(uj_per_count, dtype=float) / (integration_s * area_cm2 * spread_nm) * UW_CM2_TO_W_M2


def uj_per_count_from_lamp(
    lamp_uw_cm2_nm, signal_counts, integration_s: float, area_cm2: float, wavelength_nm
) -> np.ndarray:
    """C(λ) [µJ/count] = E_lamp(λ) · T · A · dλ / (S(λ) − D(λ)): OceanView's irradiance calibration, the relation
    of the module docstring solved for C with the lamp's known irradiance.

    ``lamp_uw_cm2_nm`` E_lamp [µW/cm²/nm] on the device's pixels (the ``.LMP`` interpolated), ``signal_counts``
    S − D [counts] of the lamp reading less the dark at the same integration time, ``integration_s`` T [s],
    ``area_cm2`` A [cm²], ``wavelength_nm`` the pixels (for dλ [nm]). Units: µW/cm²/nm · s · cm² · nm = µJ, per
    count. Pixels with S − D ≤ 0 have no calibration (the caller refuses them).

    >>> uj_per_count_from_lamp([10.0, 10.0], [1000.0, 1000.0], 0.1, 0.5, [500.0, 502.0]).tolist()
    [0.001, 0.001]
    """
    spread_nm = wavelength_spread_nm(wavelength_nm)
    energy_uj = np.asarray(lamp_uw_cm2_nm, dtype=float) * integration_s * area_cm2 * spread_nm
    return energy_uj / np.asarray(signal_counts, dtype=float)


UNLIT_EDGE_FRACTION = 0.05
"""In a lamp calibration, pixels without lamp signal are tolerated only within this fraction of the array at either
end (where the optically masked pixels and the detector's unusable edges are)."""


def check_lamp_covers(wavelength_nm, lamp_nm, lamp_source: str = "lamp") -> None:
    """`ConfigError` on ``lamp`` unless the lamp file's wavelengths cover the pixels' (no extrapolation)."""
    if wavelength_nm[0] < lamp_nm[0] or wavelength_nm[-1] > lamp_nm[-1]:
        raise ConfigError(
            "lamp",
            lamp_source,
            f"covers {lamp_nm[0]:g}–{lamp_nm[-1]:g} nm, the spectrometer {wavelength_nm[0]:g}–{wavelength_nm[-1]:g} nm",
        )


def lamp_calibration(
    wavelength_nm,
    signal_counts,
    integration_s: float,
    area_cm2: float,
    lamp: tuple[np.ndarray, np.ndarray],
    unlit_pixels=(),
    lamp_source: str = "lamp",
) -> np.ndarray:
    """C(λ) [µJ/count] on every pixel from a lamp reading (`uj_per_count_from_lamp`): ``signal_counts`` S − D of
    the lamp less the dark at ``integration_s``, ``lamp`` (wavelength_nm, E [µW/cm²/nm]) of its ``.LMP`` file,
    interpolated linearly to the pixels.

    `ConfigError` on ``lamp`` when the lamp file does not cover the pixels (no extrapolation) or is zero on one, and
    on ``signal`` when a pixel has S − D ≤ 0 (no lamp above the dark: lamp off, shutter closed, fibre unplugged)
    outside the device's ``unlit_pixels`` (its optically masked electric-dark pixels, which never see light) and
    the `UNLIT_EDGE_FRACTION` of the array at either end. The pixels without signal take the factor of the nearest
    pixel with signal, so the file covers every pixel as OceanView's does (a reading there is dark only)."""
    wavelength_nm = np.asarray(wavelength_nm, dtype=float)
    signal = np.asarray(signal_counts, dtype=float)
    lamp_nm, lamp_uw = lamp
    n = wavelength_nm.size
    check_lamp_covers(wavelength_nm, lamp_nm, lamp_source)
    lit = signal > 0
    tolerated = np.zeros(n, dtype=bool)
    tolerated[list(unlit_pixels)] = True
    edge = int(np.floor(UNLIT_EDGE_FRACTION * n))
    tolerated[:edge] = tolerated[n - edge :] = True
    dead = ~lit & ~tolerated
    if dead.any() or not lit.any():
        i = int(np.argmax(dead)) if dead.any() else n // 2
        raise ConfigError(
            "signal",
            f"{signal[i]:g} counts at {wavelength_nm[i]:g} nm",
            f"no lamp signal above the dark at {int((~lit).sum())} of {n} pixels: is the lamp on and its light "
            "reaching the optic?",
        )
    lamp_on_pixels = np.interp(wavelength_nm, lamp_nm, lamp_uw)
    if np.any(lit & ~(lamp_on_pixels > 0)):
        i = int(np.argmax(lit & ~(lamp_on_pixels > 0)))
        raise ConfigError(
            "lamp", lamp_source, f"zero irradiance at {wavelength_nm[i]:g} nm: nothing to calibrate there"
        )
    factor = np.empty_like(wavelength_nm)
    signal_lit = np.where(lit, signal, 1.0)  # the factors of the pixels without signal are copied below
    factor[lit] = uj_per_count_from_lamp(lamp_on_pixels, signal_lit, integration_s, area_cm2, wavelength_nm)[lit]
    lit_index = np.flatnonzero(lit)
    for i in np.flatnonzero(~lit):
        factor[i] = factor[lit_index[np.argmin(np.abs(lit_index - i))]]
    return factor


def linearize(
    raw_counts, electric_dark_indices, nonlinearity_coefficients, subtract_electric_dark: bool
) -> tuple[np.ndarray, float]:
    """(corrected counts, electric-dark level) of one raw readout, by the device's stored corrections in the order
    seabreeze's ``Spectrometer.intensities`` applies them: the electric-dark level (the mean of the optically
    masked pixels ``electric_dark_indices``; 0 without them) is subtracted, the counts are divided by the device's
    nonlinearity polynomial ``Σ cₖ xᵏ`` (``nonlinearity_coefficients`` c₀, c₁, … in ascending order; None: no
    correction) evaluated at the dark-subtracted counts, and the level is added back unless
    ``subtract_electric_dark``.

    >>> counts, level = linearize([10.0, 10.0, 1010.0], [0, 1], [1.0, -1e-4], True)
    >>> level, round(float(counts[2]), 6)
    (10.0, 1111.111111)
    """
    raw = np.asarray(raw_counts, dtype=float)
    level = float(np.mean(raw[list(electric_dark_indices)])) if len(electric_dark_indices) else 0.0
    signal = raw - level
    if nonlinearity_coefficients is not None:
        signal = signal / np.polynomial.polynomial.polyval(signal, nonlinearity_coefficients)
    return (signal if subtract_electric_dark else signal + level), level


def saturated(raw_counts, max_intensity: float) -> bool:
    """Whether any raw pixel is within 1 % of full scale ``max_intensity``.

    >>> saturated([100.0, 64900.0], 65535.0), saturated([100.0, 64800.0], 65535.0)
    (True, False)
    """
    return bool(np.max(raw_counts) >= SATURATION_FRACTION * max_intensity)


def next_integration_us(
    integration_us: int, raw_peak: float, baseline: float, max_intensity: float, limits_us: tuple[int, int]
) -> int:
    """The integration [µs] that would bring the raw peak to 80 % of full scale, from a reading at
    ``integration_us`` whose highest raw pixel is ``raw_peak`` over a ``baseline`` (the dark level that does not
    grow with integration), assuming counts above the baseline grow in proportion to integration time (the
    detector's linear range); clamped to the device's ``limits_us``. A saturated reading (whose peak says only
    "too much") halves the integration.

    >>> next_integration_us(10_000, 40_000.0, 0.0, 65_535.0, (1_000, 10_000_000))
    13107
    """
    low, high = limits_us
    if saturated([raw_peak], max_intensity):
        wanted = integration_us / 2
    else:
        signal = max(raw_peak - baseline, 1.0)
        wanted = integration_us * (AUTO_FRACTION * max_intensity - baseline) / signal
    return int(min(high, max(low, np.floor(wanted))))
