"""Calibrating the model against a dataset: fit, validate, judge, write — what `uwlab fit` and `uwlab demo` run.

Outputs in the calibration directory: those of `uwlab.experiments.calibration.output`, plus ``cross.json`` (the held-out
table), ``heldout.parquet`` (held-out predictions with their bands), ``spectra.parquet`` (predicted and measured
spectra) and ``posterior.nc`` (the posterior as ArviZ InferenceData, `uwlab.experiments.calibration.inference`).
``summary.json`` also records which dataset (path, plan hash), the world that rendered a simulated dataset (``world``),
the chain fitted (``model``: paper or extended), the held-out folds and table, the posterior predictive checks per
configuration, ``predictive_coverage`` (the fraction of all held-out points inside their 95 % bands and per
configuration, and the bands' sharpness: median half-width, median realised error, their ratio and the interval
score, `uwlab.experiments.calibration.validation.band_sharpness`), the verdict ``model_adequate`` with its named
``checks`` and, when the model fails, the failing checks and likely causes in ``warnings``
(`uwlab.experiments.calibration.adequacy`), the spectra comparison and, per parameter, the simulated ground truth.
The held-out folds (by default one per configuration) run beside the whole-data fit, in worker processes or on a
Dask cluster (`uwlab.experiments.calibration.parallel`), and so does the writing of what needs the whole-data fit
alone (`uwlab.experiments.calibration.output.write_posterior`); a calibration that fails part-way removes what it
wrote.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from uwlab.errors import ConfigError
from uwlab.experiments.calibration.adequacy import Verdict, verdict
from uwlab.experiments.calibration.fit import (
    FitConfig,
    FitResult,
    Folds,
    Holdout,
    default_config_for,
    fit_points,
    load_fit_config,
)
from uwlab.experiments.calibration.forward import (
    MODELS,
    build_forward_model,
    characterised_sensor,
    relative_flux,
    reused_configurations,
)
from uwlab.experiments.calibration.output import (
    PosteriorOutputs,
    check_output_dir,
    remove_outputs,
    write_fit,
    write_posterior,
)
from uwlab.experiments.calibration.parallel import FoldJob, folds_in_background
from uwlab.experiments.calibration.validation import (
    CrossValidation,
    compare_spectra,
    default_folds,
    posterior_predictive_checks,
    predicted_spectra,
)
from uwlab.experiments.dataset import Dataset, channel_view
from uwlab.model.schema import check, parse
from uwlab.outputs import FIT_FOLDER


def truth_from_metadata(metadata: dict, points: pd.DataFrame, names) -> dict:
    """Ground truth of the simulated rig for each fitted parameter (None where the simulation has none)."""
    sim_truth = metadata.get("sim_truth") or {}
    if not sim_truth:
        return {}
    truth = {}
    for name in names:
        if name.startswith("K_dn_per_e:"):
            profile = name.split(":", 1)[1]
            sweeps = points.loc[points["sensor_profile"] == profile, "sweep_id"].unique()
            values = [sim_truth[s]["K_dn_per_e"] for s in sweeps if s in sim_truth]
            truth[name] = values[0] if values else None
        else:
            values = [t.get(name) for t in sim_truth.values() if t.get(name) is not None]
            truth[name] = values[0] if values else None
    return truth


def resolve_fit_config(
    config_path: str | Path | None, points: pd.DataFrame, rigs: dict, sampler: dict | None = None
) -> FitConfig:
    """The fit config file at `config_path`, else the default for these points; `sampler` overrides keys of its
    [sampler] section (``walkers``, ``chunk_steps``, ``max_steps``, ``seed``), validated like the file's."""
    config = (
        load_fit_config(config_path)
        if config_path is not None
        else default_config_for(points[~points["saturated"].astype(bool)], rigs)
    )
    if not sampler:
        return config
    return parse(
        FitConfig,
        {"parameters": config.priors, "holdout": config.holdout, "sampler": {**config.sampler.model_dump(), **sampler}},
    )


def world_of(metadata: dict) -> str | None:
    """The world preset that rendered a simulated dataset (None for a tank's data or an older dataset)."""
    worlds = {t["world"]["preset"] for t in (metadata.get("sim_truth") or {}).values() if t.get("world")}
    if len(worlds) == 1:
        return worlds.pop()
    return None


def held_out_folds(sweeps: list[str], config: FitConfig, train_sweeps: list[str] | None) -> list[list[str]]:
    """The held-out sweeps of each fold: everything but `train_sweeps` (or the config's [holdout] train), else
    the config's `[holdout] folds`: one per sweep ("loo", the default) or that many dealt out in sweep order."""
    train = train_sweeps or config.holdout.train
    if train:
        unknown = sorted(set(train) - set(sweeps))
        if unknown:
            raise ConfigError(
                "--train" if train_sweeps else "holdout.train",
                ", ".join(unknown),
                f"not a sweep of this dataset ({', '.join(sweeps)})",
            )
        return [[s for s in sweeps if s not in train]]
    return default_folds(sweeps, config.holdout.folds)


