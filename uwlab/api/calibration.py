"""Calibration from Python: `fit`, its `Fit` (posterior as ArviZ InferenceData, verdict, predictions for a design)
and `report` — ``uwlab fit`` and ``uwlab report``.

A fit directory holds, beside the outputs of ``uwlab fit``, ``posterior.nc``: the posterior as InferenceData
(`uwlab.experiments.calibration.inference`), so ``arviz.summary(arviz.from_netcdf(".../fit/posterior.nc"))`` and
``arviz.plot_trace`` work on it directly.
"""

from __future__ import annotations

import json
import os
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
        if not (fit.directory / "summary.json").is_file():
            raise ConfigError("fit", str(directory), "no summary.json here (not a `uwlab fit` output directory)")
        return fit

    @cached_property
    def summary(self) -> dict[str, Any]:
        """``summary.json`` (the fit, its checks, the held-out table, the verdict)."""
        summary: dict[str, Any] = json.loads((self.directory / "summary.json").read_text())
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

    def figures(self) -> dict[str, Figure]:
        """The fit's figures as matplotlib Figures (a notebook shows each inline), drawn again from this
        directory: ``corner`` (the posterior's marginals, the simulated truth marked) and ``response`` (measured
        against predicted per configuration, residuals with the fitted and held-out 95 % bands) — the same figures
        as ``corner.png`` and ``response.png`` and the report. The walker traces need the whole chain, which is
        kept only in ``traces.png``; ``arviz.plot_trace(fit.posterior)`` draws the kept samples."""
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
    model: str | None = "extended",
    out: str | os.PathLike[str] | None = None,
    *,
    config: str | os.PathLike[str] | None = None,
    train: list[str] | None = None,
    channel: str | None = None,
    held_out: int | str | None = None,
    dask: str | None = None,
    progress: bool = True,
    **sampler: int,
) -> Fit:
    """Calibrate the model against a dataset with emcee, check it and judge it (``uwlab fit``).

    Parameters
    ----------
    dataset
        A `Dataset` or its directory.
    model
        The chain fitted: ``"extended"``, ``"paper"``, or None for the rigs' own ``[model] kind``.
    out
        The fit directory (default ``DATASET/fit``; ``uwlab fit --out``).
    config
        A fit config TOML (priors, sampler, held-out sweeps; default: ``configs/fit/default.toml``'s choices for
        the dataset's cameras).
    train
        The sweeps the held-out check fits (it predicts the others).
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
    >>> result = uwlab.fit("out/tank", max_steps=2000)  # doctest: +SKIP
    >>> print(result.verdict)  # doctest: +SKIP
    extended model: adequate
    """
    from uwlab.experiments.calibration.pipeline import calibrate
    from uwlab.api.campaign import dataset_path
    from uwlab.outputs import FIT_FOLDER
    from uwlab.progress import tau_bar

    root = dataset_path(dataset)
    target = Path(out) if out is not None else root / FIT_FOLDER
    shown, update = tau_bar("sampling", enabled=progress)
    with shown:
        calibrate(
            root,
            None if config is None else Path(config),
            target,
            train,
            progress=update,
            model=model,
            sampler=dict(sampler) or None,
            channel=channel,
            held_out=held_out,
            dask=dask,
        )
    return Fit.open(target)


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
    return write_report(root, Path(out) if out is not None else root / REPORT_FILE, replace=force)
