"""Photometric ↔ radiometric conversion with the CIE 1924 photopic luminosity function.

Φv = K_m ∫ Φe(λ) V(λ) dλ with K_m = 683.002 lm/W (CIE 15:2018; BIPM SI Brochure, 9th ed., defines
K_cd = 683 lm/W at 540 THz ≈ 555.016 nm, where V = 1.00002; 683.002 is the customary value at 555 nm).
V(λ) is taken from colour-science's CIE 1924 Photopic Standard Observer (1 nm, 360–830 nm), resampled to the grid.
"""
from __future__ import annotations

from functools import lru_cache

import colour
import numpy as np

from uwlab.model.grid import WavelengthGrid

K_M_LM_PER_W = 683.002
H_J_S = 6.62607015e-34
C_M_S = 299792458.0


@lru_cache(maxsize=16)
def photopic_v(grid: WavelengthGrid) -> np.ndarray:
    """V(λ) on the grid (zero outside 360–830 nm)."""
    sd = colour.colorimetry.SDS_LEFS_PHOTOPIC["CIE 1924 Photopic Standard Observer"]
    v = np.interp(grid.nm, sd.wavelengths, sd.values, left=0.0, right=0.0)
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


def photon_flux(radiant_w_per_nm: np.ndarray, grid: WavelengthGrid) -> np.ndarray:
    """Photons per second (per m² for an irradiance): ∫ Φe(λ) λ / (h c) dλ."""
    return grid.integrate(radiant_w_per_nm * grid.m) / (H_J_S * C_M_S)
