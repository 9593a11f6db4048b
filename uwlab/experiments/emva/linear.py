"""EMVA 1288 Release 4.0 Linear: the camera parameters of a photon-transfer sweep (equation and section numbers of
EMVA Standard 1288, Release 4.0 Linear, March 2021).

* Saturation (§6.6): `uwlab.experiments.emva.transfer.saturation`; μ_p.sat its photons, μ_e.sat = η μ_p.sat (eq. 24).
* Responsivity R (eq. 49): slope with fixed zero offset of μ_y − μ_y.dark against μ_p over the points from the
  darkest to 70 % of the saturation signal, 0.7 (μ_y.sat − μ_y.dark).
* System gain K (eq. 50): slope of σ²_y − σ²_y.dark against μ_y − μ_y.dark over the same points, "least-squares
  linear regression ... with unknown offset and slope". Its check (eq. 51): a cubic B-spline regression of the photon
  transfer curve up to saturation (`uwlab.experiments.emva.regression`, one interval per 7 points, at least 15
  points) gives the local slopes K_i at the n points of the 0–70 % range; the linear model holds when
  (1/n) Σ |K_i − K| / K < 0.03 (the text's "must not be smaller than 3 %" read as the limit it sets; the sum read as
  a mean). The statistic also grows with the noise of the variances (eq. 19: √(2/NM) per frame pair, large for a
  small ROI), so the part that noise alone explains (`photon_transfer_slope_noise`, propagated through the same
  regression) is subtracted before comparing with 3 %. When the check fails, or the linearity error exceeds the same
  3 %, the result suggests the general model.
* Quantum efficiency η = R / K (eq. 52).
* Temporal dark noise (eq. 53–54): σ²_y.dark measured "at the lowest exposure of the camera" (the dark measurements
  at the shortest exposure time), σ_d = √(σ²_y.dark − σ²_q) / K with σ²_q = 1/12 DN²; when σ²_y.dark < 0.24 DN²,
  σ_y.dark is set to 0.49 DN and σ_d < 0.40 / K is an upper limit.
* Absolute sensitivity threshold (eq. 26): μ_p.min = (√(σ²_y.dark / K² + 1/4) + 1/2) / η; μ_e.min = η μ_p.min (eq. 27).
* SNR (eq. 20) measured, the model eq. 21 (`uwlab.model.sensor.snr`, drawn by the plots), the ideal sensor √μ_p
  (eq. 23); total SNR with the spatial nonuniformity, measured at every point and modelled by eq. 69; SNR_max =
  √μ_e.sat (eq. 55) as a ratio, in dB (20 log₁₀) and in bits (log₂); dynamic range DR = μ_p.sat / μ_p.min (eq. 28),
  likewise.
* Linearity (§6.9): the line y = a₀ + a₁ μ_p fitted to y = μ_y − μ_y.dark over 5–95 % of the saturation signal
  minimising the relative deviations (weights 1/y², eq. 59–61), δ = 100 (y − fit)/fit (eq. 62) and
  LE = (1/n) Σ |δ| (eq. 63); the extreme δ are reported as well (the reference implementation's LE_min / LE_max).
* Dark current (§7.1, eq. 29–30): `uwlab.experiments.emva.dark`, divided by K [e⁻/s] and K² for the variance; at the
  sweep's own temperature, and at every recorded temperature (§7.2).
* DSNU, PRNU (§8.3, eq. 66–67) of the total, row, column and pixel variances
  (`uwlab.experiments.frames.nonuniformity`, highpassed), from the nonuniformity stacks or the sweep point nearest 50 %
  (`uwlab.experiments.emva.transfer.spatial_point`); spectrograms, profiles and histograms need the stacks' images.

Uncertainties (``_std``) are one-sigma errors of the regressions, propagated to first order.
"""

from __future__ import annotations

import math

import numpy as np

from uwlab.errors import ConfigError
from uwlab.experiments.emva.dark import dark_current, dark_current_by_temperature, distinct
from uwlab.experiments.frames.nonuniformity import dsnu_e, prnu_percent
from uwlab.experiments.emva.regression import bspline_regression, fit_line, intervals_for
from uwlab.experiments.emva.response import response_curve
from uwlab.experiments.emva.transfer import (
    PhotonTransfer,
    Saturation,
    no_split_note,
    points_between,
    saturation,
    spatial_point,
    unsaturated_note,
)

