"""Lambertian targets: L_t = E_t · M(λ) / π (a perfectly diffuse reflector of reflectance M; BRDF = M/π).

Named bottoms carry the original tool's broadband reflectances: sand 0.35, hard 0.30, benthic-average 0.20,
coral 0.15, organic 0.10. A CSV gives M(λ) (columns ``wavelength_nm, reflectance``), linearly interpolated with
end values held.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from uwlab.errors import ConfigError
from uwlab.model.data import read_csv_columns
from uwlab.model.grid import WavelengthGrid

NAMED_REFLECTANCE = {"sand": 0.35, "hard": 0.30, "benthic-average": 0.20, "coral": 0.15, "organic": 0.10}


def reflectance(spec, grid: WavelengthGrid, key: str = "target.reflectance"):
    """A number (kept as is, it may be a grid array), a named bottom, or a CSV → M (number or spectrum)."""
    if not isinstance(spec, (str, Path)):
        return spec
    if spec in NAMED_REFLECTANCE:
        return NAMED_REFLECTANCE[spec]
    path = Path(spec)
    if path.suffix.lower() != ".csv":
        raise ConfigError(
            key,
            str(spec),
            f"unknown reflectance; use a number in [0, 1], one of {', '.join(NAMED_REFLECTANCE)} or a .csv file",
        )
    table = read_csv_columns(path, ("wavelength_nm", "reflectance"), key)
    if np.any((table["reflectance"] < 0) | (table["reflectance"] > 1)):
        raise ConfigError(key, str(spec), "reflectance outside [0, 1]")
    return np.interp(grid.nm, table["wavelength_nm"], table["reflectance"])


def transmittance(spec, grid: WavelengthGrid, key: str = "lens.transmittance"):
    """A number or a CSV (columns ``wavelength_nm, transmittance``) → T (number or spectrum)."""
    if not isinstance(spec, (str, Path)):
        return spec
    path = Path(spec)
    if path.suffix.lower() != ".csv":
        raise ConfigError(key, str(spec), "must be a number in (0, 1] or a .csv file")
    table = read_csv_columns(path, ("wavelength_nm", "transmittance"), key)
    if np.any((table["transmittance"] < 0) | (table["transmittance"] > 1)):
        raise ConfigError(key, str(spec), "transmittance outside [0, 1]")
    return np.interp(grid.nm, table["wavelength_nm"], table["transmittance"])
