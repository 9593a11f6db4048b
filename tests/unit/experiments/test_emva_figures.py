"""The EMVA 1288 figures are Figures drawn from the characterisation's curves (the plotted data are the result's),
one per name the data allow; the files of a characterisation and the images of its datasheet are those figures."""

from __future__ import annotations

import re

import numpy as np
import pytest
from matplotlib.figure import Figure

from uwlab.experiments.emva.analysis import characterize
from uwlab.experiments.emva.datasheet import SheetInfo, datasheet_html
from uwlab.experiments.emva.output import output_paths, write_characterization
from uwlab.experiments.emva.plots import figure_names, figure_pngs, figures, plot_snr
from uwlab.experiments.emva.simulate import DirectBench
from uwlab.experiments.figures import figure_png, png_data_uri
from uwlab.model.sensor import load_sensor_profile
from uwlab.sim.devices.camera import SimTruth

STACK_FIGURES = [
    "dsnu_spectrogram",
    "prnu_spectrogram",
    "dsnu_profiles",
    "prnu_profiles",
    "dsnu_histograms",
    "prnu_histograms",
]


@pytest.fixture(scope="module")
def transfer():
    """A photon transfer with everything a figure can show: dark series at three temperatures and the
    nonuniformity stacks."""
    truth = SimTruth.from_sensor_profile(
        load_sensor_profile("imx250m"),
        resolution_px=(48, 48),
        dark_current_e_per_s=200.0,
        dsnu_e=1.5,
        prnu_percent=1.0,
        dark_current_doubling_c=7.0,
        temperature_c=30.0,
    )
    bench = DirectBench(truth, 1.07e5, 0.6, seed=21)
    return bench.photon_transfer(
        np.linspace(2e3, 115e3, 30),
        dark_exposures_us=np.linspace(1e5, 6e5, 6),
        dark_temperatures_c=(37.0, 44.0),
        stack_exposure_us=50e3,
        stack_frames=16,
    )


@pytest.fixture(scope="module")
def linear(transfer):
    result = characterize(transfer)
    return result, figures(result)


def test_a_full_measurement_draws_every_figure_with_its_panels(linear, transfer):
    _, drawn = linear
    assert list(drawn) == [
        "photon_transfer",
        "snr",
        "linearity",
        "stability",
        "dark_current",
        "dark_current_temperature",
        "spatial_variances",
        *STACK_FIGURES,
    ]
    assert all(isinstance(fig, Figure) for fig in drawn.values())
    two_panels = {"linearity", "dark_current", *STACK_FIGURES}
    assert {name: len(fig.axes) for name, fig in drawn.items()} == {n: 1 + (n in two_panels) for n in drawn}
    general = characterize(transfer, "general")
    assert figure_names(general)[:2] == ["characteristic", "snr"] and "linearity" not in figure_names(general)


def test_photon_transfer_draws_the_curves_and_the_regression(linear):
    result, drawn = linear
    c = result.curves
    ax = drawn["photon_transfer"].axes[0]
    measured, fitted, line = ax.lines[:3]
    assert np.array_equal(measured.get_xdata(), c["signal_dn"]) and np.array_equal(
        measured.get_ydata(), c["signal_var_dn2"]
    )
    assert np.array_equal(fitted.get_xdata(), c["signal_dn"][c["fit_idx"]])
    x, y = line.get_xdata(), line.get_ydata()
    assert (y[-1] - y[0]) / (x[-1] - x[0]) == pytest.approx(result.values["K_dn_per_e"], rel=1e-9)
    assert "DN²" in ax.get_ylabel() and "[DN]" in ax.get_xlabel()


def test_snr_draws_the_measured_snr_and_the_ideal_sensor(linear):
    result, drawn = linear
    c = result.curves
    ax = drawn["snr"].axes[0]
    assert ax.get_xscale() == ax.get_yscale() == "log"
    lines = {line.get_label(): line for line in ax.lines}
    ok = (c["photons"] > 0) & (np.arange(len(c["photons"])) <= c["sat"])
    assert np.array_equal(lines["measured SNR"].get_ydata(), c["snr"][ok])
    assert np.array_equal(lines["measured SNR total"].get_ydata(), c["snr_total"][ok])
    ideal = lines["ideal sensor √μ_p"]
    assert np.allclose(ideal.get_ydata(), np.sqrt(ideal.get_xdata()), rtol=1e-12)  # SNR of a photon count


def test_dark_current_against_temperature_draws_each_temperature(linear):
    result, drawn = linear
    rows = result.values["dark_current_by_temperature"]
    ax = drawn["dark_current_temperature"].axes[0]
    assert ax.get_yscale() == "log" and len(rows) == 3
    assert np.array_equal(ax.lines[0].get_xdata(), [r["temperature_c"] for r in rows])
    assert np.array_equal(ax.lines[0].get_ydata(), [r["dark_current_e_per_s"] for r in rows])


def test_profiles_are_the_images_profiles(linear):
    result, drawn = linear
    horizontal = result.images.dsnu_profiles["horizontal"]
    lines = {line.get_label(): line for line in drawn["dsnu_profiles"].axes[0].lines}
    assert set(lines) == {"max", "mean", "middle", "min"}
    assert all(np.array_equal(lines[k].get_ydata(), horizontal[k]) for k in lines)


def test_the_files_and_the_datasheet_are_these_figures(linear, transfer, tmp_path):
    result, drawn = linear
    pngs = figure_pngs(result)
    assert list(pngs) == list(drawn) and all(png.startswith(b"\x89PNG\r\n\x1a\n") for png in pngs.values())
    page = datasheet_html(result, pngs, SheetInfo())
    assert re.findall(r"data:image/png;base64,[A-Za-z0-9+/=]+", page) == [png_data_uri(p) for p in pngs.values()]

    paths = output_paths(tmp_path / "out", result, "cam", with_profile=False)
    write_characterization(result, transfer, paths, name="cam", base=None, pixel_size_um=None)
    assert sorted(p.name for p in (tmp_path / "out").glob("*.png")) == sorted(f"{n}.png" for n in drawn)
    assert (tmp_path / "out" / "snr.png").read_bytes() == figure_png(plot_snr(result))  # drawn again: same PNG