QUANTISATION_VAR_DN2 = 1.0 / 12.0
MIN_DARK_VAR_DN2 = 0.24
FLOOR_DARK_SIGMA_DN = 0.49
SENSITIVITY_FIT_FRACTION = 0.7
LINEARITY_RANGE = (0.05, 0.95)
LINEAR_MODEL_LIMIT = 0.03
MIN_POINTS_SLOPE_CHECK = 15
MIN_FIT_POINTS = 3
PARTS = ("total", "row", "col", "pixel")


def linear_model_holds(slope_deviation: float | None, slope_noise: float | None, le: float) -> bool:
    """Whether the linear model describes the camera: the eq. 51 deviation, less what the variances' noise alone
    produces, below 3 %, and the linearity error below 3 %."""
    excess = (slope_deviation or 0.0) - (slope_noise or 0.0)
    return excess < LINEAR_MODEL_LIMIT and le < 100 * LINEAR_MODEL_LIMIT


def require_fit_points(idx: np.ndarray, what: str, total: int) -> None:
    if len(idx) < MIN_FIT_POINTS:
        raise ConfigError(
            what, len(idx), f"too few points in the fit range (need >= {MIN_FIT_POINTS}, sweep has {total} points)"
        )


def dark_noise(pt: PhotonTransfer) -> tuple[float, float, bool]:
    """(σ²_y.dark [DN²] as used, its exposure [s], upper-limit flag): the dark variance at the shortest exposure,
    raised to 0.49² DN² below 0.24 DN² (eq. 54)."""
    t, var = pt.dark.at_shortest_exposure()
    if var < MIN_DARK_VAR_DN2:
        return FLOOR_DARK_SIGMA_DN**2, t, True
    return var, t, False


def linearity_fit(photons: np.ndarray, signal: np.ndarray, idx: np.ndarray) -> tuple[float, float]:
    """(a₀, a₁) of eq. 59–61: least squares of the relative deviations over the points ``idx``."""
    h, y = photons[idx], signal[idx]
    s_h_y2 = np.sum(h / y**2)
    s_h_y = np.sum(h / y)
    s_h2_y2 = np.sum(h**2 / y**2)
    s_1_y = np.sum(1 / y)
    s_1_y2 = np.sum(1 / y**2)
    delta = s_h_y2**2 - s_h2_y2 * s_1_y2
    a0 = (s_h_y * s_h_y2 - s_h2_y2 * s_1_y) / delta
    a1 = (s_h_y2 * s_1_y - s_h_y * s_1_y2) / delta
    return float(a0), float(a1)


def photon_transfer_slope_deviation(
    signal: np.ndarray, var: np.ndarray, var_std: np.ndarray, evaluate: np.ndarray, k: float
) -> tuple[float, float]:
    """(deviation, noise): (1/n) Σ |K_i − K| / K of eq. 51, K_i the slopes at the n points ``evaluate`` of the cubic
    B-spline regression of the photon transfer curve (all the given points, up to saturation, so that the 70 % point
    is not at the spline's free end, where its slope is least determined); and the value the same statistic takes
    for a straight curve from the noise of the variances alone, √(2/π) × the mean standard deviation of K_i propagated
    from ``var_std`` through the regression (zero when ``var_std`` is unknown)."""
    spline = bspline_regression(
        signal, var, intervals_for(len(signal)), (min(0.0, float(signal.min())), float(signal.max()))
    )
    deviation = float(np.mean(np.abs(spline.slope(signal[evaluate]) - k)) / k)
    slopes = spline.slope_basis(signal[evaluate]) @ np.linalg.pinv(spline.basis(signal))
    slope_std = np.sqrt(np.einsum("ij,j,ij->i", slopes, np.nan_to_num(var_std) ** 2, slopes))
    return deviation, float(math.sqrt(2.0 / math.pi) * np.mean(slope_std) / k)