@dataclass
class Calibration:
    summary: dict
    cross: pd.DataFrame
    spectra: pd.DataFrame
    out: Path


@dataclass
class Assessment:
    """A fit with its checks: the result, the per-configuration checks, the held-out predictions, the verdict."""

    result: FitResult
    ppc: pd.DataFrame
    cross: CrossValidation
    verdict: Verdict

    def summary(self) -> dict:
        """The assessment's part of summary.json (module docstring)."""
        table = self.cross.table
        per_config = dict(zip(table["sweep_id"], table["inside_95"], strict=True)) if len(table) else {}
        return {
            "model": self.result.model.kind,
            "predictive_coverage": {
                "held_out_inside_95": self.cross.inside_95,
                "per_configuration": per_config,
                **{f"held_out_{key}": value for key, value in self.cross.sharpness.items()},
                "held_out_90": self.cross.sharpness_90,
            },
            **self.verdict.to_dict(),
            "warnings": self.result.summary()["warnings"] + self.verdict.warnings(),
            "cross_configuration": self.cross.table.to_dict(orient="records"),
            "folds": self.cross.folds,
            "posterior_predictive_checks": self.ppc.to_dict(orient="records"),
        }


def assess(
    points: pd.DataFrame,
    rigs: dict,
    config: FitConfig,
    folds: list[list[str]],
    model: str | None = None,
    progress=None,
    workers: int | None = None,
    dask: str | None = None,
    meanwhile: Callable[[FitResult], object] | None = None,
) -> Assessment:
    """Fit the points with the chain `model`, check every configuration, predict each held-out fold from a fit of
    the others, and judge the model (`uwlab.experiments.calibration.adequacy`). The folds run meanwhile on
    `workers` processes (None: one per core) or on the Dask cluster at `dask`
    (`uwlab.experiments.calibration.parallel`), and so does `meanwhile` (given the whole-data fit) once the fit is
    done. Each configuration's chain is evaluated once, here, for the fit and the folds (`reused_configurations`)."""
    numbered = tuple((i, tuple(f)) for i, f in enumerate(folds))
    with reused_configurations() as configurations:
        unsaturated = points[~points["saturated"].astype(bool)]
        if not unsaturated.empty:  # (fit_points refuses an empty table)
            build_forward_model(unsaturated, rigs, config.names, kind=model)
        job = FoldJob(points, rigs, config, model, config.sampler.seed, numbered, configurations)
        with folds_in_background(job, workers, dask) as held_out:
            result = fit_points(points, rigs, config, progress=progress, kind=model)
            # what needs the whole-data fit alone is done while the folds still run: the checks and the MAP search
            ppc = posterior_predictive_checks(result)
            result.theta_map  # noqa: B018 (computed now, kept for the summary)
            if meanwhile is not None:
                meanwhile(result)
            cross = CrossValidation.of(held_out())
    return Assessment(result, ppc, cross, verdict(result, ppc, cross))


def with_characterised_sensors(rigs: dict, points: pd.DataFrame, sensors: list[str]) -> dict:
    """The rigs with ``sensor.characterised`` set from ``--sensor`` values ``CAMERA=FROM`` (CAMERA a sensor profile
    of the dataset, FROM a `uwlab emva characterize` profile TOML or output folder; a bare FROM when the dataset
    has one camera); each FROM is loaded now (`characterised_sensor`), so a bad one is refused before sampling."""
    cameras = sorted(points["sensor_profile"].astype(str).unique())
    chosen: dict[str, str] = {}
    for value in sensors:
        camera, _, source = value.rpartition("=")
        if not camera:
            if len(cameras) != 1:
                raise ConfigError("--sensor", value, f"name the camera: CAMERA=FROM with CAMERA one of {cameras}")
            camera = cameras[0]
        if camera not in cameras:
            raise ConfigError("--sensor", value, f"no camera {camera!r} in this dataset; it has {cameras}")
        characterised_sensor(source)
        chosen[camera] = str(Path(source).resolve())
    if not chosen:
        return rigs
    out = {}
    for sweep_id, rig in rigs.items():
        rows = points.loc[points["sweep_id"] == sweep_id, "sensor_profile"]
        characterised = chosen.get(str(rows.iloc[0])) if len(rows) else None
        if characterised is not None:
            rig = {**rig, "sensor": {**rig.get("sensor", {}), "characterised": characterised}}
        out[sweep_id] = rig
    return out


def sensor_descriptions(rigs: dict, points: pd.DataFrame) -> dict[str, str]:
    """Per camera, the sensor description its configurations used: the profile alone (linear response) or the
    characterisation whose response curve the fit applied."""
    out = {}
    for sweep_id, rig in rigs.items():
        rows = points.loc[points["sweep_id"] == sweep_id, "sensor_profile"]
        if len(rows):
            source = rig.get("sensor", {}).get("characterised")
            out[str(rows.iloc[0])] = (
                f"characterised: {source} (measured response curve)" if source else "profile (linear response)"
            )
    return out


