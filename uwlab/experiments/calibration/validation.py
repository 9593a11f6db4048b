"""Validation of a calibrated model: posterior predictive bands, cross-configuration prediction, spectra.

- Posterior predictive: the predicted mean response (dark-subtracted) for every posterior sample; the median and
  the 68 % (16–84th percentile) and 95 % (2.5–97.5th) credible bands at every measured point and along a dense
  exposure sweep per configuration; residuals (measured − median) in DN and in units of the point's σ. "Inside 95 %" counts a measured point
  against the posterior predictive band of a new measurement (mean + measurement noise ⊕ discrepancy).
- Cross-configuration: fit on some configurations, predict the held-out ones from the posterior (parameters the
  training data cannot reach — e.g. the gain K of a camera not in the training set — are drawn from their priors)
  and report, per configuration, the median relative error and the fraction of points inside the 95 % band.
- Spectra: the spectral irradiance the model predicts at the target (facing the light) and at the camera
  (π L_w), with the posterior median parameters, against what the spectrometer measured.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd

from uwlab.experiments.calibration.fit import FitConfig, FitResult, fit_points
from uwlab.experiments.calibration.forward import ForwardModel, build_forward_model
from uwlab.model.design import stage_spectra

BANDS = (2.5, 16, 50, 84, 97.5)
MAX_PREDICTIVE_SAMPLES = 2000


def _thinned(samples: np.ndarray) -> np.ndarray:
    step = max(1, samples.shape[0] // MAX_PREDICTIVE_SAMPLES)
    return samples[::step]


def predictive_bands(model: ForwardModel, samples: np.ndarray, observed: bool = False, seed: int = 0) -> dict[str, np.ndarray]:
    """Percentiles (2.5, 16, 50, 84, 97.5) of the predicted mean response at the model's points; with
    `observed`, of a new measurement (mean + measurement noise ⊕ discrepancy), the posterior predictive."""
    theta = _thinned(samples)
    mu = model.predict(theta)
    if observed:
        mu = mu + model.sigma(theta, mu) * np.random.default_rng(seed).standard_normal(mu.shape)
    q = np.percentile(mu, BANDS, axis=0)
    return dict(zip(("p2_5", "p16", "median", "p84", "p97_5"), q))


def point_predictions(result: FitResult) -> pd.DataFrame:
    """Measured against predicted at every fitted point, with bands and residuals; the saturated points the fit
    left out follow with ``saturated`` true, their measured value and no prediction."""
    model = result.model
    bands = predictive_bands(model, result.samples)
    observed = predictive_bands(model, result.samples, observed=True)
    columns = [c for c in ("sweep_id", "sensor_profile", "lens_label", "exposure_us", "gain_db") if c in model.points]
    frame = model.points[columns].copy()
    frame["measured_dn"] = model.y
    for key, values in bands.items():
        frame[f"predicted_{key}"] = values
    frame["observed_p2_5"] = observed["p2_5"]
    frame["observed_p97_5"] = observed["p97_5"]
    median_theta = np.median(result.samples, axis=0)[None, :]
    sigma = model.sigma(median_theta, model.predict(median_theta))[0]
    frame["residual_dn"] = model.y - bands["median"]
    frame["residual_sigma"] = frame["residual_dn"] / sigma
    frame["saturated"] = False
    if result.saturated is not None and len(result.saturated):
        left_out = result.saturated[[c for c in columns if c in result.saturated]].copy()
        left_out["measured_dn"] = result.saturated["signal_dn"].to_numpy(float)
        left_out["saturated"] = True
        frame = pd.concat([frame, left_out], ignore_index=True)
    return frame


def dense_sweeps(result: FitResult, n: int = 60) -> pd.DataFrame:
    """Predicted bands along a dense log-spaced exposure sweep per configuration (fitted exposure range)."""
    model = result.model
    rows = []
    for k in range(len(model.designs)):
        sel = model.config == k
        exposures = np.geomspace(model.points.loc[sel, "exposure_us"].min(), model.points.loc[sel, "exposure_us"].max(), n)
        first = np.flatnonzero(sel)[0]
        per_point = model.effective_exposure_s[first] / (model.points.loc[first, "exposure_us"])
        dense = replace(model, effective_exposure_s=per_point * exposures, config=np.full(n, k), camera=np.full(n, model.camera[first]),
                        y=np.zeros(n), sigma_meas=np.zeros(n))
        bands = predictive_bands(dense, result.samples)
        frame = pd.DataFrame({"sweep_id": model.points.loc[first, "sweep_id"], "configuration": k, "exposure_us": exposures,
                              **{f"predicted_{key}": v for key, v in bands.items()}})
        rows.append(frame)
    return pd.concat(rows, ignore_index=True)


def _prior_columns(config: FitConfig, names: tuple[str, ...], samples: np.ndarray, train_names: tuple[str, ...],
                   rng: np.random.Generator) -> np.ndarray:
    columns = []
    for name in names:
        if name in train_names:
            columns.append(samples[:, train_names.index(name)])
        else:
            columns.append(config.priors[name].sample(rng, (samples.shape[0],)))
    return np.stack(columns, axis=1)


def cross_configuration(points: pd.DataFrame, rigs: dict, config: FitConfig, train_sweeps: list[str],
                        progress=None) -> tuple[pd.DataFrame, FitResult]:
    """Fit on `train_sweeps`, predict the other sweeps; per-configuration errors."""
    usable = points[~points["saturated"].astype(bool)]
    train = usable[usable["sweep_id"].isin(train_sweeps)]
    test = usable[~usable["sweep_id"].isin(train_sweeps)]
    cameras = tuple(sorted(train["sensor_profile"].astype(str).unique()))
    train_config = config.model_copy(update={"priors": {n: p for n, p in config.priors.items()
                                                       if not n.startswith("K_dn_per_e:") or n.split(":", 1)[1] in cameras}})
    result = fit_points(train, rigs, train_config, progress=progress)
    rows = []
    if not test.empty:
        model = build_forward_model(test, rigs, config.names)
        theta = _prior_columns(config, model.names, _thinned(result.samples), result.names, np.random.default_rng(config.sampler.seed))
        predicted = model.predict(theta)
        observed = predicted + model.sigma(theta, predicted) * np.random.default_rng(config.sampler.seed).standard_normal(predicted.shape)
        q = np.percentile(predicted, [2.5, 50, 97.5], axis=0)
        q[[0, 2]] = np.percentile(observed, [2.5, 97.5], axis=0)
        frame = test.reset_index(drop=True).assign(median=q[1], lo=q[0], hi=q[2])
        for sweep_id, group in frame.groupby("sweep_id", sort=False):
            rel = (group["median"] - group["signal_dn"]) / group["signal_dn"]
            rows.append({"sweep_id": sweep_id, "role": "held out", "points": len(group),
                         "median_abs_rel_error": float(np.median(np.abs(rel))),
                         "max_abs_rel_error": float(np.max(np.abs(rel))),
                         "inside_95": float(np.mean((group["signal_dn"] >= group["lo"]) & (group["signal_dn"] <= group["hi"])))})
    bands = predictive_bands(result.model, result.samples, observed=True)
    for sweep_id in train_sweeps:
        sel = (result.model.points["sweep_id"] == sweep_id).to_numpy()
        if sel.any():
            rel = (bands["median"][sel] - result.model.y[sel]) / result.model.y[sel]
            inside = (result.model.y[sel] >= bands["p2_5"][sel]) & (result.model.y[sel] <= bands["p97_5"][sel])
            rows.append({"sweep_id": sweep_id, "role": "fitted", "points": int(sel.sum()),
                         "median_abs_rel_error": float(np.median(np.abs(rel))), "max_abs_rel_error": float(np.max(np.abs(rel))),
                         "inside_95": float(np.mean(inside))})
    return pd.DataFrame(rows), result


def predicted_spectra(result: FitResult) -> pd.DataFrame:
    """Model spectra at the target and at the camera, per sweep, with the posterior median parameters and the
    sweep's measured relative light output."""
    model = result.model
    median = dict(zip(result.names, np.median(result.samples, axis=0)))
    value = lambda name: median.get(name, model.nominal[name])  # noqa: E731
    frames = []
    seen = set()
    for k, design in enumerate(model.designs):
        sweep_id = model.points.loc[np.flatnonzero(model.config == k)[0], "sweep_id"]
        if sweep_id in seen:
            continue
        seen.add(sweep_id)
        fitted = design.with_values(**{"water.attenuation_scale": value("attenuation_scale"),
                                       "light.beam_half_angle_deg": value("beam_half_angle_deg"),
                                       "light.beam_half_angle_in_air_deg": None,
                                       "target.reflectance": value("reflectance")})
        spectra = stage_spectra(fitted)
        cos_i = np.cos(np.radians(design["light.incidence_deg"]))
        rows = model.points["sweep_id"] == sweep_id
        level = float(model.points.loc[rows, "relative_flux"].median()) if "relative_flux" in model.points else 1.0
        eff = value("light_efficiency") * level
        for position, irradiance in (("target", spectra["target_irradiance_w_m2_nm"] / cos_i),
                                     ("camera", np.pi * spectra["return_radiance_w_m2_sr_nm"])):
            frames.append(pd.DataFrame({"sweep_id": sweep_id, "position": position, "wavelength_nm": spectra["wavelength_nm"],
                                        "predicted_w_m2_nm": eff * irradiance}))
    return pd.concat(frames, ignore_index=True)


def compare_spectra(predicted: pd.DataFrame, measured: pd.DataFrame) -> pd.DataFrame:
    """Per sweep and position: the mean measured spectrum against the prediction (integrated ratio, shape error)."""
    rows = []
    if measured.empty:
        return pd.DataFrame(rows)
    mean = measured.groupby(["sweep_id", "position", "wavelength_nm"], as_index=False)["irradiance_w_m2_nm"].mean()
    for (sweep_id, position), group in mean.groupby(["sweep_id", "position"]):
        pred = predicted[(predicted["sweep_id"] == sweep_id) & (predicted["position"] == position)]
        if pred.empty:
            continue
        model = np.interp(group["wavelength_nm"], pred["wavelength_nm"], pred["predicted_w_m2_nm"])
        meas = group["irradiance_w_m2_nm"].to_numpy()
        ratio = np.trapezoid(meas, group["wavelength_nm"]) / np.trapezoid(model, group["wavelength_nm"])
        shape = np.sqrt(np.mean((meas / meas.max() - model / model.max()) ** 2))
        rows.append({"sweep_id": sweep_id, "position": position, "measured_over_predicted": float(ratio),
                     "shape_rms_error": float(shape)})
    return pd.DataFrame(rows)
