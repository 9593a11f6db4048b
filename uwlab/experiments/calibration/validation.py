"""Validation of a calibrated model: posterior predictive bands and checks, held-out configurations, spectra.

- Posterior predictive (`predictive_draws`): for every posterior sample θ, the predicted mean response of each
  point, μ(θ) (1 + δ_k), with its configuration's discrepancy δ_k drawn given θ and the data
  (`uwlab.experiments.calibration.fit.config_offsets`), and a new measurement of it (+ measurement noise ⊕
  within-configuration discrepancy). Bands: the 2.5/16/50/84/97.5th percentiles at every measured point and along a
  dense exposure sweep per configuration; residuals (measured − median) in DN, per cent and units of σ. "Inside
  95 %" counts a measured point against the band of a new measurement.
- Posterior predictive check per configuration (Gelman, Meng & Stern, Statistica Sinica 6, 733–807, 1996):
  T = Σ (y − μ(1 + δ_k))² / σ² of the measured points against the same statistic of replicated data, p = P(T_rep ≥
  T_obs); a small p says the configuration's points scatter about the model more than its noise allows.
- Residual trend per configuration (`residual_trend`): the residuals r = y / μ̂ − 1 [%] against the swept variable
  (`SWEPT`: exposure, f-number or light level on a log axis, gain in dB) by ordinary least squares; the trend is
  the fitted line's values at the sweep's two ends ("+0.6 → −0.7 %") and p the two-sided t-test of its slope
  (n − 2 degrees of freedom, the scatter about the line estimated from the points themselves, so the test holds
  whatever the noise model). A χ² check misses such a drift when the points are few or the discrepancy absorbs it.
- Held-out configurations (`held_out_fold`, `CrossValidation`): the configurations are split into folds (by default
  one per configuration, "leave one configuration out", so that every fold learns τ from all the others; or a
  number of folds dealt out in sweep order; or the [holdout] train list; the folds run in parallel:
  `uwlab.experiments.calibration.parallel`); each fold is fitted on the others and predicts its own
  configurations as new ones: δ_new ~ N(0, τ²) with the posterior's between-configuration scale τ, and parameters
  the training data cannot reach (the gain K of a camera it has not seen, the transmittance of a lens setting
  no training configuration carried) drawn from their priors. Per
  configuration: the relative error of the median, the fraction of points inside the 95 % band, and a check of
  the configuration's level: ρ = median(y / μ̂ − 1) against the same statistic of replicated data (two-sided p).
- Spectra: the spectral irradiance the model predicts at the target (facing the light) and at the camera
  (π L_w), with the posterior median parameters, against what the spectrometer measured.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from uwlab.experiments.calibration.fit import (
    LEAVE_ONE_OUT,
    FitConfig,
    FitResult,
    config_offsets,
    fit_points,
    one_blas_thread,
)
from uwlab.experiments.calibration.forward import (
    BARE,
    PER_LENS,
    ForwardModel,
    build_forward_model,
    lens_group_parameters,
)
from uwlab.model.evaluation import stage_spectra

BANDS = (2.5, 16, 50, 84, 97.5)
BAND_NAMES = ("p2_5", "p16", "median", "p84", "p97_5")
MAX_PREDICTIVE_SAMPLES = 2000
PREDICTION_COLUMNS = (
    "sweep_id",
    "sensor_profile",
    "lens_label",
    "focal_length_mm",
    "f_number",
    "exposure_us",
    "gain_db",
)


def _thinned(samples: np.ndarray) -> np.ndarray:
    step = max(1, samples.shape[0] // MAX_PREDICTIVE_SAMPLES)
    return samples[::step]


def new_offsets(model: ForwardModel, theta: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Discrepancies of configurations the fit has not seen, δ ~ N(0, τ²) per sample, shape (n, n_config)."""
    tau = model.parameter(theta, "config_discrepancy")[:, None]
    return tau * rng.standard_normal((theta.shape[0], model.n_config))


