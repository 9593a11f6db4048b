"""Calibrating the model against a dataset: fit, validate, write — what `uwlab fit` and `uwlab demo` run.

Outputs in the calibration directory: those of `uwlab.experiments.calibration.output`, plus ``cross.json`` (the
cross-configuration table) and ``spectra.parquet`` (predicted and measured spectra). ``summary.json`` also
records which dataset (path, plan hash), the training sweeps, the cross-configuration table, the spectra
comparison and, per parameter, the simulated ground truth when the dataset comes from the simulated rig.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from uwlab.errors import ConfigError
from uwlab.experiments.dataset import Dataset
from uwlab.experiments.calibration.fit import FitConfig, default_config_for, fit_points, load_fit_config
from uwlab.experiments.calibration.output import check_output_dir, write_fit
from uwlab.experiments.calibration.forward import relative_flux
from uwlab.experiments.calibration.validation import compare_spectra, cross_configuration, predicted_spectra


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


def resolve_fit_config(config_path: str | Path | None, points: pd.DataFrame, rigs: dict) -> FitConfig:
    if config_path is not None:
        return load_fit_config(config_path)
    return default_config_for(points[~points["saturated"].astype(bool)], rigs)


def training_sweeps(points: pd.DataFrame, requested: list[str] | None, config: FitConfig) -> list[str]:
    """The sweeps the cross-configuration check trains on: `requested` (``--train``), or the config's
    ``[holdout] train``, or the first sweep with a lens; each must be a sweep of the dataset."""
    sweeps = list(dict.fromkeys(points["sweep_id"]))
    with_lens = list(dict.fromkeys(points.loc[points["f_number"].notna(), "sweep_id"]))
    train = requested or config.holdout.train or (with_lens or sweeps)[:1]
    unknown = sorted(set(train) - set(sweeps))
    if unknown:
        raise ConfigError("--train" if requested else "holdout.train", ", ".join(unknown),
                          f"not a sweep of this dataset ({', '.join(sweeps)})")
    return train


@dataclass
class Calibration:
    summary: dict
    cross: pd.DataFrame
    spectra: pd.DataFrame
    out: Path


def calibrate(dataset_dir: str | Path, config_path: str | Path | None, out: str | Path, train_sweeps: list[str] | None = None,
              progress=None) -> Calibration:
    """Fit the whole dataset, then the cross-configuration check (training sweeps: `train_sweeps`, or the
    config's [holdout] train, or the first sweep with a lens), then the spectra; write everything to `out`.
    Every input is checked before sampling starts."""
    dataset = Dataset.open(dataset_dir)
    out = Path(out)
    check_output_dir(out)
    points, metadata = dataset.points(), dataset.metadata
    if points.empty:
        raise ConfigError("dataset", str(dataset_dir), "has no points to fit; run (or --resume) its sweep first")
    points = points.assign(relative_flux=relative_flux(points))
    rigs = metadata.get("rigs") or {}
    config = resolve_fit_config(config_path, points, rigs)
    train = training_sweeps(points, train_sweeps, config)
    result = fit_points(points, rigs, config, progress=progress)
    truth = truth_from_metadata(metadata, points, result.names)
    cross, _ = cross_configuration(points, rigs, config, train, progress=progress)
    predicted = predicted_spectra(result)
    measured = dataset.spectra()
    spectra_table = compare_spectra(predicted, measured)
    extra = {"dataset": str(Path(dataset_dir).resolve()), "plan_sha256": metadata.get("plan_sha256"),
             "cross_configuration": cross.to_dict(orient="records"), "training_sweeps": train,
             "spectra": spectra_table.to_dict(orient="records"), "sim": bool(metadata.get("sim"))}
    summary = write_fit(result, out, truth, extra)
    merged = predicted.merge(measured.groupby(["sweep_id", "position", "wavelength_nm"], as_index=False)[
        "irradiance_w_m2_nm"].mean(), how="left", on=["sweep_id", "position", "wavelength_nm"]) if not measured.empty \
        else predicted.assign(irradiance_w_m2_nm=np.nan)
    merged.to_parquet(out / "spectra.parquet", index=False)
    (out / "cross.json").write_text(json.dumps(cross.to_dict(orient="records"), indent=2) + "\n")
    return Calibration(summary, cross, spectra_table, out)