def calibrate(
    dataset_dir: str | Path,
    config_path: str | Path | None,
    out: str | Path | None,
    train_sweeps: list[str] | None = None,
    progress=None,
    model: str | None = None,
    sampler: dict | None = None,
    sensors: list[str] | None = None,
    channel: str | None = None,
    held_out: int | str | None = None,
    dask: str | None = None,
) -> Calibration:
    """Fit the whole dataset with the chain `model` ("paper", "extended"; None: the rigs' [model] kind), check it
    per configuration, predict every configuration from a fit that did not see it (`held_out_folds`), judge the
    model (`uwlab.experiments.calibration.adequacy`), compare the spectra; write everything to `out`. `sampler`
    overrides the fit config's [sampler] keys (`resolve_fit_config`); `sensors` (``uwlab fit --sensor``) name
    cameras characterised by ``uwlab emva characterize`` (`with_characterised_sensors`); `channel` ("red",
    "green", "blue"; ``uwlab fit --channel``) fits that colour channel of Bayer points, predicted with its own QE
    (`uwlab.experiments.dataset.channel_view`), instead of the whole mosaic against the combined QE. `held_out`
    (``uwlab fit --held-out``: "loo" or a number of folds) replaces the config's ``[holdout] folds``; the folds run
    on this machine's cores or on the Dask cluster at `dask` (``uwlab fit --dask``: ``local`` or
    ``tcp://HOST:PORT``), beside the whole-data fit. Every input is checked before sampling starts. The defaults of
    `uwlab fit` and `uwlab.fit` are these: `out` None is ``DATASET/fit``, `config_path` None the default fit config
    for the dataset's cameras, `model` None the rigs' [model] kind, no `sensors` the profiles, `channel` None the
    whole mosaic, `held_out` None the config's folds, `dask` None this machine's cores."""
    if model is not None and model not in MODELS:
        raise ConfigError("--model", model, f"must be one of {', '.join(MODELS)}")
    dataset = Dataset.open(dataset_dir)
    out = Path(dataset_dir) / FIT_FOLDER if out is None else Path(out)
    check_output_dir(out)
    points, metadata = dataset.points(), dataset.metadata
    # Geometry sweeps (a slanted-edge chart in the window, focus and distance stepped) validate the MTF, not the
    # radiometry: their points are left to the report's geometry section.
    points = points[points["kind"].astype(str) != "geometry"].reset_index(drop=True)
    if points.empty:
        raise ConfigError(
            "dataset",
            str(dataset_dir),
            "has no points to fit outside geometry sweeps; run (or --resume) its sweep first",
        )
    points = points.assign(relative_flux=relative_flux(points))
    if channel is not None:
        try:
            points = channel_view(points, channel)
        except ConfigError as exc:
            raise ConfigError("--channel", exc.value, exc.reason) from None
    rigs = with_characterised_sensors(metadata.get("rigs") or {}, points, sensors or [])
    config = resolve_fit_config(config_path, points, rigs, sampler)
    if held_out is not None:
        config = config.model_copy(update={"holdout": Holdout(folds=check(Folds, held_out, "--held-out"))})
    sweeps = list(dict.fromkeys(points.loc[~points["saturated"].astype(bool), "sweep_id"]))
    folds = held_out_folds(sweeps, config, train_sweeps)
    early: list[tuple[PosteriorOutputs, dict]] = []

    def write_early(result: FitResult) -> None:  # the whole-data outputs, on the core the folds leave
        truth = truth_from_metadata(metadata, points, result.names)
        early.append((write_posterior(result, out, truth), truth))

    try:
        assessment = assess(points, rigs, config, folds, model, progress, dask=dask, meanwhile=write_early)
        result, cross = assessment.result, assessment.cross
        predicted = predicted_spectra(result)
        measured = dataset.spectra()
        spectra_table = compare_spectra(predicted, measured)
        extra = {
            "dataset": str(Path(dataset_dir).resolve()),
            "plan_sha256": metadata.get("plan_sha256"),
            "world": world_of(metadata),
            "sensors": sensor_descriptions(rigs, points),
            "channel": channel or "combined",
            **assessment.summary(),
            "spectra": spectra_table.to_dict(orient="records"),
            "sim": bool(metadata.get("sim")),
        }
        posterior, truth = early[0]
        summary = write_fit(result, out, truth, extra, cross.points, posterior)
        merged = (
            predicted.merge(
                measured.groupby(["sweep_id", "position", "wavelength_nm"], as_index=False)[
                    "irradiance_w_m2_nm"
                ].mean(),
                how="left",
                on=["sweep_id", "position", "wavelength_nm"],
            )
            if not measured.empty
            else predicted.assign(irradiance_w_m2_nm=np.nan)
        )
        merged.to_parquet(out / "spectra.parquet", index=False)
        (out / "cross.json").write_text(json.dumps(cross.table.to_dict(orient="records"), indent=2) + "\n")
    except BaseException:
        remove_outputs(out)  # a calibration that fails part-way leaves its folder as it found it, free of outputs
        raise
    return Calibration(summary, cross.table, spectra_table, out)
