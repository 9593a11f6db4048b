"""Writing a calibration to disk: posterior samples, summary, predictions and figures.

Files in the output directory: ``samples.parquet`` (posterior samples, one column per parameter),
``summary.json`` (per parameter median, 2.5/16/84/97.5th percentiles, τ, R-hat; acceptance, converged flag,
parameters that cannot be separated), ``predictions.parquet`` (measured vs predicted with bands at every point),
``dense.parquet`` (bands along dense sweeps), ``corner.png``, ``traces.png``, ``response.png`` (measured vs
predicted per configuration with 68 % / 95 % bands, and residuals).
"""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import corner  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.ticker import NullFormatter  # noqa: E402

from uwlab.errors import UwlabError  # noqa: E402
from uwlab.experiments.calibration.fit import FitResult  # noqa: E402
from uwlab.experiments.calibration.validation import dense_sweeps, point_predictions  # noqa: E402
from uwlab.jsonable import dumps  # noqa: E402
from uwlab.outputs import output_dir  # noqa: E402

OUTPUT_FILES = ("samples.parquet", "summary.json", "predictions.parquet", "dense.parquet", "corner.png", "traces.png",
                "response.png")


def check_output_dir(out: Path) -> None:
    """Refuse to write where `out` cannot be written (`uwlab.outputs.output_dir`) or to overwrite an earlier
    calibration in it."""
    output_dir(out, "--out")
    existing = [name for name in OUTPUT_FILES if (out / name).exists()]
    if existing:
        raise UwlabError(f"{out} already holds a calibration ({', '.join(existing)}); choose another --out")


def corner_plot(result: FitResult, path: Path, truth: dict | None = None) -> Path:
    truths = [truth.get(n) for n in result.names] if truth else None
    fig = corner.corner(result.samples, labels=list(result.names), truths=truths, quantiles=[0.16, 0.5, 0.84],
                        show_titles=True, title_fmt=".3g", title_kwargs={"fontsize": 8}, label_kwargs={"fontsize": 8})
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def trace_plot(result: FitResult, path: Path) -> Path:
    n = len(result.names)
    fig, axes = plt.subplots(n, 1, figsize=(8, 1.6 * n), sharex=True)
    axes = np.atleast_1d(axes)
    for i, ax in enumerate(axes):
        ax.plot(result.chain[:, :, i], color="k", alpha=0.15, linewidth=0.5)
        ax.set_ylabel(result.names[i], fontsize=7)
    axes[-1].set_xlabel("step")
    fig.suptitle(f"walker traces (τ max {np.max(result.tau):.0f} steps, {result.steps} steps)")
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def response_plot(predictions: pd.DataFrame, dense: pd.DataFrame, path: Path) -> Path:
    sweeps = list(dict.fromkeys(predictions["sweep_id"]))
    fig, axes = plt.subplots(2, len(sweeps), figsize=(3.2 * len(sweeps), 5.5), squeeze=False,
                             gridspec_kw={"height_ratios": [3, 1]})
    for j, sweep_id in enumerate(sweeps):
        ax, res = axes[0, j], axes[1, j]
        band = dense[dense["sweep_id"] == sweep_id]
        here = predictions[predictions["sweep_id"] == sweep_id]
        pts, clipped = here[~here["saturated"]], here[here["saturated"]]
        ax.fill_between(band["exposure_us"], band["predicted_p2_5"], band["predicted_p97_5"], color="C0", alpha=0.2,
                        label="95 %")
        ax.fill_between(band["exposure_us"], band["predicted_p16"], band["predicted_p84"], color="C0", alpha=0.4,
                        label="68 %")
        ax.plot(band["exposure_us"], band["predicted_median"], color="C0", linewidth=1, label="predicted")
        ax.plot(pts["exposure_us"], pts["measured_dn"], "k.", label="measured")
        if len(clipped):
            ax.plot(clipped["exposure_us"], clipped["measured_dn"], "x", color="C3", label="saturated (not fitted)")
        ax.set_title(sweep_id, fontsize=8)
        res.axhline(0, color="C0")
        res.plot(pts["exposure_us"], pts["residual_dn"] / pts["predicted_median"] * 100, "k.")
        for a in (ax, res):
            a.set_xscale("log")
            a.xaxis.set_minor_formatter(NullFormatter())
        ax.set_yscale("log")
        ax.yaxis.set_minor_formatter(NullFormatter())
        res.set_xlabel("exposure [µs]", fontsize=8)
        if j == 0:
            ax.set_ylabel("mean response − dark [DN]", fontsize=8)
            res.set_ylabel("residual [%]", fontsize=8)
            ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def write_fit(result: FitResult, out: Path, truth: dict | None = None, extra: dict | None = None) -> dict:
    """Write every calibration output to `out` (refusing to overwrite); returns the summary."""
    check_output_dir(out)
    out.mkdir(exist_ok=True)
    summary = result.summary()
    if truth:
        for name, entry in summary["parameters"].items():
            entry["truth"] = truth.get(name)
    summary.update(extra or {})
    pd.DataFrame(result.samples, columns=list(result.names)).to_parquet(out / "samples.parquet", index=False)
    predictions = point_predictions(result)
    dense = dense_sweeps(result)
    predictions.to_parquet(out / "predictions.parquet", index=False)
    dense.to_parquet(out / "dense.parquet", index=False)
    corner_plot(result, out / "corner.png", truth)
    trace_plot(result, out / "traces.png")
    response_plot(predictions, dense, out / "response.png")
    (out / "summary.json").write_text(dumps(summary, indent=2) + "\n")
    return summary
