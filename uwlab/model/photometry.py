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
