"""EMVA 1288 Release 4.0 General: the black-box characterisation of a camera whose characteristic curve need not be
linear (equation and section numbers of EMVA Standard 1288, Release 4.0 General, March 2021).

Nothing is assumed inside the camera: K and η cannot be measured (Table 2: N/A) and every parameter is referred to
the input, in photons.

* Saturation: as in the linear model (§6.7, `uwlab.experiments.emva.transfer.saturation`); μ_p.sat its photons.
* Characteristic curve (eq. 5) μ_y − μ_y.dark = R(μ_p): cubic B-spline regression (§6.6, eq. 44–47,
  `uwlab.experiments.emva.regression`) over 0 … μ_p.sat with P intervals (one per 7 points, "6 to 8" for the
  recommended ≥ 50 steps), the dark point (μ_p = 0, zero signal) included; its analytic slope ∂μ_y/∂μ_p (eq. 48–49)
  and the responsivity in the dark R_d = ∂μ_y/∂μ_p at μ_p = 0 (eq. 25).
* Output SNR_y = (μ_y − μ_y.dark)/σ_y (eq. 7) and input SNR_p = (μ_p/σ_y) ∂μ_y/∂μ_p (eq. 10); ideal sensor
  √μ_p (eq. 15).
* Absolute sensitivity threshold μ_p.min (§6.8): a cubic B-spline regression of the inverse relation μ_p(SNR_p) up to
  saturation, with the same number of intervals (the dark point SNR_p = 0 at μ_p = 0 included), evaluated at
  SNR_p = 1, when the darkest point has SNR_p ≤ 2 (else it is not computed: General D.1 asks for exposure steps
  down to SNR_p ≈ 1). The text names no weights; the regression minimises the relative deviations (weights 1/μ_p,
  the dark point weighted as the darkest measured one), as the linearity regression of Linear §6.9 does:
  unweighted, the residuals of the μ_p ≈ 10⁴ points decide the curve at μ_p ≈ 5 (−6 % on a simulated camera whose
  measured SNR_p agrees with its closed form to 1 %). SNR_p.max: the largest SNR_p measured up to saturation
  (§6.8). DR = μ_p.sat / μ_p.min (eq. 21).
* Temporal dark noise (§6.7): σ²_y.dark is the t_exp → 0 offset of the dark variances when the exposure time is varied
  (method I), else the dark variance at the shortest exposure; σ_d = √(σ²_y.dark − 1/12)/R_d [p] (eq. 50), below
  0.24 DN² set to 0.49 DN with σ_d < 0.40/R_d an upper limit (eq. 51).
* Dark current in photons: the §7.1 slopes divided by R_d (eq. 24) and R_d².
* DSNU₁₂₈₈ = s_y.dark / R_d [p] (eq. 58); PRNU₁₂₈₈ = √(s²_p.50 − s²_p.dark)/μ_p.50 (eq. 59) with the variances referred
  to the input through the local slope, s²_p = s²_y/(∂μ_y/∂μ_p)² (eq. 55–56); total SNR_p = μ_p/√(σ²_p + s²_p)
  (eq. 60) at every point.
* Non-linearity: the linearity error of Release 4.0 Linear (eq. 58–63) is reported as a number describing the
  deviation from a line (Table 2: "if linear in %, otherwise describe type of nonlinearity").
"""

from __future__ import annotations

import math

import numpy as np

from uwlab.errors import ConfigError
from uwlab.experiments.emva.linear import (
    LINEARITY_RANGE,
    MIN_DARK_VAR_DN2,
    FLOOR_DARK_SIGMA_DN,
    PARTS,
    QUANTISATION_VAR_DN2,
    area_values,
    condition_values,
    part_suffix,
    dark_current_values,
    linearity_fit,
    require_fit_points,
)
from uwlab.experiments.emva.dark import distinct
from uwlab.experiments.emva.regression import bspline_regression, fit_line, intervals_for
from uwlab.experiments.emva.transfer import (
    PhotonTransfer,
    no_split_note,
    points_between,
    saturation,
    spatial_point,
    unsaturated_note,
)

