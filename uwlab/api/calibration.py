"""Calibration from Python: `fit`, its `Fit` (posterior as ArviZ InferenceData, verdict, predictions for a design)
and `report` — ``uwlab fit`` and ``uwlab report``.

A fit directory holds, beside the outputs of ``uwlab fit``, ``posterior.nc``: the posterior as InferenceData
(`uwlab.experiments.calibration.inference`), so ``arviz.summary(arviz.from_netcdf(".../fit/posterior.nc"))`` and
``arviz.plot_trace`` work on it directly.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import arviz
    import pandas as pd

    from uwlab.api.campaign import Dataset
    from uwlab.experiments.figures import Figure
    from uwlab.model.design import Design


# `fit`'s sensor=: {camera: FROM}, the ``[CAMERA=]FROM`` values of ``uwlab fit --sensor``, or one FROM.
Sensors = Mapping[str, str | os.PathLike[str]] | Sequence[str | os.PathLike[str]] | str | os.PathLike[str]


@dataclass(frozen=True)
class Verdict:
    """Whether the model is adequate for these data (`uwlab.experiments.calibration.adequacy`): the named `checks`
    (each ``{"name", "passed", "detail"}``) and the `warnings` (when it is not adequate: the failing checks and
    likely causes). True when adequate.

    >>> from uwlab.api.calibration import Verdict
    >>> verdict = Verdict(False, "paper", ({"name": "held-out levels", "passed": False, "detail": "2 of 6 outside"},),
    ...                   ())
    >>> bool(verdict), verdict.failed
    (False, ['held-out levels'])
    >>> print(verdict)
    paper model: NOT adequate
    failed: held-out levels (2 of 6 outside)
    """

    adequate: bool
    model: str
    checks: tuple[dict[str, Any], ...]
    warnings: tuple[str, ...]

    def __bool__(self) -> bool:
        return self.adequate

    @property
    def failed(self) -> list[str]:
        """The names of the checks that failed."""
        return [str(c["name"]) for c in self.checks if not c.get("passed")]

    def __str__(self) -> str:
        head = f"{self.model} model: {'adequate' if self.adequate else 'NOT adequate'}"
        failed = [f"failed: {c['name']} ({c.get('detail', '')})" for c in self.checks if not c.get("passed")]
        return "\n".join([head, *failed, *(f"warning: {w}" for w in self.warnings)])


class Fit:
    """A calibration (a ``uwlab fit`` directory): ``Fit.open(path)``.

    - `summary`: ``summary.json``; `parameters`: the posterior table (median, 2.5/16/84/97.5th percentiles, τ,
      R-hat, and the simulated truth where known) as a DataFrame;
    - `posterior`: the posterior as `arviz.InferenceData` (walkers as chains);
    - `verdict`: `Verdict`; `held_out`: each configuration predicted by a fit that did not see it;
    - `predict(design)`: the design's response and SNR over the posterior (credible band);
    - `figures()`: the corner and response figures as matplotlib Figures.

    Examples
    --------
    >>> import uwlab
    >>> fit = uwlab.Fit.open("out/demo/fit")  # doctest: +SKIP
    >>> bool(fit.verdict), fit.parameters.loc["light_efficiency", "median"]  # doctest: +SKIP
    (True, 0.8026...)
    """

    def __init__(self, directory: str | os.PathLike[str]) -> None:
        self.directory = Path(directory)

    @classmethod
    def open(cls, directory: str | os.PathLike[str]) -> Fit:
        """The fit in `directory` (refused unless it holds a ``summary.json``)."""
        from uwlab.errors import ConfigError

        fit = cls(directory)
        if not (fit.directory / "summary.json").exists():
            raise ConfigError("fit", str(directory), "no summary.json here (not a `uwlab fit` output directory)")
        return fit

    @cached_property
    def summary(self) -> dict[str, Any]:
        """``summary.json`` (the fit, its checks, the held-out table, the verdict)."""
        from uwlab.model.data import read_json

        summary: dict[str, Any] = read_json(self.directory / "summary.json", "fit")
        return summary

    @property
    def parameters(self) -> pd.DataFrame:
        """One row per fitted parameter: median, p2_5, p16, p84, p97_5, tau, rhat, map (and truth, simulated)."""
        import pandas as pd

        frame = pd.DataFrame.from_dict(self.summary["parameters"], orient="index")
        frame.index.name = "parameter"
        return frame

    @cached_property
    def posterior(self) -> arviz.InferenceData:
        """The posterior as InferenceData (``posterior.nc``; for an older fit, ``samples.parquet`` as one
        chain)."""
        from uwlab.experiments.calibration.inference import read_inference_data

        return read_inference_data(self.directory)

    @property
    def verdict(self) -> Verdict:
        s = self.summary
        return Verdict(
            bool(s.get("model_adequate")),
            str(s.get("model")),
            tuple(s.get("checks") or ()),
            tuple(s.get("warnings") or ()),
        )

    @property
    def held_out(self) -> pd.DataFrame:
        """Per configuration held out: points, median absolute relative error, share inside the 95 % band."""
        import pandas as pd

        return pd.DataFrame(self.summary.get("cross_configuration") or [])

    def figures(self) -> Mapping[str, Figure]:
        """The fit's figures as matplotlib Figures (a notebook shows each inline), drawn again from this
        directory: ``corner`` (the posterior's marginals, the simulated truth marked) and ``response`` (measured
        against predicted per configuration, residuals with the fitted and held-out 95 % bands) — the same figures
        as ``corner.png`` and ``response.png`` and the report. The walker traces need the whole chain, which is
        kept only in ``traces.png``; ``arviz.plot_trace(fit.posterior)`` draws the kept samples. Each figure is
        drawn when first asked for (`uwlab.experiments.figures.DrawnOnDemand`)."""
        from uwlab.experiments.calibration.output import fit_dir_figures

        return fit_dir_figures(self.directory)

    def predict(self, design: Design, samples: int = 1000) -> pd.DataFrame:
        """The design's on-axis response and SNR over (up to `samples` of) the posterior, the calibrated factors
        carried into the design (`uwlab.experiments.design.posterior`): one row per output, columns the
        percentiles p2_5, p16, median, p84, p97_5; ``attrs`` hold the share of samples that saturate and the
        parameters carried."""
        import pandas as pd

        from uwlab.experiments.design.posterior import credible_band, load_posterior

        band = credible_band(design, load_posterior(self.directory, design, max_samples=samples))
        rows = {k: v for k, v in band.items() if isinstance(v, dict)}
        frame = pd.DataFrame.from_dict(rows, orient="index")
        frame.attrs.update(
            saturated_fraction=band["saturated_fraction"], carried=band["carried"], samples=band["samples"]
        )
        return frame

    def __repr__(self) -> str:
        return f"Fit({str(self.directory)!r})"


def fit(
    dataset: Dataset | str | os.PathLike[str],
    model: str | None = None,
    out: str | os.PathLike[str] | None = None,
    *,
    config: str | os.PathLike[str] | None = None,
    train: Sequence[str] | None = None,
    sensor: Mapping[str, str | os.PathLike[str]]
    | Sequence[str | os.PathLike[str]]
    | str
    | os.PathLike[str]
    | None = None,
    channel: str | None = None,
    held_out: int | str | None = None,
    dask: str | None = None,
    progress: bool = True,
    **sampler: int,
) -> Fit:
    """Calibrate the model against a dataset with emcee, check it and judge it (``uwlab fit``: each option is an
    argument of the same name and default).

    Parameters
    ----------
    dataset
        A `Dataset` or its directory.
    model
        The chain fitted: ``"extended"``, ``"paper"``, or None (``uwlab fit``'s default) for the rigs' own
        ``[model] kind`` (the tank plan's rig: extended).
    out
        The fit directory (default ``DATASET/fit``; ``uwlab fit --out``).
    config
        A fit config TOML (priors, sampler, held-out sweeps; default: ``configs/fit/default.toml``'s choices for
        the dataset's cameras; a bundled one by name: ``"fit/default.toml"``).
    train
        The sweeps the held-out check fits (it predicts the others; default: two folds of the sweeps).
    sensor
        The cameras as characterised by ``uwlab emva characterize`` or `EmvaResult.write` (``uwlab fit
        --sensor``): {camera: its profile TOML or output folder}, or ``"CAMERA=FROM"`` strings as on the command
        line (a bare FROM when the dataset has one camera). The measured response curve, with its uncertainty,
        enters the model. Default: the sensor profiles (a linear response).
    channel
        ``"red"``, ``"green"`` or ``"blue"``: fit that colour channel of a Bayer dataset with the profile's QE of
        that channel (``uwlab fit --channel``); None: the whole mosaic with its combined QE.
    progress
        Show the sampling progress (a terminal or a notebook).
    **sampler
        Overrides of the config's ``[sampler]``: ``walkers``, ``chunk_steps``, ``max_steps``, ``seed`` (a short
        exploratory fit: ``max_steps=1000``; it then reports ``converged: false``).

    Returns
    -------
    Fit

    Examples
    --------
    >>> import uwlab
    >>> result = uwlab.fit("tank", sensor={"imx250m": "emva-imx250m", "icx285alm": "emva-icx285alm"})  # doctest: +SKIP
    >>> print(result.verdict)  # doctest: +SKIP
    extended model: adequate
    """
    from uwlab.api.campaign import dataset_path
    from uwlab.api.paths import config_file, python_names
    from uwlab.experiments.calibration.pipeline import calibrate
    from uwlab.progress import tau_bar

    shown, update = tau_bar("sampling", enabled=progress)
    with python_names(), shown:
        calibration = calibrate(
            dataset_path(dataset),
            None if config is None else config_file(config, "config"),
            None if out is None else Path(out),
            None if train is None else list(train),
            progress=update,
            model=model,
            sampler=dict(sampler) or None,
            sensors=_sensor_values(sensor),
            channel=channel,
            held_out=held_out,
            dask=dask,
        )
    return Fit.open(calibration.out)


def _sensor_values(sensor: Sensors | None) -> list[str] | None:
    """`fit`'s `sensor` as the values of ``uwlab fit --sensor`` (``[CAMERA=]FROM``)."""
    if sensor is None:
        return None
    if isinstance(sensor, Mapping):
        return [f"{camera}={os.fspath(source)}" for camera, source in sensor.items()]
    if isinstance(sensor, (str, os.PathLike)):
        return [os.fspath(sensor)]
    return [os.fspath(value) for value in sensor]


def report(
    source: Fit | Dataset | str | os.PathLike[str], out: str | os.PathLike[str] | None = None, *, force: bool = False
) -> Path:
    """Write the self-contained HTML validation report (``uwlab report``; verdict first).

    Parameters
    ----------
    source
        A campaign directory (datasets, fits and EMVA characterisations under it), a `Dataset`, or a `Fit` (the
        report then covers the fit and the dataset it was fitted to: their common directory).
    out
        The report file (default ``report.html`` in that directory).
    force
        Replace an existing report.

    Examples
    --------
    >>> import uwlab
    >>> uwlab.report(uwlab.Fit.open("out/tank/fit"))  # doctest: +SKIP
    PosixPath('out/tank/report.html')
    """
    from uwlab.experiments.report import write_report
    from uwlab.outputs import REPORT_FILE

    if isinstance(source, Fit):
        dataset = source.summary.get("dataset")
        fit_dir = source.directory.resolve()
        root = Path(os.path.commonpath([fit_dir, Path(dataset).resolve()])) if dataset else fit_dir
    else:
        from uwlab.api.campaign import dataset_path

        root = dataset_path(source)
    from uwlab.api.paths import python_names

    with python_names():
        return write_report(root, Path(out) if out is not None else root / REPORT_FILE, replace=force)
