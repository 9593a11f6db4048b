"""EMVA 1288 Release 4.0 (linear) characterisation from photon-transfer statistics.

Conventions and equations (EMVA Standard 1288, Release 4.0 Linear, 2021; fit ranges as in its reference
implementation):

* photons per pixel μ_p = A t_exp ∫ E(λ) λ/(h c) dλ, A the pixel area, E the irradiance at the sensor;
* system gain K: slope of σ²_y − σ²_y,dark against μ_y − μ_y,dark, and responsivity R = η K: slope of
  μ_y − μ_y,dark against μ_p, both least-squares lines through the origin over 0–70 % of the saturation
  signal; quantum efficiency η = R / K;
* saturation: the point of maximum temporal variance σ²_y among the points with at least half the largest
  signal (a low-signal variance outlier is not saturation); μ_p,sat its photon count, μ_e,sat = η μ_p,sat,
  SNR_max = √μ_e,sat;
* temporal dark noise σ_d = √(σ²_y,dark − σ²_q) / K with σ²_q = 1/12 DN²; σ²_y,dark is the t_exp → 0 intercept of
  the dark variance when dark frames at more than two exposures exist, and is raised to 0.24 DN² when smaller
  (the quantisation-limited case);
* absolute sensitivity threshold (SNR = 1) μ_p,min = (√(σ²_y,dark/K² + 1/4) + 1/2) / η — the exact root of
  SNR(μ_p) = 1 in the linear model. The reference implementation (2025) still uses Release 3.1's first-order
  form (σ_y,dark/K + 1/2) / η, smaller by 7 % at σ_y,dark/K = 1 and 0.5 % at 5; dynamic range
  DR = μ_p,sat / μ_p,min, in dB 20 log₁₀ DR;
* linearity: a line fitted to μ_y − μ_y,dark against μ_p over 5–95 % of the saturation signal, weighted
  to minimise the relative deviation; δ = 100 (y − fit)/fit; LE = (max δ − min δ) / 2 [%];
* dark current: slope of μ_y,dark against t_exp divided by K [e⁻/s] (and from the variance: slope of
  σ²_y,dark divided by K²), needing dark frames at three or more exposures;
* DSNU and PRNU: spatial variances corrected for the residual temporal noise,
  s²_y = s²_y,measured − σ²_y / L; DSNU = s_y,dark / K [e⁻], PRNU = 100 √(s²_y − s²_y,dark) / (μ_y − μ_y,dark) [%],
  at the point nearest 50 % of the saturation signal.

The reference implementation (github.com/EMVA1288/emva1288) was read for the descriptor format and the choice
of fit ranges; no code was taken from it. Uncertainties of K, η and σ_d come from the least-squares covariance
and, independently, from a small `emcee` posterior of the same straight-line models with an unknown noise
scale (flat priors).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import emcee
import numpy as np

from uwlab.errors import ConfigError

QUANTISATION_VAR_DN2 = 1.0 / 12.0
MIN_DARK_VAR_DN2 = 0.24
SENSITIVITY_FIT_FRACTION = 0.7
LINEARITY_RANGE = (0.05, 0.95)
MIN_FIT_POINTS = 3
MCMC_WALKERS = 32
MCMC_STEPS = 1500
MCMC_BURN = 500


def photons_per_pixel(photon_irradiance_m2_s, exposure_s, pixel_area_m2):
    """μ_p = A t_exp E_p (EMVA 1288 Release 4.0)."""
    return np.asarray(photon_irradiance_m2_s, float) * np.asarray(exposure_s, float) * pixel_area_m2


@dataclass(frozen=True)
class SpatialPoint:
    """Statistics of one bright and one dark stack for DSNU/PRNU (L frames each)."""

    mean_dn: float
    temporal_var_dn2: float
    spatial_var_dn2: float
    frames: int
    dark_mean_dn: float
    dark_temporal_var_dn2: float
    dark_spatial_var_dn2: float
    dark_frames: int


@dataclass(frozen=True)
class PhotonTransfer:
    """Per-point statistics of one photon-transfer sweep (arrays of equal length) plus its dark series.

    ``dark_exposure_s``/``dark_series_*``: dark means and temporal variances against exposure, for the
    dark current and the t_exp → 0 dark variance. ``spatial``: the DSNU/PRNU point when measured apart from
    the sweep (e.g. a descriptor's spatial block); else the sweep point nearest 50 % saturation is used.
    """

    photons: np.ndarray
    exposure_s: np.ndarray
    mean_dn: np.ndarray
    temporal_var_dn2: np.ndarray
    spatial_var_dn2: np.ndarray
    frames: np.ndarray
    dark_mean_dn: np.ndarray
    dark_temporal_var_dn2: np.ndarray
    dark_spatial_var_dn2: np.ndarray
    dark_frames: np.ndarray
    dark_exposure_s: np.ndarray
    dark_series_mean_dn: np.ndarray
    dark_series_var_dn2: np.ndarray
    bit_depth: int
    width_px: int = 0
    height_px: int = 0
    pixel_area_m2: float | None = None
    wavelength_nm: float | None = None
    gain_db: float = 0.0
    source: str = ""
    spatial: SpatialPoint | None = None
    notes: tuple[str, ...] = field(default=())

    def sorted(self) -> PhotonTransfer:
        """The same sweep ordered by increasing μ_p."""
        order = np.argsort(self.photons, kind="stable")
        per_point = ("photons", "exposure_s", "mean_dn", "temporal_var_dn2", "spatial_var_dn2", "frames",
                     "dark_mean_dn", "dark_temporal_var_dn2", "dark_spatial_var_dn2", "dark_frames")
        return replace(self, **{name: np.asarray(getattr(self, name))[order] for name in per_point})

    @property
    def signal_dn(self) -> np.ndarray:
        return self.mean_dn - self.dark_mean_dn

    @property
    def signal_var_dn2(self) -> np.ndarray:
        return self.temporal_var_dn2 - self.dark_temporal_var_dn2


@dataclass(frozen=True)
class LineFit:
    """y = slope x + intercept by least squares, with standard deviations from the covariance."""

    slope: float
    intercept: float
    slope_std: float
    intercept_std: float


def fit_line(x, y, through_origin: bool = False) -> LineFit:
    """Ordinary least squares; standard errors from s² (XᵀX)⁻¹ with s² the residual variance."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    design = x[:, None] if through_origin else np.column_stack([x, np.ones_like(x)])
    dof = len(x) - design.shape[1]
    if dof < 1:
        raise ConfigError("fit", len(x), f"too few points for a line (need {design.shape[1] + 1})")
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    resid = y - design @ coef
    cov = (resid @ resid / dof) * np.linalg.inv(design.T @ design)
    std = np.sqrt(np.diag(cov))
    if through_origin:
        return LineFit(float(coef[0]), 0.0, float(std[0]), 0.0)
    return LineFit(float(coef[0]), float(coef[1]), float(std[0]), float(std[1]))


def _line_log_prob(theta: np.ndarray, x: np.ndarray, y: np.ndarray, through_origin: bool) -> np.ndarray:
    """Vectorised log-posterior of y = a x (+ b) with Gaussian noise of unknown scale exp(ln s), flat priors."""
    slope = theta[:, 0]
    intercept = 0.0 if through_origin else theta[:, 1][:, None]
    ln_s = theta[:, -1]
    resid = y[None, :] - slope[:, None] * x[None, :] - intercept
    logp = -0.5 * np.sum(resid**2, axis=1) * np.exp(-2.0 * ln_s) - len(x) * ln_s
    return np.where(np.abs(ln_s) < 50.0, logp, -np.inf)


def line_posterior(x, y, through_origin: bool = False, seed: int = 0) -> np.ndarray:
    """Posterior samples of (slope[, intercept]) from a vectorised `emcee` run started at the LSQ solution."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    lsq = fit_line(x, y, through_origin)
    centre = [lsq.slope] if through_origin else [lsq.slope, lsq.intercept]
    scale = [lsq.slope_std] if through_origin else [lsq.slope_std, lsq.intercept_std]
    resid = y - lsq.slope * x - lsq.intercept
    ln_s = math.log(max(float(np.sqrt(np.mean(resid**2))), 1e-12 * max(float(np.abs(y).max()), 1e-300)))
    rng = np.random.default_rng(seed)
    ndim = len(centre) + 1
    start = np.array(centre + [ln_s]) + rng.standard_normal((MCMC_WALKERS, ndim)) * np.array(
        [max(s, 1e-12 * abs(c) + 1e-300) for s, c in zip(scale, centre)] + [0.1])
    sampler = emcee.EnsembleSampler(MCMC_WALKERS, ndim, _line_log_prob, vectorize=True,
                                    args=(x, y, through_origin))
    sampler.random_state = np.random.RandomState(seed).get_state()
    sampler.run_mcmc(start, MCMC_STEPS, progress=False)
    return sampler.get_chain(discard=MCMC_BURN, flat=True)[:, : ndim - 1]


def _indices(signal: np.ndarray, sat: int, lo: float, hi: float) -> np.ndarray:
    """Indices up to the saturation point whose signal lies in [lo, hi] × signal[sat]."""
    idx = np.arange(sat + 1)
    s = signal[idx]
    return idx[(s >= lo * signal[sat]) & (s <= hi * signal[sat])]


def saturation_index(temporal_var_dn2: np.ndarray, signal_dn: np.ndarray) -> int:
    """Index of the maximum of the temporal variance (EMVA 1288 saturation point), searched only among the
    points whose signal is at least half the largest: the variance peaks where the signal nears its maximum, and
    a variance outlier far below saturation (a disturbed frame pair) must not be taken for it. (The reference
    implementation guards against the same by searching down from the brightest point.)"""
    var = np.asarray(temporal_var_dn2, float)
    signal = np.asarray(signal_dn, float)
    candidates = np.flatnonzero(signal >= 0.5 * np.nanmax(signal))
    return int(candidates[np.argmax(var[candidates])])


def _dark_variance(pt: PhotonTransfer) -> tuple[float, float]:
    """σ²_y,dark at t_exp → 0 (intercept over > 2 exposures, else the mean) with its standard deviation."""
    t = pt.dark_exposure_s
    v = pt.dark_series_var_dn2
    if len(np.unique(t)) > 2:
        fit = fit_line(t, v)
        return fit.intercept, fit.intercept_std
    return float(np.mean(v)), float(np.std(v, ddof=1) / math.sqrt(len(v))) if len(v) > 1 else 0.0


def _sigma_d(dark_var: np.ndarray | float, k: np.ndarray | float) -> np.ndarray:
    return np.sqrt(np.maximum(dark_var, MIN_DARK_VAR_DN2) - QUANTISATION_VAR_DN2) / k


def _ratio_std(value: float, a: float, a_std: float, b: float, b_std: float) -> float:
    """Standard deviation of value = f(a, b) ∝ a^±1 b^±1 by first-order propagation (independent a, b)."""
    return abs(value) * math.hypot(a_std / a, b_std / b)


def half_saturation_index(pt: PhotonTransfer) -> int:
    """Index (in ``pt``'s order, which must be sorted by μ_p) of the point at or below saturation whose signal
    is nearest 50 % of the saturation signal."""
    signal = pt.signal_dn
    sat = saturation_index(pt.temporal_var_dn2, pt.signal_dn)
    return int(np.argmin(np.abs(signal[: sat + 1] - 0.5 * signal[sat])))


def _spatial_point(pt: PhotonTransfer) -> SpatialPoint | None:
    if pt.spatial is not None:
        return pt.spatial
    i = half_saturation_index(pt)
    values = (pt.spatial_var_dn2[i], pt.dark_spatial_var_dn2[i], pt.frames[i], pt.dark_frames[i])
    if not all(np.isfinite(values)):
        return None
    return SpatialPoint(pt.mean_dn[i], pt.temporal_var_dn2[i], pt.spatial_var_dn2[i], int(pt.frames[i]),
                        pt.dark_mean_dn[i], pt.dark_temporal_var_dn2[i], pt.dark_spatial_var_dn2[i],
                        int(pt.dark_frames[i]))


def nonuniformity(sp: SpatialPoint, k: float) -> tuple[float | None, float | None]:
    """(DSNU [e⁻], PRNU [%]) with the temporal-noise correction; None where a corrected variance is < 0."""
    s2_dark = sp.dark_spatial_var_dn2 - sp.dark_temporal_var_dn2 / sp.dark_frames
    s2 = sp.spatial_var_dn2 - sp.temporal_var_dn2 / sp.frames
    dsnu = math.sqrt(s2_dark) / k if s2_dark >= 0 else None
    excess = s2 - max(s2_dark, 0.0)
    prnu = 100.0 * math.sqrt(excess) / (sp.mean_dn - sp.dark_mean_dn) if excess >= 0 else None
    return dsnu, prnu


def linearity(photons: np.ndarray, signal: np.ndarray, idx: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(LE [%], fitted line over all points, relative deviation δ [%] of all points) — fit weighted by 1/y."""
    slope, intercept = np.polyfit(photons[idx], signal[idx], 1, w=1.0 / signal[idx])
    fit = slope * photons + intercept
    dev = 100.0 * (signal - fit) / fit
    return float((dev[idx].max() - dev[idx].min()) / 2.0), fit, dev


@dataclass(frozen=True)
class EmvaResult:
    """The EMVA 1288 parameters (`values`, JSON keys) and the curves for the plots (`curves`)."""

    values: dict
    curves: dict


def _require_fit_points(idx: np.ndarray, what: str, total: int) -> None:
    if len(idx) < MIN_FIT_POINTS:
        raise ConfigError(what, len(idx), f"too few points in the fit range (need >= {MIN_FIT_POINTS}, "
                                          f"sweep has {total} points)")


def characterize(pt: PhotonTransfer, seed: int = 0) -> EmvaResult:
    """All EMVA 1288 linear-model parameters of a photon-transfer sweep (see the module docstring)."""
    pt = pt.sorted()
    if len(pt.dark_series_var_dn2) == 0:
        raise ConfigError("dark frames", 0, "no dark frames: EMVA 1288 needs dark statistics")
    signal, var = pt.signal_dn, pt.signal_var_dn2
    sat = saturation_index(pt.temporal_var_dn2, pt.signal_dn)
    fit_idx = _indices(signal, sat, -np.inf, SENSITIVITY_FIT_FRACTION)
    fit_idx = fit_idx[pt.photons[fit_idx] > 0]
    _require_fit_points(fit_idx, "sensitivity fit (0-70 % of saturation)", len(signal))
    k_fit = fit_line(signal[fit_idx], var[fit_idx], through_origin=True)
    r_fit = fit_line(pt.photons[fit_idx], signal[fit_idx], through_origin=True)
    k, r = k_fit.slope, r_fit.slope
    eta = r / k
    eta_std = _ratio_std(eta, r, r_fit.slope_std, k, k_fit.slope_std)
    dark_var, dark_var_std = _dark_variance(pt)
    sigma_d = float(_sigma_d(dark_var, k))
    eff_var = max(dark_var, MIN_DARK_VAR_DN2)
    sigma_d_std = math.hypot(dark_var_std / (2 * k * math.sqrt(eff_var - QUANTISATION_VAR_DN2)),
                             sigma_d * k_fit.slope_std / k)

    k_samples = line_posterior(signal[fit_idx], var[fit_idx], True, seed)[:, 0]
    r_samples = line_posterior(pt.photons[fit_idx], signal[fit_idx], True, seed + 1)[:, 0]
    dark_samples = _dark_var_samples(pt, len(k_samples), seed + 2)
    eta_samples = r_samples / k_samples
    sigma_d_samples = _sigma_d(dark_samples, k_samples)

    mu_p_sat = float(pt.photons[sat])
    mu_e_sat = eta * mu_p_sat
    mu_p_min = (math.sqrt(eff_var / k**2 + 0.25) + 0.5) / eta
    lin_idx = _indices(signal, sat, *LINEARITY_RANGE)
    _require_fit_points(lin_idx, "linearity fit (5-95 % of saturation)", len(signal))
    le, lin_fit, lin_dev = linearity(pt.photons, signal, lin_idx)
    dark = dark_current(pt, k)
    spatial = _spatial_point(pt)
    dsnu, prnu = nonuniformity(spatial, k) if spatial is not None else (None, None)

    values = {
        "K_dn_per_e": k, "K_dn_per_e_std": k_fit.slope_std, "K_dn_per_e_std_mcmc": float(np.std(k_samples)),
        "quantum_efficiency": eta, "quantum_efficiency_std": eta_std,
        "quantum_efficiency_std_mcmc": float(np.std(eta_samples)),
        "responsivity_dn_per_photon": r, "responsivity_dn_per_photon_std": r_fit.slope_std,
        "dark_noise_e": sigma_d, "dark_noise_e_std": sigma_d_std,
        "dark_noise_e_std_mcmc": float(np.std(sigma_d_samples)),
        "dark_var_dn2": dark_var, "dark_var_dn2_std": dark_var_std, "dark_offset_dn": dark_offset(pt),
        "saturation_e": mu_e_sat, "saturation_e_std": mu_e_sat * eta_std / eta,
        "saturation_photons": mu_p_sat,
        "snr_max_db": 10.0 * math.log10(mu_e_sat),
        "sensitivity_threshold_photons": mu_p_min, "sensitivity_threshold_e": eta * mu_p_min,
        "dynamic_range_db": 20.0 * math.log10(mu_p_sat / mu_p_min),
        "linearity_error_percent": le,
        **dark,
        "dsnu_e": dsnu, "prnu_percent": prnu,
        "points": int(len(signal)), "sensitivity_fit_points": int(len(fit_idx)),
        "linearity_fit_points": int(len(lin_idx)), "saturation_index": sat,
        "bit_depth": int(pt.bit_depth), "gain_db": float(pt.gain_db),
        "wavelength_nm": pt.wavelength_nm, "pixel_area_m2": pt.pixel_area_m2, "source": pt.source,
        "notes": list(pt.notes),
    }
    curves = {
        "photons": pt.photons, "signal_dn": signal, "signal_var_dn2": var, "fit_idx": fit_idx, "sat": sat,
        "lin_idx": lin_idx, "linearity_fit_dn": lin_fit, "linearity_dev_percent": lin_dev,
        "snr": signal / np.sqrt(np.maximum(pt.temporal_var_dn2, 1e-30)),
        "dark_exposure_s": pt.dark_exposure_s, "dark_mean_dn": pt.dark_series_mean_dn,
        "dark_var_dn2": pt.dark_series_var_dn2,
    }
    return EmvaResult(values, curves)


def _dark_var_samples(pt: PhotonTransfer, n: int, seed: int) -> np.ndarray:
    """Posterior samples of σ²_y,dark (t_exp → 0 intercept, or the mean of the dark variances)."""
    t, v = pt.dark_exposure_s, pt.dark_series_var_dn2
    if len(np.unique(t)) > 2:
        samples = line_posterior(t, v, False, seed)[:, 1]
    elif len(v) > 2:
        samples = line_posterior(np.ones_like(v), v, True, seed)[:, 0]
    else:
        samples = np.full(n, float(np.mean(v)))
    return np.random.default_rng(seed).permutation(np.resize(samples, n))


def dark_offset(pt: PhotonTransfer) -> float:
    """μ_y,dark at t_exp → 0 [DN]: intercept of the dark means over two or more exposures, else their mean."""
    t, m = pt.dark_exposure_s, pt.dark_series_mean_dn
    return fit_line(t, m).intercept if len(np.unique(t)) > 2 else float(np.mean(m))


def dark_current(pt: PhotonTransfer, k: float) -> dict:
    """Dark current [e⁻/s] from the mean (slope / K) and from the variance (slope / K²); None with fewer than
    three distinct dark exposures."""
    t = pt.dark_exposure_s
    if len(np.unique(t)) < 3:
        return {"dark_current_e_per_s": None, "dark_current_e_per_s_std": None, "dark_current_var_e_per_s": None}
    mean_fit = fit_line(t, pt.dark_series_mean_dn)
    var_fit = fit_line(t, pt.dark_series_var_dn2)
    return {"dark_current_e_per_s": mean_fit.slope / k, "dark_current_e_per_s_std": mean_fit.slope_std / k,
            "dark_current_var_e_per_s": var_fit.slope / k**2}
