"""EMVA 1288 Release 4.0 figures, as the standard draws them (Linear §6–8, General §6–8):

photon transfer (Fig. 7; general model: the characteristic curve, General Fig. 5), SNR (Fig. 8; general: input SNR,
General Fig. 7), linearity (Fig. 9), stability (Fig. 6), dark current against exposure time (Fig. 10) and against
temperature (Fig. 11, log scale), the spatial variances at every illumination step (§4.3), horizontal and vertical
spectrograms of the DSNU and PRNU images (Figs. 12–13), their profiles (Fig. 14) and their logarithmic and accumulated
histograms (Figs. 15–16). Each ``plot_*`` returns its `Figure`; `figures` draws every one the result has data for
(a figure whose data are missing — no stacks, one temperature — is not drawn), in that order, by name: the
characterisation writes each as ``NAME.png`` and embeds the same PNGs (`figure_pngs`) in the datasheet.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import TypedDict

import numpy as np

from uwlab.errors import ConfigError
from uwlab.experiments.emva.analysis import EmvaResult
from uwlab.experiments.frames.nonuniformity import ImageAnalysis
from uwlab.experiments.emva.linear import total_snr_model
from uwlab.experiments.figures import PALETTE, DrawnOnDemand, Figure, figure_png, log_ticks
from uwlab.model.sensor import snr

FIGSIZE = (6.4, 4.2)


class LineStyle(TypedDict):
    """Keyword arguments of a matplotlib line."""

    ls: str
    color: str
    lw: float


SAT_STYLE: LineStyle = {"ls": "--", "color": "0.45", "lw": 1}


def _fmt(value, spec: str = ".4g", unit: str = "") -> str:
    return "n/a" if value is None else f"{value:{spec}}{unit}"


def plot_photon_transfer(result: EmvaResult) -> Figure:
    """Fig. 7: σ²_y − σ²_y.dark against μ_y − μ_y.dark, the 0–70 % fit points and the regression line."""
    c, v = result.curves, result.values
    fig = Figure(figsize=FIGSIZE)
    ax = fig.subplots()
    sat = c["sat"]
    ax.plot(c["signal_dn"], c["signal_var_dn2"], "o", ms=3, color="0.6", label="measured")
    idx = c["fit_idx"]
    ax.plot(c["signal_dn"][idx], c["signal_var_dn2"][idx], "o", ms=4, color="tab:green", label="fit range (0-70 %)")
    k, offset = c["photon_transfer_line"]
    x = np.linspace(0, c["signal_dn"][sat], 50)
    rel = 100 * v["K_dn_per_e_std"] / k
    ax.plot(x, k * x + offset, "-", color="tab:blue", label=f"K = {k:.4g} DN/e- ± {rel:.2g} %")
    ax.axvline(c["signal_dn"][sat], **SAT_STYLE, label="saturation")
    ax.set(
        xlabel="mean − dark value μ_y − μ_y.dark [DN]",
        ylabel="variance − dark σ²_y − σ²_y.dark [DN²]",
        title=f"Photon transfer: σ²_y.dark = {v['dark_var_dn2']:.3g} DN², K = {k:.4g} DN/e-",
    )
    ax.set_ylim(bottom=min(0.0, float(np.nanmin(c["signal_var_dn2"]))))
    ax.legend(fontsize=10)
    fig.tight_layout()
    return fig


def plot_characteristic(result: EmvaResult) -> Figure:
    """General Fig. 5: μ_y − μ_y.dark against μ_p with the B-spline regression up to saturation."""
    c, v = result.curves, result.values
    fig = Figure(figsize=FIGSIZE)
    ax = fig.subplots()
    ax.plot(c["photons"], c["signal_dn"], "o", ms=3, color="0.6", label="measured")
    upto = c["photons"] <= v["saturation_photons"]
    ax.plot(
        c["photons"][upto],
        c["characteristic_fit_dn"][upto],
        "-",
        color="tab:blue",
        label=f"cubic B-spline, {v['characteristic_intervals']} intervals",
    )
    ax.axvline(v["saturation_photons"], **SAT_STYLE, label="saturation")
    ax.set(
        xlabel="irradiation μ_p [photons/pixel]",
        ylabel="mean − dark value μ_y − μ_y.dark [DN]",
        title=f"Characteristic curve: R_d = {v['responsivity_dark_dn_per_photon']:.4g} DN/p",
    )
    ax.legend(fontsize=10)
    fig.tight_layout()
    return fig


def plot_snr(result: EmvaResult) -> Figure:
    """Fig. 8 (linear: measured SNR and SNR_total, eq. 21 and eq. 69 models, ideal sensor) or General Fig. 7 (input
    SNR_p and SNR_p.total, ideal sensor), with the sensitivity threshold and saturation marked."""
    c, v = result.curves, result.values
    ok = (c["photons"] > 0) & (np.arange(len(c["photons"])) <= c["sat"])
    p = c["photons"][ok]
    fig = Figure(figsize=FIGSIZE)
    ax = fig.subplots()
    threshold = v["sensitivity_threshold_photons"]
    grid = np.geomspace(max((threshold or p.min()) / 3, 1e-2), v["saturation_photons"], 200)
    if v["model"] == "linear":
        eta, sigma_d, k = v["quantum_efficiency"], v["dark_noise_e"], v["K_dn_per_e"]
        # measured SNR (filled dots) drawn over the total (open squares) and the models (lines) over both
        ax.loglog(
            p, c["snr_total"][ok], "s", ms=5, mfc="none", color=PALETTE["orange"], label="measured SNR total", zorder=2
        )
        ax.loglog(p, c["snr"][ok], "o", ms=3.5, color=PALETTE["blue"], label="measured SNR", zorder=3)
        ax.loglog(
            grid,
            total_snr_model(eta * grid, sigma_d, k, v["dsnu_e"], v["prnu_percent"]),
            "-",
            color=PALETTE["orange"],
            label="model total eq. 69",
            zorder=4,
        )
        ax.loglog(
            grid,
            snr(eta * grid, sigma_d, k),
            "-",
            color=PALETTE["blue"],
            label=f"model eq. 21 (η = {eta:.3f}, σ_d = {sigma_d:.3g} e-)",
            zorder=5,
        )
        ylabel = "SNR"
    else:
        ax.loglog(p, c["snr_p_total"][ok], "s", ms=5, mfc="none", color=PALETTE["orange"], label="measured SNR_p total")
        ax.loglog(p, c["snr_p"][ok], "o", ms=3.5, color=PALETTE["blue"], label="measured input SNR_p", zorder=3)
        ylabel = "input SNR_p"
    ax.loglog(grid, np.sqrt(grid), ":", color="0.3", label="ideal sensor √μ_p")
    if threshold is not None:
        ax.axvline(
            threshold, ls="--", color=PALETTE["vermillion"], lw=1, label=f"threshold SNR = 1: {threshold:.3g} p/pixel"
        )
    ax.axvline(v["saturation_photons"], **SAT_STYLE, label=f"saturation: {v['saturation_photons']:.0f} p/pixel")
    ax.axhline(1.0, color="0.7", lw=0.8)
    ax.set(
        xlabel="irradiation μ_p [photons/pixel]",
        ylabel=ylabel,
        title=f"SNR: SNR_max = {v['snr_max_db']:.1f} dB, DR = {_fmt(v['dynamic_range_db'], '.1f')} dB",
    )
    log_ticks(ax.xaxis)
    log_ticks(ax.yaxis)
    ax.legend(fontsize=10)
    fig.tight_layout()
    return fig


def plot_linearity(result: EmvaResult) -> Figure:
    """Fig. 9: the characteristic curve with the linearity regression, and the relative deviation δ over 5–95 %."""
    c, v = result.curves, result.values
    fig = Figure(figsize=(6.4, 5.6))
    (ax, bx) = fig.subplots(2, 1, sharex=True)
    ax.plot(c["photons"], c["signal_dn"], "o", ms=3, color="0.6", label="measured")
    idx = c["lin_idx"]
    ax.plot(c["photons"][idx], c["signal_dn"][idx], "o", ms=3.5, color="tab:green", label="fit range (5-95 %)")
    ax.plot(c["photons"], c["linearity_fit_dn"], "-", color="tab:blue", label="regression (eq. 58-61)")
    ax.set(ylabel="μ_y − μ_y.dark [DN]", title=f"Linearity: LE = {v['linearity_error_percent']:.3g} % (eq. 63)")
    ax.legend(fontsize=10)
    bx.plot(c["photons"][idx], c["linearity_dev_percent"][idx], "o-", ms=3, color="tab:green")
    bx.axhline(0.0, color="0.5", lw=0.8)
    bx.set(xlabel="irradiation μ_p [photons/pixel]", ylabel="deviation δ [%]")
    fig.tight_layout()
    return fig


def plot_stability(result: EmvaResult) -> Figure:
    """Fig. 6: σ_y and μ[0] − μ[1] against μ_y − μ_y.dark."""
    c = result.curves
    fig = Figure(figsize=FIGSIZE)
    ax = fig.subplots()
    ax.plot(c["signal_dn"], c["temporal_std_dn"], "o-", ms=3, label="temporal std σ_y")
    if np.isfinite(c["mean_diff_dn"]).any():
        ax.plot(c["signal_dn"], c["mean_diff_dn"], "s-", ms=3, label="difference μ[0] − μ[1]")
    ax.axhline(0.0, color="0.7", lw=0.8)
    ax.set(xlabel="gray value μ_y − μ_y.dark [DN]", ylabel="[DN]", title="Stability check")
    ax.legend(fontsize=10)
    fig.tight_layout()
    return fig


def plot_dark_current(result: EmvaResult) -> Figure:
    """Fig. 10: dark mean and dark variance against exposure time with their regression lines."""
    c, v = result.curves, result.values
    dark, fit = c["dark"], c["dark_current_fit"]
    unit = "e-/s" if v["model"] == "linear" else "p/s"
    key = "dark_current_e_per_s" if v["model"] == "linear" else "dark_current_p_per_s"
    var_key = key.replace("current_", "current_var_")
    fig = Figure(figsize=(6.4, 6.0))
    (ax, bx) = fig.subplots(2, 1)
    ax.plot(dark.exposure_s, dark.mean_dn, "o", ms=3, label="measured")
    bx.plot(dark.exposure_s, dark.var_dn2, "o", ms=3, label="measured")
    if fit is not None:
        t = np.linspace(0, dark.exposure_s.max(), 20)
        ax.plot(
            t,
            fit.offset_dn + fit.mean_dn_per_s * t,
            "-",
            label=f"fit: {_fmt(v[key])} ± {_fmt(v[key + '_std'], '.2g')} {unit}",
        )
        var_fit = np.polyfit(dark.exposure_s, dark.var_dn2, 1)
        bx.plot(
            t, np.polyval(var_fit, t), "-", label=f"fit: {_fmt(v[var_key])} ± {_fmt(v[var_key + '_std'], '.2g')} {unit}"
        )
    ax.set(xlabel="exposure time [s]", ylabel="mean dark signal [DN]", title="Dark current from mean")
    bx.set(xlabel="exposure time [s]", ylabel="variance dark signal [DN²]", title="Dark current from variance")
    ax.legend(fontsize=10)
    bx.legend(fontsize=10)
    fig.tight_layout()
    return fig


def plot_dark_temperature(result: EmvaResult) -> Figure:
    """Fig. 11: the dark current (log scale) against temperature."""
    v = result.values
    unit = "e" if v["model"] == "linear" else "p"
    rows = v["dark_current_by_temperature"]
    t = np.array([r["temperature_c"] for r in rows])
    mean = np.array([r[f"dark_current_{unit}_per_s"] for r in rows])
    std = np.array([r[f"dark_current_{unit}_per_s_std"] for r in rows])
    fig = Figure(figsize=FIGSIZE)
    ax = fig.subplots()
    ax.errorbar(t, mean, yerr=std, fmt="o-", ms=4, capsize=3, label="from mean")
    var = np.array([r[f"dark_current_var_{unit}_per_s"] for r in rows])
    ax.plot(t, var, "s--", ms=3, label="from variance")
    ax.set_yscale("log")
    ax.set(
        xlabel="temperature [°C]",
        ylabel=f"dark current [{unit}-/s]" if unit == "e" else "dark current [p/s]",
        title="Dark current against temperature",
    )
    ax.legend(fontsize=10)
    fig.tight_layout()
    return fig


def plot_spatial_variances(result: EmvaResult) -> Figure:
    """§4.3 at every illumination step: the row, column and pixel parts of the highpassed spatial variance (bright
    and dark) against μ_y − μ_y.dark, signed on a linear axis [DN²]: a part estimated below zero (noise in a
    difference of variances) is drawn where it is, not left out."""
    c = result.curves
    fig = Figure(figsize=FIGSIZE)
    ax = fig.subplots()
    x = c["signal_dn"]
    for name, color in (("pixel", PALETTE["blue"]), ("row", PALETTE["orange"]), ("col", PALETTE["green"])):
        ax.plot(x, c["spatial_split"].part(name), "o-", ms=2.5, color=color, label=f"s²_y.{name}")
        ax.plot(x, c["dark_spatial_split"].part(name), ":", color=color, label=f"s²_y.{name}.dark")
    ax.axhline(0.0, color="0.6", lw=0.8)
    ax.axvline(x[c["sat"]], **SAT_STYLE, label="saturation")
    ax.set(
        xlabel="mean − dark value μ_y − μ_y.dark [DN]",
        ylabel="spatial variance part [DN²]",
        title="Spatial nonuniformity at every step (highpassed, eq. 44)",
    )
    ax.legend(fontsize=9.5, ncol=2)
    fig.tight_layout()
    return fig


def _images(result: EmvaResult) -> ImageAnalysis:
    """The analysis of the nonuniformity images, which the spectrogram, profile and histogram figures draw
    (`figure_makers` lists them only when the result has it)."""
    if result.images is None:
        raise ConfigError("figure", None, "needs the nonuniformity stacks' mean images, which the result lacks")
    return result.images


def _spectrogram(spectrograms: dict, level_lines: list[tuple[float | None, str]], unit: str, title: str) -> Figure:
    fig = Figure(figsize=(6.4, 6.0))
    axes = fig.subplots(2, 1)
    for ax, name in zip(axes, ("horizontal", "vertical"), strict=True):
        freq, amp = spectrograms[name]
        ax.plot(freq[1:], amp[1:], "-", lw=0.9, label="√P")
        top = float(amp[1:].max())
        for level, label in level_lines:
            if level is not None and level > 0:
                ax.axhline(level, ls="--", lw=1, color="tab:red" if "1288" in label else "0.4", label=label)
                top = max(top, level)
        ax.set_ylim(0, 1.15 * top)
        ax.set(
            xlabel="spatial frequency [cycles/pixel]",
            ylabel=f"standard deviation [{unit}]",
            title=f"{title}: {name} spectrogram",
        )
        ax.legend(fontsize=9.5)
    fig.tight_layout()
    return fig


def plot_dsnu_spectrogram(result: EmvaResult) -> Figure:
    """Fig. 12: horizontal and vertical spectrograms of the highpassed DSNU image, with DSNU₁₂₈₈ and the temporal
    noise σ_y.stack.dark of a single image as lines [DN]."""
    v, stack = result.values, _images(result)
    sigma = (
        np.sqrt(v["spatial_variances"]["dark_stack_var"])
        if "dark_stack_var" in (v["spatial_variances"] or {})
        else None
    )
    return _spectrogram(
        stack.dsnu_spectrograms,
        [
            (v["dsnu_dn"], f"DSNU1288 {_fmt(v['dsnu_dn'], '.3g')} DN"),
            (sigma, f"σ_y.stack.dark {_fmt(sigma, '.3g')} DN"),
        ],
        "DN",
        "DSNU",
    )


def plot_prnu_spectrogram(result: EmvaResult) -> Figure:
    """Fig. 13: spectrograms of the highpassed PRNU image in percent of the mean, with PRNU₁₂₈₈ and σ_y.stack/μ."""
    v, stack = result.values, _images(result)
    sigma = None
    if v["spatial_variances"] and "bright_stack_var" in v["spatial_variances"]:
        sigma = 100 * np.sqrt(v["spatial_variances"]["bright_stack_var"]) / stack.signal_dn
    return _spectrogram(
        stack.prnu_spectrograms,
        [
            (v["prnu_percent"], f"PRNU1288 {_fmt(v['prnu_percent'], '.3g')} %"),
            (sigma, f"σ_y.stack {_fmt(sigma, '.3g')} %"),
        ],
        "%",
        "PRNU",
    )


def _profiles(profiles: dict, title: str, lower_upper) -> Figure:
    fig = Figure(figsize=(6.4, 6.0))
    axes = fig.subplots(2, 1)
    for ax, name, axis in zip(axes, ("horizontal", "vertical"), ("column index n", "row index m"), strict=True):
        prof = profiles[name]
        for key, color in (("max", "tab:red"), ("mean", "tab:blue"), ("middle", "0.3"), ("min", "tab:green")):
            ax.plot(prof[key], lw=0.8, color=color, label=key)
        ax.set_ylim(*lower_upper(prof))
        ax.set(xlabel=axis, ylabel="[DN]", title=f"{title}: {name} profile")
        ax.legend(fontsize=9.5, ncol=4)
    fig.tight_layout()
    return fig


def plot_dsnu_profiles(result: EmvaResult) -> Figure:
    """Fig. 14 for ⟨y_dark⟩ (unfiltered): range 0.9 × mean of the minimum line … 1.1 × mean of the maximum line
    (§8.7)."""
    return _profiles(
        _images(result).dsnu_profiles,
        "DSNU",
        lambda p: (0.9 * float(np.mean(p["min"])), 1.1 * float(np.mean(p["max"]))),
    )


def plot_prnu_profiles(result: EmvaResult) -> Figure:
    """Fig. 14 for ⟨y_50⟩ − ⟨y_dark⟩ (unfiltered): range 0.9 … 1.1 × the mean (§8.7)."""
    return _profiles(
        _images(result).prnu_profiles,
        "PRNU",
        lambda p: (0.9 * float(np.mean(p["mean"])), 1.1 * float(np.mean(p["mean"]))),
    )


def _histograms(histograms: dict, title: str, spread: str) -> Figure:
    fig = Figure(figsize=(6.4, 6.0))
    (ax, bx) = fig.subplots(2, 1)
    log = histograms["log"]
    ax.semilogy(log.centres_dn, np.maximum(log.counts, 1e-1), "-", drawstyle="steps-mid", label="data")
    ax.semilogy(log.centres_dn, log.model, "--", color="tab:red", label=f"normal, {spread}")
    ax.set_ylim(bottom=0.5)
    ax.set(xlabel="deviation from the mean [DN]", ylabel="pixels per bin", title=f"Logarithmic histogram {title}")
    ax.legend(fontsize=9.5)
    acc = histograms["accumulated"]
    bx.semilogy(acc.centres_dn, np.maximum(acc.counts, 1e-4), "-", drawstyle="steps-mid")
    bx.set_ylim(bottom=100.0 / max(1, 10 * acc.counts.size) / 10)
    bx.set(
        xlabel="absolute deviation from the mean [DN]",
        ylabel="pixels deviating at least this much [%]",
        title=f"Accumulated logarithmic histogram {title}",
    )
    fig.tight_layout()
    return fig


def plot_dsnu_histograms(result: EmvaResult) -> Figure:
    """Figs. 15a and 16a: logarithmic and accumulated histograms of the highpassed DSNU image."""
    hist = _images(result).dsnu_histograms
    return _histograms(hist, "DSNU", f"s_nw = {hist['log'].spread_dn:.3g} DN")


def plot_prnu_histograms(result: EmvaResult) -> Figure:
    """Figs. 15b and 16b: logarithmic and accumulated histograms of the highpassed PRNU image."""
    hist = _images(result).prnu_histograms
    return _histograms(hist, "PRNU", f"s_nw = {hist['log'].spread_dn:.3g} DN")


def figure_makers(result: EmvaResult) -> list[tuple[str, Callable[[EmvaResult], Figure]]]:
    """(name, ``plot_*`` function) of every figure the result has data for, in the datasheet's order."""
    v = result.values
    linear = v["model"] == "linear"
    makers: list[tuple[str, Callable[[EmvaResult], Figure]]] = [
        ("photon_transfer", plot_photon_transfer) if linear else ("characteristic", plot_characteristic),
        ("snr", plot_snr),
    ]
    if linear:
        makers.append(("linearity", plot_linearity))
    makers += [("stability", plot_stability), ("dark_current", plot_dark_current)]
    if len(v["dark_current_by_temperature"]) >= 2:
        makers.append(("dark_current_temperature", plot_dark_temperature))
    if np.isfinite(result.curves["spatial_split"].total).any():
        makers.append(("spatial_variances", plot_spatial_variances))
    if result.images is not None:
        makers += [
            ("dsnu_spectrogram", plot_dsnu_spectrogram),
            ("prnu_spectrogram", plot_prnu_spectrogram),
            ("dsnu_profiles", plot_dsnu_profiles),
            ("prnu_profiles", plot_prnu_profiles),
            ("dsnu_histograms", plot_dsnu_histograms),
            ("prnu_histograms", plot_prnu_histograms),
        ]
    return makers


def figure_names(result: EmvaResult) -> list[str]:
    """The names of `figure_makers` (the files are ``NAME.png``)."""
    return [name for name, _ in figure_makers(result)]


def figures(result: EmvaResult) -> DrawnOnDemand:
    """Every figure of `figure_makers` by name, each drawn when first asked for."""
    return DrawnOnDemand((name, functools.partial(make, result)) for name, make in figure_makers(result))


def figure_pngs(result: EmvaResult) -> dict[str, bytes]:
    """Every figure of `figures` as PNG (`uwlab.experiments.figures.figure_png`): the files ``NAME.png`` and the
    datasheet's images."""
    return {name: figure_png(fig) for name, fig in figures(result).items()}
