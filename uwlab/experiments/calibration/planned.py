"""The response a sweep plan's points are predicted to read before they are measured, with a band: the rig
console's predicted band (docs/console.md).

The prediction is the calibration's forward model (`uwlab.experiments.calibration.forward.build_forward_model`: the
dark-subtracted mean response ``signal_dn`` over the ROI, the quantity ``uwlab sweep`` records and ``uwlab fit``
fits) at the plan's settings, over parameter draws:

- **design**: θ drawn from the priors ``uwlab fit`` starts from (`uwlab.experiments.calibration.fit.
  default_config_for`: light efficiency, attenuation scale, each camera's K, the discrepancies), i.e. what the rig's
  design and its stated uncertainties predict before any calibration;
- **fit**: θ from the posterior samples of a ``uwlab fit`` directory (``samples.parquet``), its chain (paper or
  extended, ``summary.json``'s ``model``). Every configuration of the plan (camera, focal length, f-number) must be
  one of the fit's.

Each point of a new run is predicted as the report's held-out configurations are
(`uwlab.experiments.calibration.validation.predictive_draws` with ``seen`` False): a configuration's discrepancy
δ ~ N(0, τ²) drawn per sample, and a new measurement with the within-configuration discrepancy. The band is the
2.5–97.5th percentiles of those draws, the line their median, both held at the camera's clip level less its offset
(`uwlab.experiments.saturation`, from the sensor profile: K μ_e,sat at the gain, at most the ADC maximum; no
dark-subtracted reading exceeds it, where the model stays linear). The ROI mean's own measurement noise is left
out (the plan does not know it; over a window of hundreds of pixels it is far below the band's width).

Only exposure sweeps of a tank rig are predicted (the console draws response against exposure), along
`DENSE_POINTS` log-spaced exposures over the sweep's range, each at the sweep's other settings (gain, lens), with the
light at full output. The light's level-to-output curve is no part of the model (the fit takes each point's output
from the spectrometer's readings, `uwlab.experiments.calibration.forward.relative_flux`; the simulated light's is
level^2.2): a sweep at a dimmed level is predicted only from a fit whose dataset (``summary.json``'s ``dataset``,
still on disk) has that sweep at that level, with the output measured there (`fitted_flux`). The ROI is the sweep's
``roi`` rectangle, else the camera's window, else the whole sensor (an ``aruco`` ROI, found on the board at run time,
is taken as the window: the model's ROI is axis-centred in any case). Other sweeps (dark, gain, aperture,
light-level, geometry, an EMVA bench's) are listed with the reason they are not predicted.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.plan import Plan, SweepSpec, resolved_rig
from uwlab.experiments.calibration.fit import default_config_for
from uwlab.experiments.calibration.forward import (
    PER_CAMERA,
    SHARED,
    build_forward_model,
    lens_group_parameters,
    relative_flux,
)
from uwlab.experiments.calibration.validation import predictive_draws
from uwlab.experiments.dataset import Dataset
from uwlab.experiments.saturation import sensor_clip_dn
from uwlab.model.bench import Bench
from uwlab.model.data import MAX_BINARY_BYTES, check_input_file, read_json
from uwlab.drivers.camera.pixels import pixel_format

DENSE_POINTS = 40
MAX_SAMPLES = 1000
BAND_PERCENTILES = (2.5, 50.0, 97.5)
CONFIGURATION = ("sensor_profile", "focal_length_mm", "f_number")


def _roi_size(sweep: SweepSpec) -> tuple[int, int]:
    roi = sweep.table.roi
    if isinstance(roi, list | tuple):
        return int(roi[2]), int(roi[3])
    if sweep.camera.window is not None:
        return int(sweep.camera.window[2]), int(sweep.camera.window[3])
    width, height = sweep.design.sensor.resolution_px
    return int(width), int(height)


def _clip_signal_dn(sweep: SweepSpec, gain_db: float, bits: int) -> float:
    """The largest dark-subtracted signal the sweep's camera reads [DN]: its clip level from the sensor profile
    (`uwlab.experiments.saturation.sensor_clip_dn`: K μ_e,sat + offset at the gain, capped at the ADC maximum, in
    the output format) less the offset."""
    sensor = sweep.design.sensor
    offset = sensor.dark_offset_dn + (sweep.table.black_level_dn or 0.0)
    name = sweep.camera.pixel_format or f"Mono{sensor.bit_depth}"
    clip = sensor_clip_dn(float(sensor.gain_k(gain_db)), sensor.saturation_e, offset, sensor.bit_depth, name)
    return clip - offset * 2.0 ** (bits - sensor.bit_depth)


def planned_points(
    plan: Plan, flux: dict[tuple[str, float], float] | None = None, dense: int = DENSE_POINTS
) -> tuple[pd.DataFrame, dict[str, dict], dict[str, str]]:
    """The predicted sweeps' points as the forward model's contract columns (``signal_dn`` 0: not measured; and
    ``clip_signal_dn``), the rigs by sweep id (as ``uwlab sweep`` records them in metadata.json) and the sweeps left
    out with the reason.
    ``flux``: the light's measured relative output by (sweep id, light level) (`fitted_flux`), which lets a sweep at
    a dimmed level be predicted."""
    flux = flux or {}
    rows: list[dict[str, Any]] = []
    rigs: dict[str, dict] = {}
    skipped: dict[str, str] = {}
    for sweep in plan.sweeps:
        table = sweep.table
        if isinstance(sweep.design, Bench):
            skipped[table.id] = "an EMVA 1288 bench: no tank model"
            continue
        if table.kind != "exposure":
            skipped[table.id] = f"a {table.kind} sweep: the band is drawn against exposure"
            continue
        output = 1.0 if table.light_level == 1.0 else flux.get((table.id, table.light_level))
        if output is None:
            skipped[table.id] = (
                f"light level {table.light_level:g}: the light's level-to-output curve is not modelled (a fit "
                "of this sweep at this level brings its measured output)"
            )
            continue
        exposures = np.geomspace(min(sweep.values), max(sweep.values), dense if len(sweep.values) > 1 else 1)
        roi_w, roi_h = _roi_size(sweep)
        bits = (
            pixel_format(sweep.camera.pixel_format).bits
            if sweep.camera.pixel_format is not None
            else sweep.design.sensor.bit_depth
        )
        for point in replace(sweep, values=tuple(float(e) for e in exposures)).points():
            rows.append(
                {
                    "sweep_id": table.id,
                    "point_index": point.index,
                    "exposure_us": point.exposure_us,
                    "gain_db": point.gain_db,
                    "f_number": np.nan if point.f_number is None else float(point.f_number),
                    "focal_length_mm": np.nan
                    if sweep.lens.focal_length_mm is None
                    else float(sweep.lens.focal_length_mm),
                    "bit_depth": bits,
                    "sensor_profile": sweep.sensor_profile,
                    "signal_dn": 0.0,
                    "temporal_var_dn2": 0.0,
                    "frames": table.frames_per_point,
                    "roi_w": roi_w,
                    "roi_h": roi_h,
                    "saturated": False,
                    "relative_flux": output,
                    "clip_signal_dn": _clip_signal_dn(sweep, point.gain_db, bits),
                }
            )
        rigs[table.id] = resolved_rig(sweep.design)
    return pd.DataFrame(rows), rigs, skipped


def fitted_flux(fit_dir: Path) -> dict[tuple[str, float], float]:
    """The light's relative output by (sweep id, light level) in the dataset a fit was made from (``summary.json``'s
    ``dataset``; `uwlab.experiments.calibration.forward.relative_flux`, each sweep's median), {} when that dataset
    is gone."""
    dataset = read_json(fit_dir / "summary.json", "fit").get("dataset")
    if not dataset or not Path(dataset).is_dir():
        return {}
    points = Dataset.open(dataset).points()
    points = points[points["kind"].astype(str) == "exposure"].reset_index(drop=True)
    if points.empty or "light_level" not in points:
        return {}
    levels = points["light_level"].astype(float).fillna(1.0)
    frame = pd.DataFrame({"sweep": points["sweep_id"], "level": levels, "flux": relative_flux(points)})
    return {(str(k[0]), float(k[1])): float(v) for k, v in frame.groupby(["sweep", "level"])["flux"].median().items()}


def _prior_draws(points: pd.DataFrame, rigs: dict, samples: int, rng: np.random.Generator):
    config = default_config_for(points, rigs)
    theta = np.column_stack([config.priors[name].sample(rng, samples) for name in config.names])
    return config.names, theta


def _posterior_draws(fit_dir: Path, points: pd.DataFrame, samples: int):
    """The fit's posterior samples (thinned to ``samples``) for the parameters these points have, and its chain;
    `ConfigError` unless every configuration of the points is one of the fit's."""
    summary = read_json(fit_dir / "summary.json", "fit")
    table = lambda name: pd.read_parquet(check_input_file(fit_dir / name, "fit", MAX_BINARY_BYTES, "Parquet"))  # noqa: E731
    fitted = table("predictions.parquet")
    fitted = fitted[~fitted["saturated"].astype(bool)] if "saturated" in fitted else fitted
    known = {_configuration(row) for row in fitted[list(CONFIGURATION)].itertuples(index=False)}
    for sweep_id, rows in points.groupby("sweep_id", sort=False):
        for row in rows[list(CONFIGURATION)].drop_duplicates().itertuples(index=False):
            if _configuration(row) not in known:
                label = "{} {} mm f/{}".format(*_configuration(row))
                raise ConfigError(
                    "fit", str(fit_dir), f"has no configuration {label} (sweep {sweep_id}): it did not fit this plan's"
                )
    frame = table("samples.parquet")
    cameras = set(points["sensor_profile"].astype(str))
    allowed = set(SHARED) | {f"{p}:{c}" for p in PER_CAMERA for c in cameras} | lens_group_parameters(points)
    names = tuple(name for name in frame.columns if name in allowed)
    step = max(1, len(frame) // samples)
    return names, frame[list(names)].to_numpy(float)[::step], summary.get("model")


def _configuration(row) -> tuple[str, float | None, float | None]:
    profile, focal, f_number = row
    number = lambda v: None if v is None or not np.isfinite(v) else round(float(v), 6)  # noqa: E731
    return str(profile), number(focal), number(f_number)


def predicted_bands(plan: Plan, fit: str | Path | None = None, samples: int = MAX_SAMPLES, seed: int = 0) -> dict:
    """Per predicted sweep of ``plan``: ``exposure_us``, the ``median`` response and the band ``lo``–``hi``
    (2.5–97.5 %) [DN], from the design's priors or the posterior of the fit directory ``fit`` (module
    docstring); ``source`` ("design" or "fit: DIR"), ``skipped`` sweeps with their reason."""
    if fit is not None and not Path(fit).is_dir():
        raise ConfigError("fit", str(fit), "not a directory (give a `uwlab fit` output directory)")
    points, rigs, skipped = planned_points(plan, None if fit is None else fitted_flux(Path(fit)))
    source = "design" if fit is None else f"fit: {fit}"
    if points.empty:
        if fit is not None:
            reasons = "; ".join(f"{sweep_id}: {why}" for sweep_id, why in skipped.items())
            raise ConfigError("fit", str(fit), f"nothing in the plan to predict ({reasons})")
        return {"source": source, "band_percent": [2.5, 97.5], "configurations": [], "skipped": skipped}
    rng = np.random.default_rng(seed)
    if fit is None:
        names, theta = _prior_draws(points, rigs, samples, rng)
        kind = None
    else:
        names, theta, kind = _posterior_draws(Path(fit), points, samples)
    model = build_forward_model(points, rigs, names, kind=kind)
    draws = predictive_draws(model, theta, seen=False, seed=seed)
    top = points["clip_signal_dn"].to_numpy(float)
    lo, median, hi = np.minimum(np.percentile(draws.observed, BAND_PERCENTILES, axis=0), top)
    configurations = []
    for sweep_id, rows in points.groupby("sweep_id", sort=False):
        index = rows.index.to_numpy()
        configurations.append(
            {
                "sweep_id": sweep_id,
                "sensor_profile": str(rows["sensor_profile"].iloc[0]),
                "exposure_us": rows["exposure_us"].tolist(),
                "median": median[index].tolist(),
                "lo": lo[index].tolist(),
                "hi": hi[index].tolist(),
                "clip_signal_dn": float(top[index[0]]),
            }
        )
    return {
        "source": source,
        "model": model.kind,
        "samples": int(theta.shape[0]),
        "band_percent": [BAND_PERCENTILES[0], BAND_PERCENTILES[-1]],
        "configurations": configurations,
        "skipped": skipped,
    }