MAX_SNR_P_AT_LOWEST_POINT = 2.0


def dark_variance_general(pt: PhotonTransfer) -> tuple[float, bool]:
    """(σ²_y.dark [DN²], upper-limit flag) by §6.7 item 1 (see the module docstring)."""
    series = pt.dark.at_temperature(pt.operating_temperature_c)
    if len(distinct(pt.exposure_s)) > 1 and len(distinct(series.exposure_s)) > 2:
        var = fit_line(series.exposure_s, series.var_dn2).intercept
    else:
        var = series.at_shortest_exposure()[1]
    if var < MIN_DARK_VAR_DN2:
        return FLOOR_DARK_SIGMA_DN**2, True
    return var, False


def characterize_general(pt: PhotonTransfer) -> tuple[dict, dict]:
    """(values, curves) of the Release 4.0 General characterisation of ``pt`` (see the module docstring)."""
    pt = pt.sorted()
    notes = list(pt.notes)
    signal = pt.signal_dn
    sat = saturation(pt)
    unsaturated = unsaturated_note(pt, sat)
    if unsaturated:
        notes.append(unsaturated)
    idx = np.arange(sat.index + 1)
    idx = idx[pt.photons[idx] > 0]
    intervals = intervals_for(len(idx) + 1)
    require_fit_points(idx, "characteristic curve (up to saturation)", len(signal))
    mu_p_sat = float(pt.photons[sat.index])
    x = np.r_[0.0, pt.photons[idx]]
    curve = bspline_regression(x, np.r_[0.0, signal[idx]], intervals, (0.0, mu_p_sat))
    slope = curve.slope
    r_d = float(slope(0.0))
    if not r_d > 0:
        raise ConfigError("characteristic curve", f"R_d = {r_d:.4g}", "the slope at zero exposure must be positive")
    local_slope = slope(pt.photons[idx])
    sigma_y = np.sqrt(pt.temporal_var_dn2[idx])
    snr_p = pt.photons[idx] / sigma_y * local_slope
    relative = 1.0 / np.r_[pt.photons[idx].min(), pt.photons[idx]]
    inverse = bspline_regression(np.r_[0.0, snr_p], x, intervals, (0.0, float(snr_p.max())), relative)
    mu_p_min: float | None
    mu_p_min = float(inverse(1.0))
    if snr_p.min() > MAX_SNR_P_AT_LOWEST_POINT or not 0 < mu_p_min < mu_p_sat:
        notes.append(
            f"μ_p.min and the dynamic range not computed: the darkest point has SNR_p = {snr_p.min():.2g}, "
            "General D.1 asks for exposure steps down to SNR_p ≈ 1"
        )
        mu_p_min = None
    snr_max = float(snr_p.max())
    dr = mu_p_sat / mu_p_min if mu_p_min else None

    dark_var, upper_limit = dark_variance_general(pt)
    sigma_d = math.sqrt(dark_var - QUANTISATION_VAR_DN2) / r_d
    if upper_limit:
        notes.append(
            f"σ²_y.dark below 0.24 DN²: σ_y.dark set to 0.49 DN and σ_d = {sigma_d:.3g} p is an upper limit (eq. 51)"
        )
    lin_idx = points_between(signal, sat.index, *LINEARITY_RANGE)
    le = None
    if len(lin_idx) >= 3:
        a0, a1 = linearity_fit(pt.photons, signal, lin_idx)
        fit = a0 + a1 * pt.photons[lin_idx]
        le = float(np.mean(np.abs(100.0 * (signal[lin_idx] - fit) / fit)))

    values = {
        "model": "general",
        "standard": "EMVA 1288 Release 4.0 General",
        "K_dn_per_e": None,
        "quantum_efficiency": None,
        "inverse_K_e_per_dn": None,
        "responsivity_dark_dn_per_photon": r_d,
        "characteristic_intervals": intervals,
        "dark_var_dn2": dark_var,
        "dark_noise_dn": math.sqrt(dark_var),
        "dark_noise_p": sigma_d,
        "dark_noise_upper_limit": upper_limit,
        "saturation_index": sat.index,
        "saturation_rule": sat.rule,
        "variance_max_index": sat.variance_max_index,
        "saturation_photons": mu_p_sat,
        "saturation_dn": float(signal[sat.index]),
        "snr_max": snr_max,
        "snr_max_db": 20.0 * math.log10(snr_max),
        "snr_max_bits": math.log2(snr_max),
        "inverse_snr_max_percent": 100.0 / snr_max,
        "sensitivity_threshold_photons": mu_p_min,
        "dynamic_range": dr,
        "dynamic_range_db": 20.0 * math.log10(dr) if dr else None,
        "dynamic_range_bits": math.log2(dr) if dr else None,
        "linearity_error_percent": le,
        "points": int(len(signal)),
        "characteristic_fit_points": int(len(idx)),
    }
    values.update(area_values(values, pt.pixel_area_m2, ("saturation_photons", "sensitivity_threshold_photons")))
    dark_values, dark_fit = dark_current_values(pt, r_d, "p", notes)
    values.update(dark_values)
    all_slopes = slope(np.clip(pt.photons, 0.0, mu_p_sat))
    with np.errstate(divide="ignore", invalid="ignore"):
        snr_p_all = pt.photons / np.sqrt(pt.temporal_var_dn2) * all_slopes
        snr_y_all = signal / np.sqrt(pt.temporal_var_dn2)
    spatial_values, snr_total = _nonuniformity(pt, sat.index, r_d, slope, all_slopes, notes)
    values.update(spatial_values)
    values.update(condition_values(pt, notes))
    curves = {
        "photons": pt.photons,
        "signal_dn": signal,
        "sat": sat.index,
        "variance_max": sat.variance_max_index,
        "fit_idx": idx,
        "characteristic_fit_dn": curve(np.clip(pt.photons, 0.0, mu_p_sat)),
        "characteristic_slope": all_slopes,
        "snr_p": snr_p_all,
        "snr_y": snr_y_all,
        "snr_p_total": snr_total,
        "inverse_snr": inverse,
        "temporal_std_dn": np.sqrt(pt.temporal_var_dn2),
        "mean_diff_dn": pt.mean_diff_dn,
        "exposure_s": pt.exposure_s,
        "dark": pt.dark,
        "dark_current_fit": dark_fit,
        "spatial_split": pt.spatial,
        "dark_spatial_split": pt.dark_spatial,
        "signal_var_dn2": pt.signal_var_dn2,
    }
    return values, curves