@dataclass(frozen=True)
class Draws:
    """Posterior predictive draws at a model's points: θ, the model's mean μ(θ), the configuration offsets, the
    mean response μ (1 + δ_k) and a new measurement of it; arrays (n_samples, n_points)."""

    theta: np.ndarray
    model_mean: np.ndarray
    offsets: np.ndarray
    mean: np.ndarray
    observed: np.ndarray
    sigma: np.ndarray


def predictive_draws(model: ForwardModel, theta: np.ndarray, seen: bool, seed: int = 0) -> Draws:
    """Draws for configurations the fit has seen (offsets given the data) or not (`seen` False: new offsets)."""
    rng = np.random.default_rng(seed)
    mu = model.predict(theta)
    offsets = config_offsets(model, theta, rng) if seen else new_offsets(model, theta, rng)
    mean = mu * (1 + offsets[:, model.config])
    sigma = model.sigma(theta, mu)
    return Draws(theta, mu, offsets, mean, mean + sigma * rng.standard_normal(mu.shape), sigma)


def _bands(values: np.ndarray) -> dict[str, np.ndarray]:
    return dict(zip(BAND_NAMES, np.percentile(values, BANDS, axis=0), strict=True))


def point_predictions(result: FitResult) -> pd.DataFrame:
    """Measured against predicted at every fitted point, with bands and residuals; the saturated points the fit
    left out follow with ``saturated`` true, their measured value and no prediction."""
    model = result.model
    draws = predictive_draws(model, _thinned(result.samples), seen=True)
    frame = _prediction_frame(model, draws)
    if result.saturated is not None and len(result.saturated):
        columns = [c for c in PREDICTION_COLUMNS if c in result.saturated]
        left_out = result.saturated[columns].copy()
        left_out["measured_dn"] = result.saturated["signal_dn"].to_numpy(float)
        left_out["saturated"] = True
        frame = pd.concat([frame, left_out], ignore_index=True)
    return frame


def _prediction_frame(model: ForwardModel, draws: Draws) -> pd.DataFrame:
    columns = [c for c in PREDICTION_COLUMNS if c in model.points]
    frame = model.points[columns].copy()
    frame["measured_dn"] = model.y
    for key, values in _bands(draws.mean).items():
        frame[f"predicted_{key}"] = values
    observed = _bands(draws.observed)
    frame["observed_p2_5"], frame["observed_p97_5"] = observed["p2_5"], observed["p97_5"]
    frame["observed_p5"], frame["observed_p95"] = np.percentile(draws.observed, (5, 95), axis=0)
    frame["residual_dn"] = model.y - frame["predicted_median"]
    frame["residual_percent"] = 100 * frame["residual_dn"] / frame["predicted_median"]
    frame["residual_sigma"] = frame["residual_dn"] / np.median(draws.sigma, axis=0)
    frame["inside_95"] = (model.y >= frame["observed_p2_5"]) & (model.y <= frame["observed_p97_5"])
    frame["saturated"] = False
    return frame


def dense_sweeps(result: FitResult, n: int = 60) -> pd.DataFrame:
    """Predicted bands along a dense log-spaced exposure sweep per configuration (fitted exposure range), with
    each configuration's discrepancy drawn given the data."""
    model = result.model
    theta = _thinned(result.samples)
    offsets = config_offsets(model, theta, np.random.default_rng(0))
    rows = []
    for k in range(model.n_config):
        sel = model.config == k
        exposures = np.geomspace(
            model.points.loc[sel, "exposure_us"].min(), model.points.loc[sel, "exposure_us"].max(), n
        )
        first = np.flatnonzero(sel)[0]
        per_point = model.effective_exposure_s[first] / (model.points.loc[first, "exposure_us"])
        dense = replace(
            model,
            effective_exposure_s=per_point * exposures,
            config=np.full(n, k),
            camera=np.full(n, model.camera[first]),
            y=np.zeros(n),
            sigma_meas=np.zeros(n),
            well_fraction_per_dn=None
            if model.well_fraction_per_dn is None
            else np.full(n, model.well_fraction_per_dn[first]),
        )
        bands = _bands(dense.predict(theta) * (1 + offsets[:, k : k + 1]))
        frame = pd.DataFrame(
            {
                "sweep_id": model.points.loc[first, "sweep_id"],
                "configuration": k,
                "exposure_us": exposures,
                **{f"predicted_{key}": v for key, v in bands.items()},
            }
        )
        rows.append(frame)
    return pd.concat(rows, ignore_index=True)


