"""A calibration's posterior as an `arviz.InferenceData`, written as NetCDF (``posterior.nc``) beside the fit's other
outputs, so that `arviz.summary`, `arviz.plot_trace` and any other Bayesian tool read a `uwlab fit` directory.

Layout (ArviZ's InferenceData schema, https://python.arviz.org/en/stable/schema/schema.html):

- ``posterior``: one variable per fitted parameter (the names of ``summary.json``, e.g. ``light_efficiency``,
  ``K_dn_per_e:imx250m``), dimensions (chain, draw). An emcee ensemble has no independent chains: each *walker* is
  stored as a chain, and the draws are the walker's positions after burn-in and thinning — exactly the samples of
  ``samples.parquet`` (`uwlab.experiments.calibration.fit.run_fit` flattens them step-major, so sample
  ``i = draw · walkers + walker``). Hence every percentile of the posterior equals the fit's own table.
- ``sample_stats``: ``lp``, the log posterior density of each draw.
- attributes: the chain fitted (``model``), ``converged``, ``steps``, the largest autocorrelation time ``tau_max``
  and ``inference_library = "emcee"``.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from uwlab.errors import ConfigError

if TYPE_CHECKING:
    import arviz

    from uwlab.experiments.calibration.fit import FitResult

POSTERIOR_NAME = "posterior.nc"
NETCDF_ENGINE = "h5netcdf"


def by_walker(flat: np.ndarray, walkers: int) -> np.ndarray:
    """Step-major flat samples (n·walkers, ...) → (walkers, n, ...), the (chain, draw) order of ArviZ.

    >>> by_walker(np.arange(6), 2).tolist()
    [[0, 2, 4], [1, 3, 5]]
    """
    if flat.shape[0] % walkers:
        raise ValueError(f"{flat.shape[0]} samples are not a whole number of steps of {walkers} walkers")
    return np.swapaxes(flat.reshape((-1, walkers) + flat.shape[1:]), 0, 1)


def inference_data(result: FitResult) -> arviz.InferenceData:
    """The posterior of a fit as InferenceData (module docstring)."""
    import arviz

    walkers = int(result.chain.shape[1])
    chains = by_walker(result.samples, walkers)
    posterior = {name: chains[:, :, i] for i, name in enumerate(result.names)}
    attrs = {
        "model": result.model.kind,
        "converged": int(result.converged),
        "steps": int(result.steps),
        "tau_max": float(np.max(result.tau)),
        "inference_library": "emcee",
    }
    data: arviz.InferenceData = arviz.from_dict(
        posterior=posterior, sample_stats={"lp": by_walker(result.log_prob, walkers)}
    )
    data["posterior"].attrs.update(attrs)
    return data


def write_inference_data(result: FitResult, out: Path) -> Path:
    """Write ``posterior.nc`` into the fit directory `out`; returns its path."""
    path = Path(out) / POSTERIOR_NAME
    inference_data(result).to_netcdf(str(path), engine=NETCDF_ENGINE)
    return path


def read_inference_data(fit_dir: str | Path) -> arviz.InferenceData:
    """The InferenceData of a fit directory: its ``posterior.nc``, or — for a fit written before it existed — its
    ``samples.parquet`` as a single chain."""
    import arviz

    fit_dir = Path(fit_dir)
    path = fit_dir / POSTERIOR_NAME
    if path.is_file():
        stored: arviz.InferenceData = arviz.from_netcdf(  # type: ignore[no-untyped-call]
            str(path), engine=NETCDF_ENGINE
        )
        return stored
    samples = fit_dir / "samples.parquet"
    if not samples.is_file():
        raise ConfigError(
            "fit",
            str(fit_dir),
            f"neither {POSTERIOR_NAME} nor samples.parquet here (not a `uwlab fit` output directory)",
        )
    frame = pd.read_parquet(samples)
    single: arviz.InferenceData = arviz.from_dict(
        posterior={name: frame[name].to_numpy()[None, :] for name in frame.columns}
    )
    return single
