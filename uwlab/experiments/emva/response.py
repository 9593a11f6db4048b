"""The measured response curve of a characterised camera, for the model (the fields of
`uwlab.model.sensor.ResponseCurve`, validated as one where a sensor profile is written,
`uwlab.experiments.emva.profile`: the analysis path does not import pydantic, a third of a small characterisation's
time).

From the photon-transfer points between `RESPONSE_RANGE` of the saturation signal (the darkest, noisiest points and
the saturation plateau left out): the responsivity of each point, y_i = (μ_y − μ_y.dark)_i / μ_p,i [DN/photon],
against its well fraction u_i = η μ_p,i / μ_e.sat, fitted by ordinary least squares with y = c₀ + c₁ u + c₂ u²;
the curve relative to the zero-signal responsivity is c(u) = 1 + (c₁/c₀) u + (c₂/c₀) u², and the covariance of
(a, b) = (c₁/c₀, c₂/c₀) follows from the fit's (residual variance × (XᵀX)⁻¹) by the delta method. A camera whose
charge is compressed as μ_e − β μ_e²/μ_e.sat has c(u) = 1 − β u: a ≈ −β, b ≈ 0.
"""

from __future__ import annotations

import numpy as np

from uwlab.experiments.emva.transfer import points_between

RESPONSE_RANGE = (0.02, 0.95)
MIN_POINTS = 6


def response_curve(
    photons: np.ndarray, signal_dn: np.ndarray, saturation_index: int, eta: float, saturation_e: float
) -> dict | None:
    """The response curve (module docstring) of sorted photon-transfer points, as the fields of a
    `uwlab.model.sensor.ResponseCurve`; None with fewer than `MIN_POINTS` points in `RESPONSE_RANGE`.

    >>> mu_p = np.linspace(100.0, 10000.0, 20)
    >>> electrons = 0.5 * mu_p
    >>> curve = response_curve(mu_p, 0.2 * (electrons - 0.02 * electrons**2 / 5000.0), 19, 0.5, 5000.0)
    >>> round(curve["a"], 6), abs(round(curve["b"], 6))
    (-0.02, 0.0)
    """
    idx = points_between(signal_dn, saturation_index, *RESPONSE_RANGE)
    idx = idx[photons[idx] > 0]
    if idx.size < MIN_POINTS:
        return None
    u = eta * photons[idx] / saturation_e
    y = signal_dn[idx] / photons[idx]
    x = np.column_stack([np.ones_like(u), u, u**2])
    coef, *_ = np.linalg.lstsq(x, y, rcond=None)
    residual = y - x @ coef
    cov = float(residual @ residual) / (idx.size - 3) * np.linalg.inv(x.T @ x)
    c0, c1, c2 = coef
    jacobian = np.array([[-c1 / c0**2, 1 / c0, 0.0], [-c2 / c0**2, 0.0, 1 / c0]])
    ab_cov = jacobian @ cov @ jacobian.T
    return {
        "a": float(c1 / c0),
        "b": float(c2 / c0),
        "covariance": ((float(ab_cov[0, 0]), float(ab_cov[0, 1])), (float(ab_cov[1, 0]), float(ab_cov[1, 1]))),
        "fraction_range": (float(u.min()), float(u.max())),
        "source": f"EMVA 1288 photon transfer, {idx.size} points between {RESPONSE_RANGE[0]:g} and "
        f"{RESPONSE_RANGE[1]:g} of saturation",
    }