SWEPT = {"exposure": "exposure_us", "aperture": "f_number", "gain": "gain_db", "light-level": "light_level"}
LOG_SWEPT = ("exposure_us", "f_number", "light_level")


@dataclass(frozen=True)
class Trend:
    """A configuration's residual trend against its swept variable (module docstring)."""

    variable: str
    low: float  # the swept variable's range
    high: float
    start_percent: float  # the fitted residual line at `low` and at `high`
    end_percent: float
    p: float

    @property
    def change_percent(self) -> float:
        return self.end_percent - self.start_percent


def residual_trend(kind: str, swept: pd.DataFrame, residual_percent: np.ndarray) -> Trend | None:
    """The trend of `residual_percent` against the variable `kind` sweeps (a column of `swept`); None when the
    sweep has fewer than 4 distinct values of it or is not a sweep of one (dark).

    >>> rows = pd.DataFrame({"exposure_us": [10.0, 100.0, 1000.0, 10000.0, 100000.0]})
    >>> trend = residual_trend("exposure", rows, np.array([0.6, 0.3, 0.0, -0.3, -0.6]) + [0, 1e-3, -1e-3, 0, 0])
    >>> round(trend.start_percent, 2), round(trend.end_percent, 2), trend.p < 1e-4
    (0.6, -0.6, True)
    """
    from scipy import stats

    variable = SWEPT.get(kind)
    if variable is None or variable not in swept:
        return None
    values = swept[variable].to_numpy(float)
    if np.unique(values).size < 4:
        return None
    x = np.log(values) if variable in LOG_SWEPT else values
    fit = stats.linregress(x, residual_percent)
    ends = fit.intercept + fit.slope * np.array([x.min(), x.max()])
    p = float(fit.pvalue) if np.isfinite(fit.pvalue) else (0.0 if fit.slope else 1.0)
    return Trend(variable, float(values.min()), float(values.max()), float(ends[0]), float(ends[1]), p)


def posterior_predictive_checks(result: FitResult, seed: int = 0) -> pd.DataFrame:
    """Per fitted configuration: points, fraction inside the 95 % band, the median discrepancy δ_k [%], the
    posterior predictive p-value of its χ² and its residual trend against the swept variable (module docstring;
    ``trend_*`` columns NaN where there is none)."""
    model = result.model
    draws = predictive_draws(model, _thinned(result.samples), seen=True, seed=seed)
    replicated = draws.mean + draws.sigma * np.random.default_rng(seed + 1).standard_normal(draws.mean.shape)
    observed_chi = ((model.y - draws.mean) / draws.sigma) ** 2 @ model.membership
    replicated_chi = ((replicated - draws.mean) / draws.sigma) ** 2 @ model.membership
    frame = _prediction_frame(model, draws)
    rows = []
    for k in range(model.n_config):
        sel = model.config == k
        first = np.flatnonzero(sel)[0]
        kind = str(model.points.loc[first, "kind"])
        trend = residual_trend(kind, model.points.loc[sel], frame.loc[sel, "residual_percent"].to_numpy(float))
        rows.append(
            {
                "sweep_id": str(model.points.loc[first, "sweep_id"]),
                "points": int(sel.sum()),
                "inside_95": float(frame.loc[sel, "inside_95"].mean()),
                "offset_percent": float(100 * np.median(draws.offsets[:, k])),
                "ppc_p": float((np.sum(replicated_chi[:, k] >= observed_chi[:, k]) + 1) / (draws.theta.shape[0] + 1)),
                "trend_variable": None if trend is None else trend.variable,
                "trend_low": np.nan if trend is None else trend.low,
                "trend_high": np.nan if trend is None else trend.high,
                "trend_start_percent": np.nan if trend is None else trend.start_percent,
                "trend_end_percent": np.nan if trend is None else trend.end_percent,
                "trend_p": np.nan if trend is None else trend.p,
            }
        )
    return pd.DataFrame(rows)


