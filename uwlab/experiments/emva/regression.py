"""The regressions of EMVA 1288 Release 4.0: least-squares lines (Linear §6.6 eq. 49–50, §7.1) and the cubic
B-spline regression of Release 4.0 General §6.6 (eq. 44–49), which Release 4.0 Linear §6.6 (eq. 51) also uses to
check that the photon transfer curve is straight.

Lines: ordinary least squares, standard deviations of the coefficients from the covariance s² (XᵀX)⁻¹ with s² the
residual variance (the "one-sigma statistical uncertainty ... computed from the linear regression" of §6.6).

B-splines: the range [x₀, x₁] is divided into P intervals of width Δ = (x₁ − x₀)/P; the model is
Σ_{p=0}^{P+2} a_p β₃((x − x₀)/Δ − (p − 1)) with the uniform cubic B-spline β₃ (eq. 45), a linear least-squares
problem in the P + 3 coefficients a_p (eq. 46–47); its derivative is analytic (eq. 48–49). These are the B-splines
of degree 3 on the uniform knots x₀ + (j − 3)Δ, j = 0 … P + 6, so `scipy.interpolate.make_lsq_spline` solves eq. 47
exactly and `BSpline.derivative` gives eq. 48.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import BSpline, make_lsq_spline

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


def bspline_regression(x, y, intervals: int, x_range: tuple[float, float] | None = None,
                       weights=None) -> BSpline:
    """The least-squares cubic B-spline of eq. 44–47 over ``x_range`` (default: the data's range) with
    ``intervals`` intervals (``weights`` multiply the residuals; default 1, eq. 47); `ConfigError` when the data
    cannot determine it (Schoenberg–Whitney)."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    w = np.ones_like(x) if weights is None else np.asarray(weights, float)
    order = np.argsort(x, kind="stable")
    x, y, w = x[order], y[order], w[order]
    x0, x1 = x_range if x_range is not None else (float(x[0]), float(x[-1]))
    if not x1 > x0 or len(x) < intervals + 3:
        raise ConfigError("B-spline regression", len(x), f"needs more than {intervals + 2} distinct points")
    step = (x1 - x0) / intervals
    knots = x0 + (np.arange(intervals + 7) - 3) * step
    knots[3], knots[intervals + 3] = x0, x1  # the base interval exactly, whatever the rounding of the steps
    try:
        return make_lsq_spline(x, y, knots, k=3, w=w)
    except (ValueError, RuntimeError, np.linalg.LinAlgError) as exc:
        raise ConfigError("B-spline regression", len(x), f"the points do not determine {intervals} intervals ({exc})") \
            from None
