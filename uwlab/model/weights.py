"""Spectral weights: the spectral integrals of the chain, tabulated per design.

Every numeric parameter may be an array; arrays broadcast against each other (a Cartesian grid is an open mesh:
one axis per parameter), and each quantity is computed only over the axes it depends on. Spectral integrals
depend on the design only through the attenuating path length D = scale · (d_L + d_C), so they are evaluated
as exp(−D ⊗ c) @ W with W the fixed spectral weights (one matrix product, no per-wavelength loop).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from uwlab.model import extended
from uwlab.model.design import Design
from uwlab.model.photometry import photons_per_joule, radiant_per_lumen
from uwlab.model.spectra import relative_spectrum
from uwlab.model.spectral_table import SpectralTable
from uwlab.model.target import reflectance, transmittance
from uwlab.model.water import scattering_parts, water_iop


def _spectral_key(d: Design):
    return (
        d.grid,
        d["light.spectrum"],
        d["water.type"],
        _hashable(d["target.reflectance"]),
        _hashable(d["lens.transmittance"]),
        id(d.sensor),
        d["sensor.channel"],
        d["water.particle_scattering_per_m"],
        d["water.particle_scattering_exponent"],
    )


def _hashable(value):
    """Spectral inputs are named by their file; a broadband number (or grid array) is not part of the weights."""
    return value if isinstance(value, str) else "broadband"


@dataclass(frozen=True)
class SpectralWeights:
    """Fixed spectral factors of the chain on the grid.

    c: beam attenuation [1/m] (unscaled): the water type's plus the added particles' scattering. W: columns
    (target irradiance, sensor irradiance, electron rate) per unit luminous flux, with the spectral (tabulated)
    reflectance and lens transmittance folded in and trapezoidal weights applied, so that exp(−D c) @ W integrates
    over wavelength; then the photon rate of the source alone, × reflectance, × reflectance × lens transmittance
    (the stages of `light_budget`). `reflectance` and `lens_transmittance` are the spectral curves when given as
    files, else ones (broadband numbers stay outside). b_water, b_particles: the scattering coefficients [1/m]
    (the extended model's veiling light): pure water's molecular part of the water type's b, and its particle
    part plus the added particles' (`uwlab.model.water.scattering_parts`).
    """

    c: np.ndarray
    W: np.ndarray
    s_per_lm: np.ndarray
    reflectance: np.ndarray
    lens_transmittance: np.ndarray
    qe: np.ndarray
    b_water: np.ndarray
    b_particles: np.ndarray

    @cached_property
    def table(self) -> SpectralTable:
        """G(D) = exp(−D c) @ W at any path lengths, without a sum over wavelength per point."""
        return SpectralTable(self.c, self.W)

    @cached_property
    def electron_mean_rate_per_m(self) -> float:
        """c̄ = −d ln G_e/dD at D = 0 = Σ W_e c / Σ W_e [1/m]: the electron-rate-weighted mean attenuation, the
        steepest slope of the convex ln G_e (0 when the column is zero)."""
        total = self.W[:, 2].sum()
        return float(self.W[:, 2] @ self.c / total) if total > 0 else 0.0

    @cached_property
    def image_tables(self) -> dict:
        """Image-average sample geometries and tables by lens/port geometry (`_image_geometry`), a small cache."""
        return {}


_WEIGHTS_CACHE: dict = {}


IMAGE_TABLES_PER_WEIGHTS = 32


IMAGE_DIRECT_PATHS = 512


def spectral_weights(d: Design) -> SpectralWeights:
    """The design's spectral weights, cached by its categorical inputs (spectral files, water, sensor)."""
    key = _spectral_key(d)
    if key not in _WEIGHTS_CACHE:
        if len(_WEIGHTS_CACHE) > 64:
            _WEIGHTS_CACHE.clear()
        _WEIGHTS_CACHE[key] = _compute_weights(d)
    return _WEIGHTS_CACHE[key]


def _compute_weights(d: Design) -> SpectralWeights:
    grid = d.grid
    s = radiant_per_lumen(relative_spectrum(d["light.spectrum"], grid), grid)
    iop = water_iop(d["water.type"], grid)
    added = extended.particles(d).b_per_m(grid.nm)
    b_water, b_suspended = scattering_parts(iop.b_per_m, grid.nm)
    c = iop.c_per_m + added
    m = reflectance(d["target.reflectance"], grid)
    t = transmittance(d["lens.transmittance"], grid)
    qe = d.sensor.qe_on(grid, d["sensor.channel"])
    m_spec = m if _is_spectral(d, "target.reflectance") else np.ones_like(grid.nm)
    t_spec = t if _is_spectral(d, "lens.transmittance") else np.ones_like(grid.nm)
    base = s * grid.w_nm
    photons = base * photons_per_joule(grid.nm)
    W = np.stack(
        [
            base,
            base * m_spec * t_spec,
            photons * m_spec * t_spec * qe,
            photons,
            photons * m_spec,
            photons * m_spec * t_spec,
        ],
        axis=1,
    )
    return SpectralWeights(
        c=c,
        W=W,
        s_per_lm=s,
        reflectance=m_spec,
        lens_transmittance=t_spec,
        qe=qe,
        b_water=b_water,
        b_particles=b_suspended + added,
    )


def _is_spectral(d: Design, dotted: str) -> bool:
    """A factor given as a file is spectral (folded into W); a number (or grid array) is broadband."""
    return isinstance(d[dotted], str)


def broadband_factor(d: Design, dotted: str):
    """A broadband factor: the configured number, or 1 when the factor is spectral (already in W)."""
    return 1.0 if _is_spectral(d, dotted) else d[dotted]


def path_integrals(weights: SpectralWeights, path_m) -> np.ndarray:
    """∫ W(λ) exp(−c(λ) D) dλ for attenuating path lengths D (any shape) → shape D.shape + (3,), summed over
    the wavelength grid (the reference the chain's interpolation table, `SpectralWeights.table`, is tested
    against)."""
    path = np.asarray(path_m, float)
    return np.exp(-path[..., None] * weights.c) @ weights.W