def _prior_columns(
    config: FitConfig,
    names: tuple[str, ...],
    samples: np.ndarray,
    train_names: tuple[str, ...],
    rng: np.random.Generator,
) -> np.ndarray:
    columns = []
    for name in names:
        if name in train_names:
            columns.append(samples[:, train_names.index(name)])
        else:
            columns.append(config.priors[name].sample(rng, (samples.shape[0],)))
    return np.stack(columns, axis=1)


def default_folds(sweeps: list[str], count: int | str = LEAVE_ONE_OUT) -> list[list[str]]:
    """The held-out sets: one per sweep for ``"loo"`` (leave one configuration out: each is predicted from a fit of
    all the others), else `count` folds, the sweeps dealt out in order (every fold trains on the others).

    >>> default_folds(["a", "b", "c"]), default_folds(["a", "b", "c"], 2)
    ([['a'], ['b'], ['c']], [['a', 'c'], ['b']])
    """
    if count == LEAVE_ONE_OUT:
        return [[s] for s in sweeps]
    assert isinstance(count, int)
    return [sweeps[i::count] for i in range(min(count, len(sweeps))) if sweeps[i::count]]


BAND_COLUMNS = {0.05: ("observed_p2_5", "observed_p97_5"), 0.10: ("observed_p5", "observed_p95")}


def band_sharpness(points: pd.DataFrame, alpha: float = 0.05) -> dict[str, float]:
    """How sharp the held-out central (1 − α) bands (α: 0.05 or 0.10, `BAND_COLUMNS`) are beside how well they
    cover: medians over the points of the band's half-width and of the realised error, both in % of the predicted
    median, their ratio, the fraction of points inside (``inside``) and the interval score of the band in %
    (Gneiting & Raftery, JASA 102, 359–378, 2007, eq. 43:
    IS = (u − l) + (2/α)(l − y)·[y < l] + (2/α)(y − u)·[y > u]; smaller is better: a calibrated band of the
    sharpest width minimises it).

    >>> frame = pd.DataFrame({"observed_p2_5": [90.0, 95.0], "observed_p97_5": [110.0, 105.0],
    ...                       "predicted_median": [100.0, 100.0], "measured_dn": [101.0, 106.0]})
    >>> {key: round(value, 3) for key, value in band_sharpness(frame).items() if key != "inside"}
    {'half_width_percent': 7.5, 'error_percent': 3.5, 'width_over_error': 2.143, 'interval_score_percent': 35.0}
    >>> band_sharpness(frame)["inside"]
    0.5
    """
    if not len(points):
        nan = float("nan")
        keys = ("half_width_percent", "error_percent", "width_over_error", "interval_score_percent", "inside")
        return dict.fromkeys(keys, nan)
    lo, hi = (points[c].to_numpy(float) for c in BAND_COLUMNS[alpha])
    y, median = points["measured_dn"].to_numpy(float), points["predicted_median"].to_numpy(float)
    score = (hi - lo) + (2 / alpha) * np.clip(lo - y, 0, None) + (2 / alpha) * np.clip(y - hi, 0, None)
    half = float(np.median(100 * (hi - lo) / 2 / median))
    error = float(np.median(100 * np.abs(y - median) / median))
    return {
        "half_width_percent": half,
        "error_percent": error,
        "width_over_error": half / error if error > 0 else float("inf"),
        "interval_score_percent": float(np.median(100 * score / median)),
        "inside": float(np.mean((y >= lo) & (y <= hi))),
    }


