"""Scattering by water and suspended particles: phase functions and the volume scattering function.

Convention: the volume scattering function β(ψ, λ) = b(λ) p̃(ψ) [1/(m sr)] with the phase function p̃
normalised over the sphere, 2π ∫₀^π p̃(ψ) sin ψ dψ = 1; ψ is the scattering angle between the incident and the
scattered directions (0 = forward). Water and particles scatter independently and their β add.

- Pure water: p̃_w(ψ) = 0.06225 (1 + 0.835 cos²ψ) sr⁻¹ (Morel, "Optical properties of pure water and pure sea
  water", 1974, depolarisation ratio 0.09; Mobley, *Light and Water*, 1994, eq. 3.29); b_w(λ) is in
  `uwlab.model.water`.
- Particles, Fournier–Forand (Fournier & Forand, Proc. SPIE 2258, 194–201, 1994; the normalised form of
  Fournier & Jonasz, Proc. SPIE 3761, 1999, as written in Mobley, Sundman & Boss, "Phase function effects on
  oceanic light fields", Applied Optics 41(6), 1035–1050, 2002, eq. 7):
  p̃(ψ) = [ν(1−δ) − (1−δ^ν) + (δ(1−δ^ν) − ν(1−δ)) / sin²(ψ/2)] / (4π (1−δ)² δ^ν)
         + (1 − δ₁₈₀^ν)(3cos²ψ − 1) / (16π (δ₁₈₀ − 1) δ₁₈₀^ν),
  ν = (3 − μ)/2, δ = 4 sin²(ψ/2) / (3 (n − 1)²), δ₁₈₀ = δ(π); n is the particles' real index relative to water
  and μ the slope of their hyperbolic (Junge) size distribution. Its backscatter fraction (their eq. 8)
  B = 1 − [1 − δ₉₀^(ν+1) − ½(1 − δ₉₀^ν)] / [(1 − δ₉₀) δ₉₀^ν]. n = 1.10, μ = 3.5835 give B = 0.0183, the
  backscatter fraction of Petzold's average particle phase function (Mobley et al. 2002).
- Particles, Henyey–Greenstein (Henyey & Greenstein, Astrophys. J. 93, 70–83, 1941):
  p̃(ψ) = (1 − g²) / (4π (1 + g² − 2g cos ψ)^(3/2)), g the mean cosine; B = (1−g)/(2g) [(1+g)/√(1+g²) − 1].
- Particle scattering spectrum: b_p(λ) = b_p(550 nm) (550 nm / λ)^γ (the 1/λ law, γ = 1, of Gordon & Morel,
  *Remote Assessment of Ocean Color*, 1983; γ is a parameter).

>>> round(float(fournier_forand_backscatter_fraction(1.10, 3.5835)), 4)
0.0183
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from uwlab.errors import ConfigError

PURE_WATER_P0 = 0.06225
PURE_WATER_ANISOTROPY = 0.835
PETZOLD_INDEX = 1.10
PETZOLD_JUNGE_SLOPE = 3.5835
PHASE_FUNCTIONS = ("fournier-forand", "henyey-greenstein")
REFERENCE_NM = 550.0


def pure_water_phase(cos_psi):
    """Morel's (1974) phase function of pure water p̃_w [1/sr] at cos ψ."""
    return PURE_WATER_P0 * (1.0 + PURE_WATER_ANISOTROPY * np.asarray(cos_psi, float) ** 2)


def fournier_forand_phase(cos_psi, index=PETZOLD_INDEX, junge_slope=PETZOLD_JUNGE_SLOPE):
    """Fournier–Forand phase function [1/sr] at cos ψ (module docstring; finite for ψ > 0)."""
    nu = (3.0 - junge_slope) / 2.0
    sin2_half = np.clip((1.0 - np.asarray(cos_psi, float)) / 2.0, 1e-30, 1.0)
    scale = 4.0 / (3.0 * (index - 1.0) ** 2)
    delta = scale * sin2_half
    d180 = scale
    main = (nu * (1 - delta) - (1 - delta**nu) + (delta * (1 - delta**nu) - nu * (1 - delta)) / sin2_half) / (
        4 * np.pi * (1 - delta) ** 2 * delta**nu
    )
    correction = (1 - d180**nu) * (3 * np.asarray(cos_psi, float) ** 2 - 1) / (16 * np.pi * (d180 - 1) * d180**nu)
    return main + correction


def fournier_forand_backscatter_fraction(index=PETZOLD_INDEX, junge_slope=PETZOLD_JUNGE_SLOPE):
    """Backscatter fraction B = b_b / b of the Fournier–Forand phase function (Mobley et al. 2002, eq. 8)."""
    nu = (3.0 - junge_slope) / 2.0
    d90 = 4.0 / (3.0 * (index - 1.0) ** 2) * 0.5
    return 1 - (1 - d90 ** (nu + 1) - 0.5 * (1 - d90**nu)) / ((1 - d90) * d90**nu)


def henyey_greenstein_phase(cos_psi, g):
    """Henyey–Greenstein phase function [1/sr] with mean cosine g."""
    return (1 - g**2) / (4 * np.pi * (1 + g**2 - 2 * g * np.asarray(cos_psi, float)) ** 1.5)


@dataclass(frozen=True)
class ParticleScattering:
    """Suspended particles: b_p at 550 nm [1/m], its spectral exponent γ and the phase function.

    ``phase`` is "fournier-forand" (parameters ``index`` n and ``junge_slope`` μ) or "henyey-greenstein"
    (parameter ``g``)."""

    b550_per_m: float = 0.0
    exponent: float = 1.0
    phase: str = "fournier-forand"
    index: float = PETZOLD_INDEX
    junge_slope: float = PETZOLD_JUNGE_SLOPE
    g: float = 0.924

    def __post_init__(self):
        if self.phase not in PHASE_FUNCTIONS:
            raise ConfigError("phase_function", self.phase, f"must be one of {', '.join(PHASE_FUNCTIONS)}")

    def b_per_m(self, nm) -> np.ndarray:
        """b_p(λ) = b_p(550) (550/λ)^γ [1/m]."""
        return self.b550_per_m * (REFERENCE_NM / np.asarray(nm, float)) ** self.exponent

    def phase_function(self, cos_psi) -> np.ndarray:
        if self.phase == "fournier-forand":
            return fournier_forand_phase(cos_psi, self.index, self.junge_slope)
        return henyey_greenstein_phase(cos_psi, self.g)

    @property
    def backscatter_fraction(self) -> float:
        if self.phase == "fournier-forand":
            return float(fournier_forand_backscatter_fraction(self.index, self.junge_slope))
        g = self.g
        return float((1 - g) / (2 * g) * ((1 + g) / np.sqrt(1 + g**2) - 1))
