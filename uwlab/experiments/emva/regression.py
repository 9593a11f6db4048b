"""The regressions of EMVA 1288 Release 4.0: least-squares lines (Linear §6.6 eq. 49–50, §7.1) and the cubic
B-spline regression of Release 4.0 General §6.6 (eq. 44–49), which Release 4.0 Linear §6.6 (eq. 51) also uses to
check that the photon transfer curve is straight.

Lines: ordinary least squares, standard deviations of the coefficients from the covariance s² (XᵀX)⁻¹ with s² the
residual variance (the "one-sigma statistical uncertainty ... computed from the linear regression" of §6.6).

B-splines: the range [x₀, x₁] is divided into P intervals of width Δ = (x₁ − x₀)/P; the model is
Σ_{p=0}^{P+2} a_p β₃((x − x₀)/Δ − (p − 1)) with the uniform cubic B-spline β₃ of eq. 45, a linear least-squares
problem in the P + 3 coefficients a_p (eq. 46–47, solved by `numpy.linalg.lstsq`); its derivative uses β₃′ of
eq. 49 (eq. 48). Written out from the standard's equations rather than taken from scipy.interpolate, whose import
alone costs more CPU time than the whole characterisation of a 100-image dataset.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from uwlab.errors import ConfigError

POINTS_PER_INTERVAL = 7


@dataclass(frozen=True)
class LineFit:
    """y = slope x + intercept by least squares, with standard deviations from the covariance s² (XᵀX)⁻¹."""

    slope: float
    intercept: float
    slope_std: float
    intercept_std: float


def fit_line(x, y, through_origin: bool = False) -> LineFit:
    """Ordinary least squares (``through_origin``: no intercept); NaN standard deviations with no degree of
    freedom left."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    design = x[:, None] if through_origin else np.column_stack([x, np.ones_like(x)])
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    dof = len(x) - design.shape[1]
    resid = y - design @ coef
    cov = (resid @ resid / dof if dof > 0 else np.nan) * np.linalg.pinv(design.T @ design)
    std = np.sqrt(np.diag(cov))
    if through_origin:
        return LineFit(float(coef[0]), 0.0, float(std[0]), 0.0)
    return LineFit(float(coef[0]), float(coef[1]), float(std[0]), float(std[1]))


def intervals_for(points: int) -> int:
    """P for a regression over ``points`` measurements: one interval per `POINTS_PER_INTERVAL` points, at least 2
    (General §6.6: "for the recommended number of exposure steps [≥ 50], 6 to 8 intervals")."""
    return max(2, int(round(points / POINTS_PER_INTERVAL)))


def beta3(x) -> np.ndarray:
    """The uniform cubic B-spline β₃(x) of General eq. 45."""
    a = np.abs(np.asarray(x, float))
    return np.where(a < 1, 2.0 / 3.0 - a**2 + 0.5 * a**3, np.where(a <= 2, (2.0 - a) ** 3 / 6.0, 0.0))


def beta3_slope(x) -> np.ndarray:
    """β₃′(x) of General eq. 49."""
    x = np.asarray(x, float)
    a = np.abs(x)
    return np.where(a < 1, -2.0 * x * (1.0 - 0.75 * a), np.where(a <= 2, -0.5 * np.sign(x) * (2.0 - a) ** 2, 0.0))


@dataclass(frozen=True)
class BSplineFit:
    """Σ_p a_p β₃((x − x₀)/Δ − (p − 1)), p = 0 … P + 2 (eq. 44/46)."""

    coefficients: np.ndarray
    x0: float
    step: float

    def basis(self, x) -> np.ndarray:
        """The design matrix f_p(x) of eq. 46, shape (len(x), P + 3)."""
        u = (np.asarray(x, float)[:, None] - self.x0) / self.step - (np.arange(len(self.coefficients)) - 1)
        return beta3(u)

    def slope_basis(self, x) -> np.ndarray:
        """∂f_p/∂x of eq. 48, shape (len(x), P + 3)."""
        u = (np.asarray(x, float)[:, None] - self.x0) / self.step - (np.arange(len(self.coefficients)) - 1)
        return beta3_slope(u) / self.step

    def __call__(self, x):
        x = np.asarray(x, float)
        return (self.basis(np.atleast_1d(x)) @ self.coefficients).reshape(x.shape)

    def slope(self, x):
        """∂y/∂x (eq. 48)."""
        x = np.asarray(x, float)
        return (self.slope_basis(np.atleast_1d(x)) @ self.coefficients).reshape(x.shape)


def bspline_regression(x, y, intervals: int, x_range: tuple[float, float] | None = None, weights=None) -> BSplineFit:
    """The least-squares cubic B-spline of eq. 44–47 over ``x_range`` (default: the data's range) with
    ``intervals`` intervals (``weights`` multiply the residuals; default 1, eq. 47); `ConfigError` when the points
    cannot determine the P + 3 coefficients."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    w = np.ones_like(x) if weights is None else np.asarray(weights, float)
    x0, x1 = x_range if x_range is not None else (float(x.min()), float(x.max()))
    if not x1 > x0 or len(x) < intervals + 3:
        raise ConfigError("B-spline regression", len(x), f"needs more than {intervals + 2} distinct points")
    fit = BSplineFit(np.zeros(intervals + 3), float(x0), (x1 - x0) / intervals)
    design = fit.basis(x) * w[:, None]
    coefficients, _, rank, _ = np.linalg.lstsq(design, y * w, rcond=None)
    if rank < intervals + 3:
        raise ConfigError("B-spline regression", len(x), f"the points do not determine {intervals} intervals")
    return BSplineFit(coefficients, fit.x0, fit.step)