@dataclass
class CrossValidation:
    """Held-out predictions: per configuration (`table`), per point (`points`, with bands) and the folds."""

    table: pd.DataFrame
    points: pd.DataFrame
    folds: list[dict]

    @classmethod
    def of(cls, folds: list[HeldOutFold | None]) -> CrossValidation:
        """The folds' predictions together (None: a fold with nothing to train on or to predict)."""
        done = [f for f in folds if f is not None]
        return cls(
            pd.concat([f.table for f in done], ignore_index=True) if done else pd.DataFrame(),
            pd.concat([f.points for f in done], ignore_index=True) if done else pd.DataFrame(),
            [f.info for f in done],
        )

    @property
    def inside_95(self) -> float:
        return float(self.points["inside_95"].mean()) if len(self.points) else float("nan")

    @property
    def sharpness(self) -> dict[str, float]:
        """`band_sharpness` of the held-out points' 95 % bands (``inside`` is `inside_95`)."""
        return {k: v for k, v in band_sharpness(self.points).items() if k != "inside"}

    @property
    def sharpness_90(self) -> dict[str, float]:
        """`band_sharpness` of the held-out points' 90 % bands."""
        return band_sharpness(self.points, 0.10)


@dataclass
class HeldOutFold:
    """One fold's held-out predictions: per configuration (`table`), per point (`points`) and what it trained on."""

    table: pd.DataFrame
    points: pd.DataFrame
    info: dict


def _for_points(config: FitConfig, points: pd.DataFrame, lone: str | None = None) -> FitConfig:
    """The config without the parameters of what has no points here: the gains K of absent cameras, the
    transmittances of absent lens settings, the bare sensor's factor without bare sensors; and without `lone`, the
    lens group a fold trained on alone (`held_out_fold`)."""
    present = {f"K_dn_per_e:{c}" for c in points["sensor_profile"].astype(str)} | lens_group_parameters(points)
    grouped = lambda n: n == BARE or n.startswith(("K_dn_per_e:", f"{PER_LENS}:"))  # noqa: E731
    priors = {n: p for n, p in config.priors.items() if n != lone and (not grouped(n) or n in present)}
    return config.model_copy(update={"priors": priors})


@one_blas_thread()
def held_out_fold(
    points: pd.DataFrame,
    rigs: dict,
    config: FitConfig,
    fold: list[str],
    number: int,
    kind: str | None = None,
    progress=None,
    seed: int = 0,
) -> HeldOutFold | None:
    """Fit the unsaturated points of every sweep but those of `fold` and predict these as new configurations
    (module docstring); None when either side has no points. `number` tells the fold's draws apart (seed +
    number). On one BLAS thread (`one_blas_thread`): the same numbers here as in a fold's worker."""
    usable = points[~points["saturated"].astype(bool)]
    train = usable[~usable["sweep_id"].isin(fold)]
    test = usable[usable["sweep_id"].isin(fold)]
    if train.empty or test.empty:
        return None
    # A fold that trains on one lens group alone cannot tell the group's factor from the light's efficiency (the
    # data see only their product): the factor stays at its nominal value in the fit and in the predictions of
    # its own group, and the efficiency carries it; another group's factor is drawn from its prior.
    groups = lens_group_parameters(train)
    lone = next(iter(groups)) if len(groups) == 1 else None
    result = fit_points(train, rigs, _for_points(config, train, lone), progress=progress, kind=kind)
    model = build_forward_model(test, rigs, _for_points(config, test, lone).names, kind=kind)
    rng = np.random.default_rng(seed + number)
    theta = _prior_columns(config, model.names, _thinned(result.samples), result.names, rng)
    draws = predictive_draws(model, theta, seen=False, seed=seed + number)
    frame = _prediction_frame(model, draws).assign(fold=number)
    info = {
        "held_out": list(fold),
        "trained_on": sorted(set(train["sweep_id"])),
        "converged": result.converged,
        "config_discrepancy_median": result.median("config_discrepancy"),
    }
    return HeldOutFold(_held_out_table(model, draws, frame, number), frame, info)


