"""The design figures of the paper: depth of field, spectra along the chain, framerate and exposure limits, water
attenuation, quantum efficiency (`design_figures`, as `Figure` objects; ``uwlab design --plot`` writes them as PNG
files), and the Pareto front of ``uwlab design solve --plot`` (`plot_front`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.ticker import ScalarFormatter

from uwlab.errors import ConfigError
from uwlab.experiments.figures import Figure, save_figure
from uwlab.experiments.design.curves import dof_curves, operation_curves, quantum_efficiency, water_attenuation
from uwlab.model.design import Design
from uwlab.model.evaluation import stage_spectra
from uwlab.outputs import output_dir


def plot_dof(design: Design) -> Figure:
    """Far (solid) and near (dashed) depth-of-field limits against the f-number, one colour per focus distance
    (`dof_curves`); no far limit past the hyperfocal distance."""
    curves = dof_curves(design)
    fig = Figure(figsize=(7, 4.5))
    ax = fig.subplots()
    for s, near, far in zip(curves["focus_m"], curves["near_m"], curves["far_m"], strict=True):
        (line,) = ax.plot(curves["f_number"], np.where(np.isfinite(far), far, np.nan), label=f"focus {s:.2f} m")
        ax.plot(curves["f_number"], near, color=line.get_color(), linestyle="--")
    ax.set(
        xscale="log",
        xlabel="f-number N",
        ylabel="object distance in water [m]",
        title="Depth of field: far (solid) and near (dashed) limits",
    )
    ax.legend()
    fig.tight_layout()
    return fig


def plot_stages(design: Design) -> Figure:
    """The spectrum at each stage of the on-axis chain, one panel per stage (`stage_spectra`)."""
    spectra = stage_spectra(design)
    nm = spectra["wavelength_nm"]
    fig = Figure(figsize=(7, 10))
    axes = fig.subplots(5, 1, sharex=True)
    panels = [
        ("source_w_nm", "source Φe [W/nm]"),
        ("target_irradiance_w_m2_nm", "at target E_t [W/m²/nm]"),
        ("return_radiance_w_m2_sr_nm", "after return path L_w [W/m²/sr/nm]"),
        ("sensor_irradiance_w_m2_nm", "after lens E_s [W/m²/nm]"),
        ("absorbed_w_m2_nm", "absorbed E_s·η [W/m²/nm]"),
    ]
    for ax, (key, label) in zip(axes, panels, strict=True):
        ax.plot(nm, spectra[key])
        ax.set_ylabel(label, fontsize=8)
    axes[-1].set_xlabel("wavelength [nm]")
    axes[0].set_title("Spectrum at each stage of the on-axis chain")
    fig.tight_layout()
    return fig


def plot_operation(design: Design) -> Figure:
    """Minimum framerate for the overlap and maximum exposure for the blur limit against speed, one line per
    altitude (`operation_curves`)."""
    curves = operation_curves(design)
    fig = Figure(figsize=(10, 4))
    (a1, a2) = fig.subplots(1, 2)
    for h, framerate, exposure in zip(
        curves["altitude_m"], curves["min_framerate_hz"], curves["max_exposure_s"], strict=True
    ):
        a1.plot(curves["speed_m_s"], framerate, label=f"altitude {h:.2f} m")
        a2.plot(curves["speed_m_s"], exposure * 1e3, label=f"altitude {h:.2f} m")
    a1.set(xlabel="speed [m/s]", ylabel="minimum framerate [Hz]", title="Framerate for the overlap")
    a2.set(xlabel="speed [m/s]", ylabel="maximum exposure [ms]", yscale="log", title="Exposure for the blur limit")
    a1.legend()
    fig.tight_layout()
    return fig


def plot_water(design: Design) -> Figure:
    """Beam attenuation of every named water type (`water_attenuation`)."""
    fig = Figure(figsize=(7, 4.5))
    ax = fig.subplots()
    for name, c in water_attenuation(design.grid).items():
        ax.plot(design.grid.nm, c, label=name)
    ax.set(
        yscale="log",
        xlabel="wavelength [nm]",
        ylabel="beam attenuation c = a + b [1/m]",
        title="Water attenuation profiles",
    )
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    return fig


def plot_qe(design: Design) -> Figure:
    """Quantum efficiency of every shipped sensor profile and the design's own (bold; `quantum_efficiency`)."""
    fig = Figure(figsize=(7, 4.5))
    ax = fig.subplots()
    for name, (nm, qe) in quantum_efficiency((design.sensor,)).items():
        ax.plot(nm, qe, label=name, linewidth=2.5 if name == design.sensor.name else 1)
    ax.set(xlabel="wavelength [nm]", ylabel="quantum efficiency η", title="Sensor quantum efficiency (mono / combined)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def prepare_plot_dir(out_dir: str | Path) -> Path:
    """Create the figure directory once `uwlab.outputs.output_dir` accepts it (its parent must exist), or fail in one
    line naming it."""
    out_dir = output_dir(out_dir, "--plot")
    out_dir.mkdir(exist_ok=True)
    return out_dir


DESIGN_FIGURES = {
    "dof": plot_dof,
    "spectra": plot_stages,
    "operation": plot_operation,
    "water": plot_water,
    "qe": plot_qe,
}


def design_figures(design: Design) -> dict[str, Figure]:
    """Every design figure of a scalar design by name (``uwlab design --plot`` writes each as ``NAME.png``)."""
    return {name: plot(design) for name, plot in DESIGN_FIGURES.items()}


def write_design_plots(design: Design, out_dir: Path) -> list[Path]:
    """Write all design figures for a scalar design into out_dir; returns the files."""
    out_dir = prepare_plot_dir(out_dir)
    try:
        return [save_figure(fig, out_dir / f"{name}.png") for name, fig in design_figures(design).items()]
    except OSError as exc:
        raise ConfigError("--plot", str(out_dir), f"cannot write a figure ({exc.strerror})") from None


def _axis_label(key: str) -> str:
    """ "light.luminous_flux_lm" → "light.luminous_flux [lm]" (the unit from the key's suffix)."""
    units = {"lm": "lm", "m": "m", "mm": "mm", "s": "s", "db": "dB", "deg": "°", "hz": "Hz", "m_s": "m/s", "nm": "nm"}
    for suffix in sorted(units, key=len, reverse=True):
        if key.lower().endswith("_" + suffix):
            return f"{key[: -len(suffix) - 1]} [{units[suffix]}]"
    return key


def plot_front(
    front,
    x_key: str,
    y_key: str,
    senses: tuple[str, str],
    requirements: list[str],
    log_x: bool,
    log_y: bool,
) -> Figure:
    """The Pareto front of two objectives, points coloured by the requirements that bind there."""
    fig = Figure(figsize=(7.5, 5))
    ax = fig.subplots()
    x, y = front[x_key].to_numpy(), front[y_key].to_numpy()
    ax.plot(x, y, color="0.4", linewidth=1, zorder=1)
    for label, rows in front.groupby(front["active"].where(front["active"] != "", "none"), sort=False):
        ax.scatter(rows[x_key], rows[y_key], s=28, zorder=2, label=f"active: {label}")
    ax.set(
        xscale="log" if log_x else "linear",
        yscale="log" if log_y else "linear",
        xlabel=f"{_axis_label(x_key)} ({senses[0]})",
        ylabel=f"{_axis_label(y_key)} ({senses[1]})",
    )
    for axis in (ax.xaxis, ax.yaxis):
        for setter in (axis.set_major_formatter, axis.set_minor_formatter):
            formatter = ScalarFormatter()
            formatter.set_scientific(False)
            setter(formatter)
    number = lambda v: f"{v:,.0f}" if abs(v) >= 1000 else f"{v:.3g}"  # noqa: E731
    for i, align in ((0, "left"), (len(x) - 1, "right")):
        ax.annotate(
            f"({number(x[i])}, {number(y[i])})",
            (x[i], y[i]),
            textcoords="offset points",
            xytext=(8, -4) if i == 0 else (-8, -4),
            ha=align,
            va="top",
            fontsize=8,
        )
    ax.set_title(
        "Pareto front: each point is the optimum of the first objective for that value of the second\n"
        "requirements: " + ", ".join(requirements),
        fontsize=8,
    )
    ax.tick_params(which="minor", labelsize=7)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    return fig
