"""The wavelength grid every spectral quantity lives on.

Convention: wavelengths in nanometres on a uniform grid (default 380–780 nm in 1 nm steps); spectral
densities are per nanometre; integrals use the trapezoidal rule, ∫ f dλ ≈ Σ f_i w_i with the weights `w_nm`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from uwlab.errors import ConfigError


@dataclass(frozen=True)
class WavelengthGrid:
    start_nm: float = 380.0
    stop_nm: float = 780.0
    step_nm: float = 1.0

    def __post_init__(self) -> None:
        if not self.step_nm > 0:
            raise ConfigError("spectral.step_nm", self.step_nm, "must be > 0")
        if not 0 < self.start_nm < self.stop_nm:
            raise ConfigError("spectral.stop_nm", self.stop_nm, f"must exceed start_nm = {self.start_nm} > 0")

    @cached_property
    def nm(self) -> np.ndarray:
        n = int(round((self.stop_nm - self.start_nm) / self.step_nm)) + 1
        return self.start_nm + self.step_nm * np.arange(n)

    @cached_property
    def m(self) -> np.ndarray:
        return self.nm * 1e-9

    @cached_property
    def w_nm(self) -> np.ndarray:
        """Trapezoidal integration weights [nm]."""
        w = np.full(self.nm.shape, self.step_nm)
        w[[0, -1]] = self.step_nm / 2
        return w

    def integrate(self, spectral: np.ndarray) -> np.ndarray:
        """∫ f(λ) dλ over the grid; the wavelength axis is the last one."""
        return np.asarray(spectral) @ self.w_nm


DEFAULT_GRID = WavelengthGrid()
