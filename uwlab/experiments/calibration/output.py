"""Writing a calibration to disk: posterior samples, summary, predictions and figures.

Files in the output directory: ``samples.parquet`` (posterior samples, one column per parameter),
``posterior.nc`` (the same samples per walker as an ArviZ ``InferenceData`` in NetCDF: ``arviz.from_netcdf``,
``arviz.summary`` and ``arviz.plot_trace`` work on it),
``summary.json`` (per parameter median, 2.5/16/84/97.5th percentiles, τ, R-hat; acceptance, converged flag,
parameters that cannot be separated; ``provenance``: the software and machine that fitted, `uwlab.provenance`),
``predictions.parquet`` (measured vs predicted with bands at every point),
``dense.parquet`` (bands along dense sweeps), ``heldout.parquet`` (predictions of each configuration from a fit
that did not see it), ``corner.png``, ``traces.png``, ``response.png`` (measured vs predicted per configuration,
saturated points marked, and residuals in per cent with the fitted and held-out 95 % bands): the `Figure` objects
of `plot_corner`, `plot_traces` and `plot_response`, written with `PNG_OPTIONS`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.ticker import FuncFormatter

from uwlab.errors import UwlabError
from uwlab.experiments.figures import LABEL_PT, PALETTE, TICK_PT, DrawnOnDemand, Figure, log_ticks, save_figure
from uwlab.experiments.calibration.fit import FitResult
from uwlab.experiments.calibration.inference import POSTERIOR_NAME, write_inference_data
from uwlab.experiments.calibration.validation import dense_sweeps, point_predictions
from uwlab.jsonable import dumps
from uwlab.model.data import MAX_BINARY_BYTES, check_input_file, read_json
from uwlab.outputs import output_dir
from uwlab.provenance import provenance

OUTPUT_FILES = (
    "samples.parquet",
    POSTERIOR_NAME,
    "summary.json",
    "predictions.parquet",
    "dense.parquet",
    "heldout.parquet",
    "corner.png",
    "traces.png",
    "response.png",
)
# How each figure becomes its PNG (`uwlab.experiments.figures.save_figure`): the corner and traces at 80 dpi, the
# response, laid out by its own grid, at 90 dpi cropped to what is drawn (the report embeds these files).
PNG_OPTIONS: dict[str, dict] = {
    "corner": {"dpi": 80},
    "traces": {"dpi": 80},
    "response": {"dpi": 90, "tight_bbox": True},
}


def check_output_dir(out: Path) -> None:
    """Refuse to write where `out` cannot be written (`uwlab.outputs.output_dir`) or to overwrite an earlier
    calibration in it."""
    output_dir(out, "--out")
    existing = [name for name in OUTPUT_FILES if (out / name).exists()]
    if existing:
        raise UwlabError(f"{out} already holds a calibration ({', '.join(existing)}); choose another --out")


def plot_corner(samples: np.ndarray, names: Sequence[str], truth: dict | None = None) -> Figure:
    """The posterior's one- and two-parameter marginals (`corner`), medians and 68 % intervals as titles, the
    simulated `truth` (by parameter name) marked where known; `samples`: (draws, parameters) in the order of
    `names`."""
    truths = [truth.get(n) for n in names] if truth else None
    import corner  # it imports pyplot (0.4 s): only where a corner plot is drawn

    k = len(names)  # corner's own figure size for k parameters (its defaults), on a Figure of ours
    size = 1.0 + 2.0 * k + 2.0 * (k - 1) * 0.05 + 0.4
    fig: Figure = corner.corner(
        samples,
        fig=Figure(figsize=(size, size)),
        labels=list(names),
        truths=truths,
        quantiles=[0.16, 0.5, 0.84],
        show_titles=True,
        title_fmt=".3g",
        title_kwargs={"fontsize": TICK_PT},
        label_kwargs={"fontsize": TICK_PT},
    )
    return fig


def plot_traces(result: FitResult) -> Figure:
    """Every walker's position against the step, one panel per parameter (the whole chain, burn-in included), its
    name above it (as a y-label the long names, ``lens_transmittance:30mm-F2.0``, ran into their neighbours)."""
    n = len(result.names)
    fig = Figure(figsize=(8, 1.6 * n))
    axes = fig.subplots(n, 1, sharex=True)
    axes = np.atleast_1d(axes)
    for i, ax in enumerate(axes):
        ax.plot(result.chain[:, :, i], color="k", alpha=0.15, linewidth=0.5)
        ax.set_title(result.names[i], loc="left", fontsize=TICK_PT)
        ax.tick_params(labelsize=TICK_PT)
    axes[-1].set_xlabel("step")
    fig.suptitle(f"walker traces (τ max {np.max(result.tau):.0f} steps, {result.steps} steps)")
    fig.tight_layout()
    return fig


def configuration_label(sensor_profile: str, focal_length_mm, f_number) -> str:
    """A configuration in words: ``IMX250M · 30 mm f/2`` or ``IMX250M · no lens``."""
    sensor = str(sensor_profile).upper()
    if f_number is None or not np.isfinite(f_number):
        return f"{sensor} · no lens"
    return f"{sensor} · {focal_length_mm:g} mm f/{f_number:g}"


def configuration_labels(frame: pd.DataFrame) -> dict[str, str]:
    """{sweep_id: `configuration_label`} of the rows of a points or predictions table."""
    rows = frame.drop_duplicates("sweep_id")
    return {r.sweep_id: configuration_label(r.sensor_profile, r.focal_length_mm, r.f_number) for r in rows.itertuples()}


FITTED, HELD_OUT, SATURATED = PALETTE["blue"], PALETTE["orange"], PALETTE["vermillion"]
MIN_RESIDUAL_RANGE_PERCENT = 0.5


def plot_response(predictions: pd.DataFrame, dense: pd.DataFrame, held_out: pd.DataFrame | None = None) -> Figure:
    """Per configuration: the measured response against exposure with the fitted model (saturated points marked),
    and below it the residuals in per cent of the model with its 95 % band of a new measurement, fitted and, where
    given, predicted for the configuration held out of the fit. Axes follow `uwlab.experiments.figures`' rules: log
    axes ticked at 1, 2, 5 per decade; the residual axis linear, sized to the fitted band and the residuals
    (`_residuals`), anything beyond it drawn at its edge and labelled with its value; the model over the dots."""
    sweeps = list(dict.fromkeys(predictions["sweep_id"]))
    labels = configuration_labels(predictions)
    columns = min(3, len(sweeps))
    rows = -(-len(sweeps) // columns)
    fig = Figure(figsize=(4.6 * columns, 5.4 * rows))
    outer = fig.add_gridspec(rows, columns, hspace=0.32, wspace=0.3, top=1 - 0.8 / (5.4 * rows))
    for j, sweep_id in enumerate(sweeps):
        cell = outer[divmod(j, columns)].subgridspec(2, 1, height_ratios=[2.0, 1.7], hspace=0.06)
        ax = fig.add_subplot(cell[0])
        res = fig.add_subplot(cell[1], sharex=ax)
        band = dense[dense["sweep_id"] == sweep_id]
        here = predictions[predictions["sweep_id"] == sweep_id]
        pts, clipped = here[~here["saturated"].astype(bool)], here[here["saturated"].astype(bool)]
        ax.plot(pts["exposure_us"], pts["measured_dn"], "o", color="k", markersize=4, label="measured", zorder=2)
        ax.plot(
            band["exposure_us"], band["predicted_median"], color=FITTED, linewidth=1.5, label="model (fitted)", zorder=3
        )
        if len(clipped):
            ax.plot(
                clipped["exposure_us"],
                clipped["measured_dn"],
                "x",
                color=SATURATED,
                markersize=8,
                mew=2,
                label="saturated (not fitted)",
            )
        ax.set_title(labels.get(sweep_id, sweep_id), fontsize=LABEL_PT + 1)
        ax.set_xscale("log")
        ax.set_yscale("log")
        log_ticks(ax.yaxis)
        ax.tick_params(labelbottom=False, labelsize=TICK_PT)
        _residuals(res, pts, held_out[held_out["sweep_id"] == sweep_id] if held_out is not None else None)
        log_ticks(res.xaxis)
        res.set_xlabel("exposure [µs]", fontsize=LABEL_PT)
        if j % columns == 0:
            ax.set_ylabel("signal − dark [DN]", fontsize=LABEL_PT)
            res.set_ylabel("residual [%]", fontsize=LABEL_PT)
        if j == 0:
            handles = [h for a in (ax, res) for h in a.get_legend_handles_labels()[0]]
            names = [n for a in (ax, res) for n in a.get_legend_handles_labels()[1]]
            fig.legend(
                handles, names, loc="upper center", ncol=5, fontsize=LABEL_PT, frameon=False, bbox_to_anchor=(0.5, 1.0)
            )
    return fig


def _residuals(ax, pts: pd.DataFrame, held_out: pd.DataFrame | None) -> None:
    """Residuals [%] of the measured points with the fitted band (shaded) and the held-out band (bars) on a linear
    axis of ±1.4 × the larger of the fitted band and the 75th percentile of |residuals| (at least
    ±`MIN_RESIDUAL_RANGE_PERCENT`): a residual beyond it is drawn at the edge as a triangle labelled with its value,
    a held-out band beyond it is cut at the edge (a triangle where all of it lies beyond), with the held-out
    prediction's offset and its band's extent written in the panel."""
    x = pts["exposure_us"].to_numpy()
    centre = pts["predicted_median"].to_numpy()
    lo = 100 * (pts["observed_p2_5"].to_numpy() / centre - 1)
    hi = 100 * (pts["observed_p97_5"].to_numpy() / centre - 1)
    residual = pts["residual_percent"].to_numpy()
    band = np.abs(np.concatenate([lo, hi]))
    band = band[np.isfinite(band)]
    spread = np.abs(residual[np.isfinite(residual)])
    scale = max(
        float(band.max()) if band.size else 0.0,
        float(np.percentile(spread, 75)) if spread.size else 0.0,
        MIN_RESIDUAL_RANGE_PERCENT / 1.4,
    )
    limit = 1.4 * scale
    if held_out is not None and len(held_out):
        h = held_out.set_index("exposure_us").reindex(x)
        h_lo = 100 * (h["observed_p2_5"].to_numpy() / centre - 1)
        h_hi = 100 * (h["observed_p97_5"].to_numpy() / centre - 1)
        ax.vlines(
            x,
            np.clip(h_lo, -limit, limit),
            np.clip(h_hi, -limit, limit),
            color=HELD_OUT,
            linewidth=5,
            alpha=0.5,
            label="95 % band, predicted held out",
            zorder=1,
        )
        h_median = 100 * (h["predicted_median"].to_numpy() / centre - 1)
        above, below = h_lo > limit, h_hi < -limit  # the whole band beyond the axis: a marker at the edge
        ax.plot(x[above], np.full(above.sum(), limit), "^", color=HELD_OUT, markersize=8, clip_on=False, zorder=4)
        ax.plot(x[below], np.full(below.sum(), -limit), "v", color=HELD_OUT, markersize=8, clip_on=False, zorder=4)
        if np.isfinite(h_lo).any() and max(np.nanmax(h_hi), -np.nanmin(h_lo)) > limit:
            ax.annotate(
                f"held out: {np.nanmedian(h_median):+.3g} %\nband {np.nanmin(h_lo):+.3g} to {np.nanmax(h_hi):+.3g} %",
                (0.02, 0.04),
                xycoords="axes fraction",
                va="bottom",
                bbox={"facecolor": "white", "alpha": 0.8, "edgecolor": "none", "pad": 1.0},
                fontsize=TICK_PT,
                color=HELD_OUT,
            )
    ax.fill_between(x, lo, hi, color=FITTED, alpha=0.35, linewidth=0, label="95 % band, fitted", zorder=2)
    ax.axhline(0, color=FITTED, linewidth=1, zorder=2)
    inside = np.abs(residual) <= limit
    ax.plot(x[inside], residual[inside], "o", color="k", markersize=4, zorder=3)
    for xi, ri in zip(x[~inside], residual[~inside], strict=True):
        edge = np.sign(ri) * limit
        ax.plot(xi, edge, "^" if ri > 0 else "v", color=SATURATED, markersize=8, zorder=4, clip_on=False)
        ax.annotate(
            f"{ri:+.3g} %",
            (xi, edge),
            textcoords="offset points",
            xytext=(5, -13 if ri > 0 else 4),
            fontsize=TICK_PT,
            color=SATURATED,
        )
    ax.set_ylim(-limit, limit)
    ax.set_xscale("log")
    ax.tick_params(labelsize=TICK_PT)
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:+.3g}" if v else "0"))


def fit_dir_figures(fit_dir: Path) -> DrawnOnDemand:
    """The figures of a written calibration drawn again from its files, by name, each when first asked for:
    ``corner`` (from ``samples.parquet`` and the truth in ``summary.json``) and ``response`` (from
    ``predictions.parquet``, ``dense.parquet`` and ``heldout.parquet``) — with `PNG_OPTIONS`, the very ``corner.png``
    and ``response.png``. The traces are not among them: a fit directory keeps the samples after burn-in, not the
    whole chain."""

    def corner_figure() -> Figure:
        summary = read_json(fit_dir / "summary.json", "fit")
        samples = _table(fit_dir / "samples.parquet")
        truth = {name: p["truth"] for name, p in summary["parameters"].items() if "truth" in p}
        return plot_corner(samples.to_numpy(), list(samples.columns), truth or None)

    def response_figure() -> Figure:
        held_out = fit_dir / "heldout.parquet"
        return plot_response(
            _table(fit_dir / "predictions.parquet"),
            _table(fit_dir / "dense.parquet"),
            _table(held_out) if held_out.exists() else None,
        )

    return DrawnOnDemand([("corner", corner_figure), ("response", response_figure)])


def _table(path: Path) -> pd.DataFrame:
    """A Parquet table of a fit directory, the path checked as every input is (a regular file, bounded)."""
    return pd.read_parquet(check_input_file(path, "fit", MAX_BINARY_BYTES, "Parquet"))


@dataclass(frozen=True)
class PosteriorOutputs:
    """What `write_posterior` wrote and `write_fit` draws on: the point predictions and the dense sweeps."""

    predictions: pd.DataFrame
    dense: pd.DataFrame


def write_posterior(result: FitResult, out: Path, truth: dict | None = None) -> PosteriorOutputs:
    """The outputs that need the whole-data fit alone — samples.parquet, posterior.nc, predictions.parquet,
    dense.parquet, corner.png, traces.png — into `out` (refusing to overwrite): `uwlab.experiments.calibration.
    pipeline.calibrate` writes them while the held-out folds still run, `write_fit` the rest."""
    check_output_dir(out)
    out.mkdir(exist_ok=True)
    pd.DataFrame(result.samples, columns=list(result.names)).to_parquet(out / "samples.parquet", index=False)
    write_inference_data(result, out)
    predictions = point_predictions(result)
    dense = dense_sweeps(result)
    predictions.to_parquet(out / "predictions.parquet", index=False)
    dense.to_parquet(out / "dense.parquet", index=False)
    figures = {"corner": plot_corner(result.samples, result.names, truth), "traces": plot_traces(result)}
    for name, fig in figures.items():
        save_figure(fig, out / f"{name}.png", **PNG_OPTIONS[name])
    return PosteriorOutputs(predictions, dense)


def remove_outputs(out: Path) -> None:
    """Remove every calibration output from `out`: after a calibration that failed part-way, whose output folder
    held none when it started (`check_output_dir`), so that it can be run again."""
    for name in OUTPUT_FILES:
        (out / name).unlink(missing_ok=True)


def write_fit(
    result: FitResult,
    out: Path,
    truth: dict | None = None,
    extra: dict | None = None,
    held_out: pd.DataFrame | None = None,
    posterior: PosteriorOutputs | None = None,
) -> dict:
    """Write every calibration output to `out` (refusing to overwrite); returns the summary. `held_out`: the
    held-out predictions (`uwlab.experiments.calibration.validation.held_out_fold`), drawn in response.png and
    written to heldout.parquet; `posterior`: what `write_posterior` has written already (None: written here)."""
    if posterior is None:
        posterior = write_posterior(result, out, truth)
    summary = result.summary()
    if truth:
        for name, entry in summary["parameters"].items():
            entry["truth"] = truth.get(name)
    summary.update(extra or {})
    summary["provenance"] = provenance()
    response = plot_response(posterior.predictions, posterior.dense, held_out)
    save_figure(response, out / "response.png", **PNG_OPTIONS["response"])
    if held_out is not None:
        held_out.to_parquet(out / "heldout.parquet", index=False)
    (out / "summary.json").write_text(dumps(summary, indent=2) + "\n")
    return summary
