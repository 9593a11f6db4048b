"""Relative spectral power distributions of light sources.

Named spectra (all relative, arbitrary scale; the luminous flux sets the absolute level):
- ``generic-led``: the white-LED fit of Billings, Iscar & Johnson-Roberson, "Parametric Design of Underwater
  Optical Systems": w₁ N(450.70 nm, 11.67 nm) + w₂ N(565.43 nm, 64.63 nm) with w₁ = 24.49, w₂ = 119.86 on
  unit-area Gaussians.
- ``halogen``: CIE standard illuminant A (Planckian, 2856 K), CIE 15:2018, from colour-science.
- ``fluorescent``: CIE illuminant FL2 (cool white fluorescent), CIE 15:2018, from colour-science.
- ``daylight``: CIE standard illuminant D65, CIE 15:2018, from colour-science.
colour-science's tabulated illuminants are resampled with its default interpolator and held constant beyond
their range; CSV spectra (columns ``wavelength_nm, relative``) are interpolated linearly and are zero outside.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from uwlab.errors import ConfigError
from uwlab.model.data import read_csv_columns
from uwlab.model.grid import WavelengthGrid

GENERIC_LED_MEANS_NM = (450.70, 565.43)
GENERIC_LED_SIGMAS_NM = (11.67, 64.63)
GENERIC_LED_WEIGHTS = (24.49, 119.86)

_COLOUR_ILLUMINANTS = {"halogen": "A", "fluorescent": "FL2", "daylight": "D65"}
NAMED_SPECTRA = ("generic-led", *_COLOUR_ILLUMINANTS)


def generic_led(nm: np.ndarray) -> np.ndarray:
    """The paper's two-Gaussian white LED (weights on unit-area Gaussians), evaluated at `nm`."""
    mu = np.asarray(GENERIC_LED_MEANS_NM)
    sigma = np.asarray(GENERIC_LED_SIGMAS_NM)
    w = np.asarray(GENERIC_LED_WEIGHTS)
    z = (np.asarray(nm)[..., None] - mu) / sigma
    return (w * np.exp(-0.5 * z**2) / (sigma * np.sqrt(2 * np.pi))).sum(axis=-1)


@lru_cache(maxsize=32)
def _named(name: str, grid: WavelengthGrid) -> np.ndarray:
    if name == "generic-led":
        out = generic_led(grid.nm)
    else:
        import colour  # only for these spectra: importing colour-science costs seconds

        sd = colour.SDS_ILLUMINANTS[_COLOUR_ILLUMINANTS[name]].copy()
        shape = colour.SpectralShape(grid.start_nm, grid.stop_nm, grid.step_nm)
        out = np.array(sd.align(shape).values, dtype=float)
    out.setflags(write=False)
    return out


def relative_spectrum(spec: str | Path, grid: WavelengthGrid, key: str = "light.spectrum") -> np.ndarray:
    """A named spectrum or a CSV path → relative spectral power on the grid."""
    if isinstance(spec, str) and spec in NAMED_SPECTRA:
        return _named(spec, grid)
    path = Path(spec)
    if path.suffix.lower() != ".csv":
        raise ConfigError(key, str(spec), f"unknown spectrum; use one of {', '.join(NAMED_SPECTRA)} or a .csv file")
    table = read_csv_columns(path, ("wavelength_nm", "relative"), key)
    if np.any(table["relative"] < 0):
        raise ConfigError(key, str(spec), "negative relative power")
    out = np.interp(grid.nm, table["wavelength_nm"], table["relative"], left=0.0, right=0.0)
    if not np.any(out > 0):
        raise ConfigError(key, str(spec), "no power inside the wavelength grid")
    return out
