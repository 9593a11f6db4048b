"""Dark signal against exposure time and temperature: EMVA 1288 Release 4.0 Linear §3 and §7 (General §3, §7).

* The dark signal grows linearly with the exposure time, μ_y.dark = μ_y.0 + μ_I.y t_exp (eq. 29) and, the thermal
  electrons being Poisson distributed, so does its temporal variance, σ²_y.dark = σ²_y.0 + K μ_I.y t_exp (eq. 30).
  The dark current is the slope of least-squares lines through the dark means [DN/s] and variances [DN²/s] against
  t_exp, "at least six equally spaced exposure times" (§7.1), reported with their one-sigma errors from the
  regression. Divided by K and K² (linear model) or by R_d and R_d² (general model, eq. 24) by the caller.
* Temperature dependence (§7.2): the dark current at each recorded temperature (dark measurements grouped to
  `TEMPERATURE_STEP_C`), presented as data (Release 4 assumes no model, §3.2).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from uwlab.experiments.emva.regression import fit_line

MIN_DARK_EXPOSURES = 6
TEMPERATURE_STEP_C = 0.5


@dataclass(frozen=True)
class DarkSeries:
    """Dark measurements: exposure [s], mean [DN], temporal variance [DN²] and temperature [°C] (NaN: unknown),
    arrays of equal length."""

    exposure_s: np.ndarray
    mean_dn: np.ndarray
    var_dn2: np.ndarray
    temperature_c: np.ndarray

    def __post_init__(self) -> None:
        for name in ("exposure_s", "mean_dn", "var_dn2", "temperature_c"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), float))

    def __len__(self) -> int:
        return len(self.exposure_s)

    def select(self, mask: np.ndarray) -> DarkSeries:
        return DarkSeries(self.exposure_s[mask], self.mean_dn[mask], self.var_dn2[mask], self.temperature_c[mask])

    def at_shortest_exposure(self) -> tuple[float, float]:
        """(t_exp [s], mean temporal variance [DN²]) of the measurements at the shortest exposure."""
        shortest = float(self.exposure_s.min())
        return shortest, float(self.var_dn2[self.exposure_s == shortest].mean())

    def at_temperature(self, temperature_c: float | None) -> DarkSeries:
        """The measurements recorded within half a `TEMPERATURE_STEP_C` of ``temperature_c`` (all of them when it is
        None or no temperature was recorded)."""
        if temperature_c is None or not np.isfinite(temperature_c) or not np.isfinite(self.temperature_c).any():
            return self
        return self.select(np.abs(self.temperature_c - temperature_c) <= TEMPERATURE_STEP_C / 2)


@dataclass(frozen=True)
class DarkCurrent:
    """Slopes of the dark mean [DN/s] and variance [DN²/s] against exposure time (§7.1) at one temperature."""

    mean_dn_per_s: float
    mean_dn_per_s_std: float
    var_dn2_per_s: float
    var_dn2_per_s_std: float
    offset_dn: float
    exposures: int
    temperature_c: float | None


def distinct(values: np.ndarray) -> list[float]:
    """The distinct values, sorted: `np.unique` without its import of numpy.ma (numpy 2.4; a tenth of a small
    characterisation's time)."""
    return sorted(set(np.asarray(values, float).tolist()))


def dark_current(series: DarkSeries) -> DarkCurrent | None:
    """§7.1 regressions of one temperature's dark series; None with fewer than `MIN_DARK_EXPOSURES` distinct exposure
    times."""
    exposures = len(distinct(series.exposure_s))
    if exposures < MIN_DARK_EXPOSURES:
        return None
    mean = fit_line(series.exposure_s, series.mean_dn)
    var = fit_line(series.exposure_s, series.var_dn2)
    temps = series.temperature_c[np.isfinite(series.temperature_c)]
    return DarkCurrent(
        mean.slope,
        mean.slope_std,
        var.slope,
        var.slope_std,
        mean.intercept,
        exposures,
        float(np.median(temps)) if temps.size else None,
    )


def dark_current_by_temperature(series: DarkSeries) -> list[DarkCurrent]:
    """§7.2: the dark current at every recorded temperature with enough exposure times, by increasing temperature."""
    known = np.isfinite(series.temperature_c)
    if not known.any():
        return []
    groups = np.round(series.temperature_c[known] / TEMPERATURE_STEP_C) * TEMPERATURE_STEP_C
    found = (dark_current(series.select(known).select(groups == t)) for t in distinct(groups))
    return [d for d in found if d is not None]
