"""A calibration's posterior as an `arviz.InferenceData`, written as NetCDF (``posterior.nc``) beside the fit's other
outputs, so that `arviz.summary`, `arviz.plot_trace` and any other Bayesian tool read a `uwlab fit` directory.

Layout (ArviZ's InferenceData schema, https://python.arviz.org/en/stable/schema/schema.html):

- ``posterior``: one variable per fitted parameter (the names of ``summary.json``, e.g. ``light_efficiency``,
  ``K_dn_per_e:imx250m``), dimensions (chain, draw). An emcee ensemble has no independent chains: each *walker* is
  stored as a chain, and the draws are the walker's positions after burn-in and thinning — exactly the samples of
  ``samples.parquet`` (`FitResult.inference_data` builds it). Hence every percentile of the posterior equals the
  fit's own table.
- ``sample_stats``: ``lp``, the log posterior density of each draw.
- attributes: the chain fitted (``model``), ``converged``, ``steps``, ``burn``, ``thin``, ``acceptance``, the
  largest autocorrelation time ``max_autocorrelation_steps`` and ``inference_library = "emcee"``.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import pandas as pd

from uwlab.errors import ConfigError

if TYPE_CHECKING:
    import arviz

    from uwlab.experiments.calibration.fit import FitResult

POSTERIOR_NAME = "posterior.nc"
NETCDF_ENGINE = "h5netcdf"


def write_inference_data(result: FitResult, out: Path) -> Path:
    """Write ``posterior.nc`` into the fit directory `out`; returns its path."""
    path = Path(out) / POSTERIOR_NAME
    result.inference_data().to_netcdf(str(path), engine=NETCDF_ENGINE)
    return path


def read_inference_data(fit_dir: str | Path) -> arviz.InferenceData:
    """The InferenceData of a fit directory: its ``posterior.nc``, or — for a fit written before it existed — its
    ``samples.parquet`` as a single chain."""
    import arviz

    fit_dir = Path(fit_dir)
    path = fit_dir / POSTERIOR_NAME
    if path.is_file():
        stored: arviz.InferenceData = arviz.from_netcdf(str(path), engine=NETCDF_ENGINE)
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