def _held_out_table(model: ForwardModel, draws: Draws, frame: pd.DataFrame, fold: int) -> pd.DataFrame:
    """Per held-out configuration: errors, inside-95 fraction and the level check (module docstring)."""
    centre = np.median(draws.model_mean, axis=0)
    rows = []
    for k in range(model.n_config):
        sel = model.config == k
        observed = np.median(model.y[sel] / centre[sel] - 1)
        replicated = np.median(draws.observed[:, sel] / centre[sel] - 1, axis=1)
        tail = min(np.sum(replicated <= observed), np.sum(replicated >= observed))
        rel = (frame.loc[sel, "predicted_median"] - model.y[sel]) / model.y[sel]
        rows.append(
            {
                "sweep_id": str(model.points.loc[np.flatnonzero(sel)[0], "sweep_id"]),
                "fold": fold,
                "role": "held out",
                "points": int(sel.sum()),
                "median_abs_rel_error": float(np.median(np.abs(rel))),
                "max_abs_rel_error": float(np.max(np.abs(rel))),
                "inside_95": float(frame.loc[sel, "inside_95"].mean()),
                "level_offset_percent": float(100 * observed),
                "level_p": float(min(1.0, 2 * (tail + 1) / (replicated.size + 1))),
            }
        )
    return pd.DataFrame(rows)


def predicted_spectra(result: FitResult) -> pd.DataFrame:
    """Model spectra at the target and at the camera, per sweep, with the posterior median parameters and the
    sweep's measured relative light output."""
    model = result.model
    median = dict(zip(result.names, np.median(result.samples, axis=0), strict=True))
    value = lambda name: median.get(name, model.nominal[name])  # noqa: E731
    frames = []
    seen = set()
    for k, design in enumerate(model.designs):
        sweep_id = model.points.loc[np.flatnonzero(model.config == k)[0], "sweep_id"]
        if sweep_id in seen:
            continue
        seen.add(sweep_id)
        changes = {"water.attenuation_scale": value("attenuation_scale"), "target.reflectance": value("reflectance")}
        if "beam_half_angle_deg" in result.names:  # a fitted beam is in water
            changes.update(
                {"light.beam_half_angle_deg": value("beam_half_angle_deg"), "light.beam_half_angle_in_air_deg": None}
            )
        fitted = design.with_values(**changes)
        spectra = stage_spectra(fitted)
        rows = model.points["sweep_id"] == sweep_id
        level = float(model.points.loc[rows, "relative_flux"].median()) if "relative_flux" in model.points else 1.0
        eff = value("light_efficiency") * level
        for position, irradiance in (
            ("target", spectra["facing_light_w_m2_nm"]),
            ("camera", np.pi * spectra["return_radiance_w_m2_sr_nm"]),
        ):
            frames.append(
                pd.DataFrame(
                    {
                        "sweep_id": sweep_id,
                        "position": position,
                        "wavelength_nm": spectra["wavelength_nm"],
                        "predicted_w_m2_nm": eff * irradiance,
                    }
                )
            )
    return pd.concat(frames, ignore_index=True)


def compare_spectra(predicted: pd.DataFrame, measured: pd.DataFrame) -> pd.DataFrame:
    """Per sweep and position: the mean measured spectrum against the prediction (integrated ratio, shape error)."""
    rows: list[dict] = []
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
        rows.append(
            {
                "sweep_id": sweep_id,
                "position": position,
                "measured_over_predicted": float(ratio),
                "shape_rms_error": float(shape),
            }
        )
    return pd.DataFrame(rows)