def variance_std(pt: PhotonTransfer) -> np.ndarray:
    """Standard deviation of σ²_y − σ²_y.dark per point from eq. 19, σ(σ²)/σ² = √(2/(NM)) per frame pair (0 when
    the image size is unknown)."""
    pixels = pt.width_px * pt.height_px
    if pixels <= 0:
        return np.zeros_like(pt.photons)
    bright = pt.temporal_var_dn2**2 / np.maximum(pt.frames // 2, 1)
    dark = pt.dark_temporal_var_dn2**2 / np.maximum(pt.dark_frames // 2, 1)
    return np.sqrt(2.0 / pixels * (bright + dark))


def characterize_linear(pt: PhotonTransfer) -> tuple[dict, dict]:
    """(values, curves) of the Release 4.0 Linear characterisation of ``pt`` (see the module docstring)."""
    pt = pt.sorted()
    notes = list(pt.notes)
    signal, var = pt.signal_dn, pt.signal_var_dn2
    sat = saturation(pt)
    unsaturated = unsaturated_note(pt, sat)
    if unsaturated:
        notes.append(unsaturated)
    fit_idx = points_between(signal, sat.index, -np.inf, SENSITIVITY_FIT_FRACTION)
    fit_idx = fit_idx[pt.photons[fit_idx] > 0]
    require_fit_points(fit_idx, "sensitivity fit (0-70 % of saturation)", len(signal))
    k_fit = fit_line(signal[fit_idx], var[fit_idx])
    r_fit = fit_line(pt.photons[fit_idx], signal[fit_idx], through_origin=True)
    k, r = k_fit.slope, r_fit.slope
    if not k > 0 or not r > 0:
        raise ConfigError("photon transfer", f"K = {k:.4g}, R = {r:.4g}", "slopes must be positive: is the light on?")
    eta = r / k
    eta_std = abs(eta) * math.hypot(r_fit.slope_std / r, k_fit.slope_std / k)
    slope_deviation = slope_noise = None
    upto = np.arange(sat.index + 1)
    upto = upto[pt.photons[upto] > 0]
    if len(upto) >= MIN_POINTS_SLOPE_CHECK:
        slope_deviation, slope_noise = photon_transfer_slope_deviation(
            signal[upto], var[upto], variance_std(pt)[upto], np.searchsorted(upto, fit_idx), k
        )
    else:
        notes.append(
            f"photon transfer linearity (eq. 51) not checked: {len(upto)} points up to saturation, the "
            f"B-spline check needs {MIN_POINTS_SLOPE_CHECK}"
        )

    dark_var, dark_t, upper_limit = dark_noise(pt)
    sigma_d = math.sqrt(dark_var - QUANTISATION_VAR_DN2) / k
    if upper_limit:
        notes.append(
            f"σ²_y.dark below 0.24 DN² at {dark_t * 1e6:g} µs: σ_y.dark set to 0.49 DN and σ_d = "
            f"{sigma_d:.3g} e- is an upper limit (eq. 54)"
        )
    mu_p_min = (math.sqrt(dark_var / k**2 + 0.25) + 0.5) / eta
    mu_p_sat = float(pt.photons[sat.index])
    mu_e_sat = eta * mu_p_sat
    snr_max = math.sqrt(mu_e_sat)
    dr = mu_p_sat / mu_p_min

    lin_idx = points_between(signal, sat.index, *LINEARITY_RANGE)
    require_fit_points(lin_idx, "linearity fit (5-95 % of saturation)", len(signal))
    a0, a1 = linearity_fit(pt.photons, signal, lin_idx)
    lin_fit = a0 + a1 * pt.photons
    deviation = 100.0 * (signal - lin_fit) / lin_fit
    le = float(np.mean(np.abs(deviation[lin_idx])))
    if not linear_model_holds(slope_deviation, slope_noise, le):
        shown = "n/a" if slope_deviation is None else f"{100 * slope_deviation:.1f} %"
        notes.append(
            f"the linear model does not describe this camera (photon transfer slope deviation {shown}, eq. "
            f"51; linearity error {le:.1f} %; limit 3 %): characterise it with --model general"
        )

    values = {
        "model": "linear",
        "standard": "EMVA 1288 Release 4.0 Linear",
        "K_dn_per_e": k,
        "K_dn_per_e_std": k_fit.slope_std,
        "inverse_K_e_per_dn": 1.0 / k,
        "photon_transfer_offset_dn2": k_fit.intercept,
        "photon_transfer_slope_deviation": slope_deviation,
        "photon_transfer_slope_noise": slope_noise,
        "responsivity_dn_per_photon": r,
        "responsivity_dn_per_photon_std": r_fit.slope_std,
        "quantum_efficiency": eta,
        "quantum_efficiency_std": eta_std,
        "dark_var_dn2": dark_var,
        "dark_noise_dn": math.sqrt(dark_var),
        "dark_noise_e": sigma_d,
        "dark_noise_e_std": sigma_d * k_fit.slope_std / k,
        "dark_noise_upper_limit": upper_limit,
        "dark_noise_exposure_s": dark_t,
        "saturation_index": sat.index,
        "saturation_rule": sat.rule,
        "variance_max_index": sat.variance_max_index,
        "saturation_photons": mu_p_sat,
        "saturation_e": mu_e_sat,
        "saturation_e_std": mu_e_sat * eta_std / eta,
        "saturation_dn": float(signal[sat.index]),
        "snr_max": snr_max,
        "snr_max_db": 20.0 * math.log10(snr_max),
        "snr_max_bits": math.log2(snr_max),
        "inverse_snr_max_percent": 100.0 / snr_max,
        "sensitivity_threshold_photons": mu_p_min,
        "sensitivity_threshold_e": eta * mu_p_min,
        "dynamic_range": dr,
        "dynamic_range_db": 20.0 * math.log10(dr),
        "dynamic_range_bits": math.log2(dr),
        "linearity_error_percent": le,
        "linearity_deviation_min_percent": float(deviation[lin_idx].min()),
        "linearity_deviation_max_percent": float(deviation[lin_idx].max()),
        "linearity_offset_dn": a0,
        "linearity_slope_dn_per_photon": a1,
        "points": int(len(signal)),
        "sensitivity_fit_points": int(len(fit_idx)),
        "sensitivity_index_min": int(fit_idx[0]),
        "sensitivity_index_max": int(fit_idx[-1]),
        "linearity_fit_points": int(len(lin_idx)),
        "linearity_index_min": int(lin_idx[0]),
        "linearity_index_max": int(lin_idx[-1]),
    }
    values.update(
        area_values(
            values,
            pt.pixel_area_m2,
            ("saturation_photons", "saturation_e", "sensitivity_threshold_photons", "sensitivity_threshold_e"),
        )
    )
    values["response"] = response_curve(pt.photons, signal, sat.index, eta, mu_e_sat)
    dark_values, dark_fit = dark_current_values(pt, k, "e", notes, k_fit.slope_std)
    values.update(dark_values)
    spatial_values, spatial_curves = _nonuniformity(pt, sat, k, notes)
    values.update(spatial_values)
    values.update(condition_values(pt, notes))
    curves = {
        "photons": pt.photons,
        "signal_dn": signal,
        "signal_var_dn2": var,
        "fit_idx": fit_idx,
        "sat": sat.index,
        "variance_max": sat.variance_max_index,
        "lin_idx": lin_idx,
        "linearity_fit_dn": lin_fit,
        "linearity_dev_percent": deviation,
        "temporal_std_dn": np.sqrt(pt.temporal_var_dn2),
        "mean_diff_dn": pt.mean_diff_dn,
        "snr": signal / np.sqrt(np.maximum(pt.temporal_var_dn2, 1e-30)),
        "exposure_s": pt.exposure_s,
        "dark": pt.dark,
        "photon_transfer_line": (k, k_fit.intercept),
        "dark_current_fit": dark_fit,
        **spatial_curves,
    }
    return values, curves


def area_values(values: dict, pixel_area_m2: float | None, keys: tuple[str, ...]) -> dict:
    """The per-µm² variants of ``keys`` (Table 2: "in number of ... per µm²"), None without a pixel area."""
    area_um2 = pixel_area_m2 * 1e12 if pixel_area_m2 else None
    return {f"{key}_per_um2": values[key] / area_um2 if area_um2 and values[key] is not None else None for key in keys}


def dark_current_values(
    pt: PhotonTransfer, scale: float, unit: str, notes: list[str], scale_std: float = 0.0
) -> tuple[dict, object]:
    """§7.1 at the sweep's temperature and §7.2 at every recorded temperature, divided by ``scale`` (K: ``unit``
    "e"; R_d: "p") and ``scale``² for the variance, the standard deviations including ``scale_std``; also the dark
    offset μ_y.dark at the shortest exposure or the regression's t_exp → 0 value. Returns (values, the `DarkCurrent`
    fit or None)."""
    series = pt.dark.at_temperature(pt.operating_temperature_c)
    current = dark_current(series)
    key = f"dark_current_{unit}_per_s"
    var_key = f"dark_current_var_{unit}_per_s"
    by_temperature = [
        {
            "temperature_c": d.temperature_c,
            key: d.mean_dn_per_s / scale,
            f"{key}_std": d.mean_dn_per_s_std / scale,
            var_key: d.var_dn2_per_s / scale**2,
            f"{var_key}_std": d.var_dn2_per_s_std / scale**2,
            "exposures": d.exposures,
        }
        for d in dark_current_by_temperature(pt.dark)
    ]
    exposures = len(distinct(series.exposure_s))
    values = {
        key: None,
        f"{key}_std": None,
        var_key: None,
        f"{var_key}_std": None,
        "dark_current_dn_per_s": None,
        "dark_current_var_dn2_per_s": None,
        "dark_current_exposures": exposures,
        "dark_offset_dn": float(series.mean_dn[series.exposure_s == series.exposure_s.min()].mean()),
        "dark_current_by_temperature": by_temperature,
    }
    if current is None:
        notes.append(
            f"dark current not computed: dark frames at {exposures} exposure times, Release 4.0 §7.1 needs at least 6"
        )
        return values, None
    if current.mean_dn_per_s + current.mean_dn_per_s_std <= 0:
        notes.append(
            "dark current below its one-sigma error: the exposure times are too short to measure it "
            "(§7.1: reported with its error)"
        )
    rel = scale_std / scale
    values |= {
        key: current.mean_dn_per_s / scale,
        f"{key}_std": math.hypot(current.mean_dn_per_s_std, current.mean_dn_per_s * rel) / scale,
        var_key: current.var_dn2_per_s / scale**2,
        f"{var_key}_std": math.hypot(current.var_dn2_per_s_std, 2 * current.var_dn2_per_s * rel) / scale**2,
        "dark_current_dn_per_s": current.mean_dn_per_s,
        "dark_current_var_dn2_per_s": current.var_dn2_per_s,
        "dark_offset_dn": current.offset_dn,
    }
    return values, current


def _nonuniformity(pt: PhotonTransfer, sat: Saturation, k: float, notes: list[str]) -> tuple[dict, dict]:
    """DSNU [e⁻] and PRNU [%] of every part (eq. 66–67), the spatial variances for the XML, the measured total SNR
    at every point and the model of eq. 69."""
    point = spatial_point(pt, sat.index)
    values: dict[str, object] = {f"dsnu{part_suffix(p)}_e": None for p in PARTS}
    values |= {f"prnu{part_suffix(p)}_percent": None for p in PARTS}
    values |= {"dsnu_dn": None, "nonuniformity_source": None, "spatial_variances": None}
    with np.errstate(divide="ignore", invalid="ignore"):
        snr_total = pt.signal_dn / np.sqrt(pt.temporal_var_dn2 + pt.spatial.total)
    curves = {"snr_total": snr_total, "spatial_split": pt.spatial, "dark_spatial_split": pt.dark_spatial}
    if point is None:
        notes.append(no_split_note(pt))
        return values, curves
    for p in PARTS:
        values[f"dsnu{part_suffix(p)}_e"] = dsnu_e(point.dark[p], k)
        values[f"prnu{part_suffix(p)}_percent"] = prnu_percent(point.bright[p], point.dark[p], point.signal_dn)
    values["dsnu_dn"] = math.sqrt(point.dark["total"]) if point.dark["total"] >= 0 else None
    values["nonuniformity_source"] = point.source
    spatial: dict[str, object] = {"bright": point.bright, "dark": point.dark, "frames": point.frames}
    stack = pt.stack
    if stack is not None and stack.bright.spatial is not None and stack.dark.spatial is not None:
        spatial |= {
            "bright_measured": stack.bright.spatial.measured,
            "dark_measured": stack.dark.spatial.measured,
            "bright_cav": stack.bright.spatial.cav,
            "bright_rav": stack.bright.spatial.rav,
            "dark_cav": stack.dark.spatial.cav,
            "dark_rav": stack.dark.spatial.rav,
            "bright_stack_var": stack.bright.stack_var_dn2,
            "dark_stack_var": stack.dark.stack_var_dn2,
        }
    values["spatial_variances"] = spatial
    return values, curves


def total_snr_model(mu_e, sigma_d_e: float, k: float, dsnu: float | None, prnu_pct: float | None):
    """SNR_total of eq. 69 [1] for μ_e = η μ_p electrons."""
    mu_e = np.asarray(mu_e, float)
    spatial = (dsnu or 0.0) ** 2 + ((prnu_pct or 0.0) / 100.0 * mu_e) ** 2
    return mu_e / np.sqrt(sigma_d_e**2 + QUANTISATION_VAR_DN2 / k**2 + mu_e + spatial)


def part_suffix(part: str) -> str:
    return "" if part == "total" else f"_{part}"


def condition_values(pt: PhotonTransfer, notes: list[str]) -> dict:
    """Operating point and provenance entries shared by both models."""
    return {
        "bit_depth": int(pt.bit_depth),
        "gain_db": float(pt.gain_db),
        "wavelength_nm": pt.wavelength_nm,
        "pixel_area_m2": pt.pixel_area_m2,
        "temperature_c": pt.operating_temperature_c,
        "width_px": int(pt.width_px),
        "height_px": int(pt.height_px),
        "source": pt.source,
        "channel": pt.channel,
        "notes": notes,
    }