def _nonuniformity(
    pt: PhotonTransfer, sat: int, r_d: float, slope, all_slopes: np.ndarray, notes: list[str]
) -> tuple[dict, np.ndarray]:
    """DSNU [p] (eq. 58), PRNU [%] (eq. 59) of every part, and the measured total SNR_p (eq. 60)."""
    values: dict[str, object] = {f"dsnu{part_suffix(p)}_p": None for p in PARTS}
    values |= {f"prnu{part_suffix(p)}_percent": None for p in PARTS}
    values |= {"dsnu_dn": None, "nonuniformity_source": None, "spatial_variances": None}
    with np.errstate(invalid="ignore", divide="ignore"):
        snr_total = pt.photons / np.sqrt((pt.temporal_var_dn2 + pt.spatial.total) / all_slopes**2)
    point = spatial_point(pt, sat)
    if point is None:
        notes.append(no_split_note(pt))
        return values, snr_total
    slope_50 = float(slope(point.photons))
    for p in PARTS:
        dark = point.dark[p]
        values[f"dsnu{part_suffix(p)}_p"] = math.sqrt(dark) / r_d if dark >= 0 else None
        excess = point.bright[p] / slope_50**2 - dark / r_d**2
        values[f"prnu{part_suffix(p)}_percent"] = 100.0 * math.sqrt(excess) / point.photons if excess >= 0 else None
    values["dsnu_dn"] = math.sqrt(point.dark["total"]) if point.dark["total"] >= 0 else None
    values["nonuniformity_source"] = point.source
    values["spatial_variances"] = {"bright": point.bright, "dark": point.dark, "frames": point.frames}
    return values, snr_total
