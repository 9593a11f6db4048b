"""Figures from the public API: `uwlab.design_figures`, `EmvaResult.figures()` and `Fit.figures()` return matplotlib
Figures that render to PNG, and they are the figures the CLI writes (a fit directory's figures drawn again are its
very PNG files)."""

from __future__ import annotations

import io
import shutil

import matplotlib.figure
import numpy as np
import pytest
from matplotlib.figure import Figure

import uwlab
from uwlab.errors import ConfigError
from uwlab.experiments.calibration.fit import FitConfig, default_config_for, fit_points
from uwlab.experiments.calibration.output import PNG_OPTIONS, plot_traces, write_fit
from uwlab.experiments.calibration.simulate import simulate_campaign
from uwlab.experiments.calibration.validation import point_predictions
from uwlab.experiments.emva.plots import figure_names
from uwlab.experiments.emva.simulate import DirectBench
from uwlab.experiments.figures import figure_png
from uwlab.model.schema import parse
from uwlab.model.sensor import load_sensor_profile
from uwlab.sim.devices.camera import SimTruth

PNG = b"\x89PNG\r\n\x1a\n"
TRUTH = {"light_efficiency": 0.8, "attenuation_scale": 1.2, "K_dn_per_e:imx250m": 0.36, "K_dn_per_e:icx285alm": 1.05}


def rendered(fig: Figure) -> bytes:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    return buffer.getvalue()


def test_design_figures_render_and_refuse_a_grid():
    design = uwlab.load_design(uwlab.config_path("design/example.toml"))
    figures = uwlab.design_figures(design)
    assert list(figures) == ["dof", "spectra", "operation", "water", "qe"]
    assert all(rendered(fig).startswith(PNG) for fig in figures.values())
    with pytest.raises(ConfigError, match="one design"):
        uwlab.design_figures(design.with_values(**{"lens.f_number": np.array([2.0, 4.0])}))


def test_an_api_figure_shows_itself_in_a_notebook_without_pyplot():
    formatters = pytest.importorskip("IPython.core.formatters")
    fig = uwlab.design_figures(uwlab.load_design(uwlab.config_path("design/example.toml")))["qe"]
    png = formatters.PNGFormatter()(fig)  # what IPython's display calls for image/png
    assert png is not None and png.startswith(PNG)
    assert formatters.PNGFormatter()(matplotlib.figure.Figure()) is None  # matplotlib's own, without pyplot: none


def test_emva_result_figures_are_the_characterisations():
    truth = SimTruth.from_sensor_profile(load_sensor_profile("imx250m"), resolution_px=(32, 32))
    pt = DirectBench(truth, 1.07e5, 0.6, seed=3).photon_transfer(
        np.linspace(2e3, 115e3, 24), dark_exposures_us=np.linspace(1e5, 6e5, 6)
    )
    result = uwlab.characterize(pt)
    figures = result.figures()
    assert list(figures) == figure_names(result.analysis)
    assert list(figures)[:3] == ["photon_transfer", "snr", "linearity"]
    snr = figures["snr"].axes[0]
    assert snr.get_xscale() == "log" and snr.get_xlabel() == "irradiation μ_p [photons/pixel]"
    assert rendered(figures["photon_transfer"]).startswith(PNG)


@pytest.fixture(scope="module")
def fit_dir(tmp_path_factory):
    """A short fit written as `uwlab fit` writes it, with the simulated truth and held-out predictions."""
    points, rigs = simulate_campaign(TRUTH, seed=1, points_per_sweep=4)
    base = default_config_for(points[~points["saturated"]], rigs)
    config = parse(FitConfig, {"parameters": base.priors, "sampler": {"max_steps": 1000, "chunk_steps": 500}})
    result = fit_points(points, rigs, config)
    predicted = point_predictions(result)
    held_out = predicted.assign(
        **{k: predicted[k] * 1.02 for k in ("predicted_median", "observed_p2_5", "observed_p97_5")}
    )
    out = tmp_path_factory.mktemp("fit") / "fit"
    write_fit(result, out, TRUTH, held_out=held_out)
    return out, result, points["sweep_id"].nunique()


def test_a_fits_figures_are_its_png_files(fit_dir):
    out, result, sweeps = fit_dir
    figures = uwlab.Fit.open(out).figures()
    assert list(figures) == ["corner", "response"]
    for name, fig in figures.items():
        assert figure_png(fig, **PNG_OPTIONS[name]) == (out / f"{name}.png").read_bytes(), name
    k = len(result.names)
    corner = figures["corner"]
    assert len(corner.axes) == k * k
    assert [ax.get_xlabel() for ax in corner.axes[-k:]] == list(result.names)
    response = figures["response"].axes
    assert len(response) == 2 * sweeps  # per configuration, the response and its residuals
    residuals = response[1::2]
    assert all(ax.get_ylabel() == "residual [%]" for ax in residuals[::3])  # the first of each row of three
    held = [c for ax in residuals for c in ax.collections if c.get_label() == "95 % band, predicted held out"]
    assert len(held) == sweeps  # heldout.parquet drawn again


def test_each_trace_panel_names_its_parameter_above_it(fit_dir):
    _, result, _ = fit_dir
    axes = plot_traces(result).axes
    assert [ax.get_title(loc="left") for ax in axes] == list(result.names)
    assert all(ax.get_ylabel() == "" for ax in axes)  # long names as y-labels ran into their neighbours


def test_a_fits_figure_is_drawn_from_its_own_files_only_when_asked_for(fit_dir, tmp_path):
    """Showing the response does not draw the corner: without the samples the corner needs, the response is drawn
    and the corner fails only when asked for."""
    out, _, _ = fit_dir
    copy = tmp_path / "fit"
    shutil.copytree(out, copy)
    (copy / "samples.parquet").unlink()
    figures = uwlab.Fit.open(copy).figures()
    assert figure_png(figures["response"], **PNG_OPTIONS["response"]) == (out / "response.png").read_bytes()
    with pytest.raises(ConfigError, match="samples.parquet"):
        figures["corner"]
