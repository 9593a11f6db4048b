"""The design and port figures are Figures drawn from the curves functions (the plotted data are those curves),
and ``uwlab design --plot`` / ``uwlab port trace --plot`` write exactly those figures, one PNG per name."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from matplotlib.figure import Figure

from tests.support.paths import EXAMPLE, ROOT
from uwlab.cli.main import main
from uwlab.experiments.design.curves import dof_curves, operation_curves, quantum_efficiency, water_attenuation
from uwlab.experiments.design.plots import design_figures, plot_dof, plot_front
from uwlab.experiments.figures import figure_png
from uwlab.experiments.port.plots import port_figures
from uwlab.model.build import load_design
from uwlab.model.evaluation import stage_spectra
from uwlab.model.port_field import trace_design

FLAT_TILTED = {"housing.flat_thickness_mm": 10, "housing.flat_tilt_deg": [2, 0]}


@pytest.fixture(scope="module")
def design():
    return load_design(EXAMPLE)


@pytest.fixture(scope="module")
def figures(design):
    return design_figures(design)


def test_every_design_figure_is_a_figure_with_its_axes(figures):
    assert list(figures) == ["dof", "spectra", "operation", "water", "qe"]
    assert all(isinstance(fig, Figure) for fig in figures.values())
    assert [len(fig.axes) for fig in figures.values()] == [1, 5, 2, 1, 1]


def test_dof_lines_are_the_dof_curves():
    design = load_design(ROOT / "configs" / "design" / "dome-8mm.toml")  # reaches the hyperfocal distance
    curves = dof_curves(design)
    ax = plot_dof(design).axes[0]
    far, near = ax.lines[0::2], ax.lines[1::2]
    assert len(far) == len(near) == len(curves["focus_m"])
    for i, (solid, dashed) in enumerate(zip(far, near, strict=True)):
        assert solid.get_linestyle() == "-" and dashed.get_linestyle() == "--"
        assert np.array_equal(solid.get_xdata(), curves["f_number"])
        far_m, bounded = curves["far_m"][i], np.isfinite(curves["far_m"][i])
        assert np.array_equal(solid.get_ydata()[bounded], far_m[bounded])
        assert np.isnan(solid.get_ydata()[~bounded]).all()  # past the hyperfocal distance: a gap, not a line to inf
        assert np.array_equal(dashed.get_ydata(), curves["near_m"][i])
    assert not np.isfinite(curves["far_m"]).all()
    assert ax.get_xscale() == "log" and ax.get_xlabel() == "f-number N"


def test_spectra_panels_are_the_stage_spectra(design, figures):
    spectra = stage_spectra(design)
    keys = [
        "source_w_nm",
        "target_irradiance_w_m2_nm",
        "return_radiance_w_m2_sr_nm",
        "sensor_irradiance_w_m2_nm",
        "absorbed_w_m2_nm",
    ]
    axes = figures["spectra"].axes
    for ax, key in zip(axes, keys, strict=True):
        (line,) = ax.lines
        assert np.array_equal(line.get_xdata(), spectra["wavelength_nm"])
        assert np.array_equal(line.get_ydata(), spectra[key])
    assert axes[-1].get_xlabel() == "wavelength [nm]"


def test_operation_panels_are_the_operation_curves_in_ms(design, figures):
    curves = operation_curves(design)
    framerate, exposure = figures["operation"].axes
    assert len(framerate.lines) == len(exposure.lines) == len(curves["altitude_m"])
    for i in range(len(curves["altitude_m"])):
        assert np.array_equal(framerate.lines[i].get_ydata(), curves["min_framerate_hz"][i])
        assert np.allclose(exposure.lines[i].get_ydata(), curves["max_exposure_s"][i] * 1e3, rtol=1e-12)
    assert exposure.get_ylabel() == "maximum exposure [ms]" and exposure.get_yscale() == "log"


def test_water_and_qe_lines_are_the_tables(design, figures):
    water = water_attenuation(design.grid)
    ax = figures["water"].axes[0]
    assert [line.get_label() for line in ax.lines] == list(water)
    assert all(np.array_equal(line.get_ydata(), water[line.get_label()]) for line in ax.lines)
    qe = quantum_efficiency((design.sensor,))
    lines = {line.get_label(): line for line in figures["qe"].axes[0].lines}
    assert set(lines) == set(qe)
    assert np.array_equal(lines[design.sensor.name].get_ydata(), qe[design.sensor.name][1])
    assert [n for n, line in lines.items() if line.get_linewidth() == 2.5] == [design.sensor.name]  # its own, bold


def test_design_plot_writes_each_figure_as_its_png(figures, tmp_path, capsys):
    assert main(["design", str(EXAMPLE), "--plot", str(tmp_path)]) == 0
    capsys.readouterr()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(f"{name}.png" for name in figures)
    for name, fig in figures.items():
        assert (tmp_path / f"{name}.png").read_bytes() == figure_png(fig), name


def test_port_figures_are_the_trace_profiles_and_what_trace_plot_writes(tmp_path, capsys):
    design = load_design(EXAMPLE, FLAT_TILTED)
    trace = trace_design(design)
    figures = port_figures(design, trace)
    distortion, error = figures["port_distortion"].axes
    profile = trace["profile"]
    for line, name in zip(distortion.lines[:3], ("x", "y", "diagonal"), strict=True):
        assert np.array_equal(line.get_xdata(), profile["field_deg_air"][name])
        assert np.array_equal(line.get_ydata(), profile["distortion_percent"][name])
    assert np.array_equal(error.lines[2].get_ydata(), profile["distortion_px"]["diagonal"])
    (focus,) = figures["port_focus"].axes
    assert np.allclose(focus.lines[0].get_ydata(), profile["virtual_image_tangential_m"]["x"] * 1e3, rtol=1e-12)
    assert focus.get_xlabel() == "field angle in air [deg]"

    sets = [arg for key, value in FLAT_TILTED.items() for arg in ("--set", f"{key}={value}")]
    assert main(["port", "trace", str(EXAMPLE), *sets, "--plot", str(tmp_path)]) == 0
    capsys.readouterr()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["port_distortion.png", "port_focus.png"]
    for name, fig in figures.items():
        assert (tmp_path / f"{name}.png").read_bytes() == figure_png(fig), name


def test_the_front_is_the_frame_with_points_grouped_by_binding_requirement():
    frame = pd.DataFrame(
        {
            "lens.f_number": [2.0, 2.8, 4.0, 5.6],
            "light.luminous_flux_lm": [1200.0, 2400.0, 4800.0, 9600.0],
            "active": ["", "snr_db >= 30", "snr_db >= 30", "dof_m.near <= 1.7"],
        }
    )
    fig = plot_front(frame, "light.luminous_flux_lm", "lens.f_number", ("min", "max"), ["snr_db >= 30"], True, False)
    (ax,) = fig.axes
    (line,) = ax.lines
    assert np.array_equal(line.get_xdata(), frame["light.luminous_flux_lm"])
    assert np.array_equal(line.get_ydata(), frame["lens.f_number"])
    assert [c.get_label() for c in ax.collections] == [
        "active: none",
        "active: snr_db >= 30",
        "active: dof_m.near <= 1.7",
    ]
    assert [len(c.get_offsets()) for c in ax.collections] == [1, 2, 1]
    assert ax.get_xlabel() == "light.luminous_flux [lm] (min)" and ax.get_xscale() == "log"
    assert ax.get_yscale() == "linear"
