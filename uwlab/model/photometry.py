"""Photometric ↔ radiometric conversion with the CIE 1924 photopic luminosity function.

Φv = K_m ∫ Φe(λ) V(λ) dλ with K_m = 683.002 lm/W (CIE 15:2018; BIPM SI Brochure, 9th ed., defines
K_cd = 683 lm/W at 540 THz ≈ 555.016 nm, where V = 1.00002; 683.002 is the customary value at 555 nm).
V(λ) is the CIE 1924 Photopic Standard Observer (1 nm, 360–830 nm; `configs/photometry/cie_1924_photopic_v.csv`,
exported unchanged from colour-science, which the tests check), interpolated linearly and zero outside its table.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from uwlab.model.data import config_dir, read_csv_columns
from uwlab.model.grid import WavelengthGrid

K_M_LM_PER_W = 683.002
H_J_S = 6.62607015e-34
C_M_S = 299792458.0


PHOTOPIC_TABLE = "photometry/cie_1924_photopic_v.csv"


@lru_cache(maxsize=4)
def _photopic_table(root: Path) -> tuple[np.ndarray, np.ndarray]:
    table = read_csv_columns(root / PHOTOPIC_TABLE, ("wavelength_nm", "v"), "photopic V(λ) table")
    return table["wavelength_nm"], table["v"]


def photopic_v_at(wavelength_nm) -> np.ndarray:
    """V(λ) at the given wavelengths [nm] (zero outside 360–830 nm).

    >>> float(photopic_v_at(555.0))
    1.0
    """
    table_nm, v = _photopic_table(config_dir())
    return np.interp(wavelength_nm, table_nm, v, left=0.0, right=0.0)


@lru_cache(maxsize=16)
def photopic_v(grid: WavelengthGrid) -> np.ndarray:
    """V(λ) on the grid (zero outside 360–830 nm), read-only."""
    v = photopic_v_at(grid.nm)
    v.setflags(write=False)
    return v


def radiant_per_lumen(relative_spectrum: np.ndarray, grid: WavelengthGrid) -> np.ndarray:
    """Spectral radiant flux per lumen, s(λ) = S(λ) / (K_m ∫ S V dλ) [W/nm per lm].

    Multiplying by a luminous flux Φv [lm] gives Φe(λ) [W/nm] whose luminous flux is exactly Φv.
    """
    luminous = K_M_LM_PER_W * grid.integrate(relative_spectrum * photopic_v(grid))
    return relative_spectrum / luminous


def luminous_flux(radiant_w_per_nm: np.ndarray, grid: WavelengthGrid) -> np.ndarray:
    """Φv = K_m ∫ Φe(λ) V(λ) dλ [lm] for a spectral radiant flux [W/nm] (or illuminance for W/m²/nm)."""
    return K_M_LM_PER_W * grid.integrate(radiant_w_per_nm * photopic_v(grid))


def photons_per_joule(wavelength_nm) -> np.ndarray:
    """λ / (h c) [photons per J]: the number of photons in one joule of light of wavelength λ.

    >>> round(float(photons_per_joule(555.0)) / 1e18, 4)
    2.7939
    """
    return np.asarray(wavelength_nm, float) * 1e-9 / (H_J_S * C_M_S)


def photon_flux(wavelength_nm, spectral_w_per_nm) -> np.ndarray:
    """Photon flux ∫ Φe(λ) λ / (h c) dλ [photons/s], or photon irradiance [photons m⁻² s⁻¹] for a spectral
    irradiance [W m⁻² nm⁻¹], by the trapezoidal rule over the given wavelengths (any order; the wavelength
    axis is the last one). The one conversion from spectral energy to photons in uwlab (EMVA 1288 Release 4.0
    Linear, eq. 3: μ_p = A t_exp E λ / (h c)).

    >>> nm = np.array([550.0, 560.0])
    >>> bool(np.isclose(photon_flux(nm, np.ones(2)), 10 * photons_per_joule(555.0)))
    True
    """
    nm = np.asarray(wavelength_nm, float)
    order = np.argsort(nm, kind="stable")
    nm = nm[order]
    energy = np.asarray(spectral_w_per_nm, float)[..., order]
    return np.trapezoid(energy * photons_per_joule(nm), nm, axis=-1)
