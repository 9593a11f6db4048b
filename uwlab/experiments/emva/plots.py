"""EMVA 1288 figures (PNG): photon transfer, SNR, linearity, dark current (Release 4.0 linear)."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from uwlab.experiments.emva.analysis import EmvaResult  # noqa: E402
from uwlab.experiments.figures import save_figure  # noqa: E402
from uwlab.model.sensor import snr  # noqa: E402

PLOT_NAMES = ("photon_transfer.png", "snr.png", "linearity.png", "dark_current.png")


def plot_photon_transfer(result: EmvaResult, path: Path) -> Path:
    c, v = result.curves, result.values
    fig, ax = plt.subplots(figsize=(7, 4.5))
    ax.plot(c["signal_dn"], c["signal_var_dn2"], "o", ms=3, label="measured")
    ax.plot(c["signal_dn"][c["fit_idx"]], c["signal_var_dn2"][c["fit_idx"]], "o", ms=4, label="fit range (0-70 %)")
    x = np.linspace(0, c["signal_dn"][c["sat"]], 50)
    ax.plot(x, v["K_dn_per_e"] * x, "-", label=f"K = {v['K_dn_per_e']:.4g} DN/e-")
    ax.axvline(c["signal_dn"][c["sat"]], ls=":", color="grey", label="saturation")
    ax.set(xlabel="μ_y − μ_y,dark [DN]", ylabel="σ²_y − σ²_y,dark [DN²]", title="Photon transfer")
    ax.legend()
    return save_figure(fig, path)


def plot_snr(result: EmvaResult, path: Path) -> Path:
    c, v = result.curves, result.values
    ok = c["photons"] > 0
    fig, ax = plt.subplots(figsize=(7, 4.5))
    ax.loglog(c["photons"][ok], c["snr"][ok], "o", ms=3, label="measured")
    p = np.geomspace(max(v["sensitivity_threshold_photons"] / 2, 1e-3), v["saturation_photons"], 100)
    eta, sigma_d = v["quantum_efficiency"], v["dark_noise_e"]
    ax.loglog(p, snr(eta * p, sigma_d, v["K_dn_per_e"]), "-", label=f"model (η = {eta:.3f}, σ_d = {sigma_d:.3g} e-)")
    ax.loglog(p, np.sqrt(eta * p), ":", label="ideal (shot noise only)")
    ax.axhline(1.0, color="grey", lw=0.8)
    ax.set(xlabel="μ_p [photons/pixel]", ylabel="SNR", title="Signal-to-noise ratio")
    ax.legend()
    return save_figure(fig, path)


def plot_linearity(result: EmvaResult, path: Path) -> Path:
    c, v = result.curves, result.values
    fig, (ax, bx) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    ax.plot(c["photons"], c["signal_dn"], "o", ms=3, label="measured")
    ax.plot(c["photons"], c["linearity_fit_dn"], "-", label="fit (5-95 %)")
    ax.set(ylabel="μ_y − μ_y,dark [DN]", title=f"Linearity: LE = {v['linearity_error_percent']:.3g} %")
    ax.legend()
    idx = c["lin_idx"]
    bx.plot(c["photons"][idx], c["linearity_dev_percent"][idx], "o-", ms=3)
    bx.set(xlabel="μ_p [photons/pixel]", ylabel="deviation [%]")
    return save_figure(fig, path)


def plot_dark_current(result: EmvaResult, path: Path) -> Path:
    c, v = result.curves, result.values
    fig, ax = plt.subplots(figsize=(7, 4.5))
    t = c["dark_exposure_s"]
    ax.plot(t * 1e3, c["dark_mean_dn"], "o", ms=3, label="μ_y,dark")
    if v["dark_current_e_per_s"] is not None:
        slope, offset = np.polyfit(t, c["dark_mean_dn"], 1)
        ax.plot(t * 1e3, slope * t + offset, "-", label=f"{v['dark_current_e_per_s']:.4g} e-/s")
    ax.set(xlabel="exposure [ms]", ylabel="mean dark signal [DN]", title="Dark current")
    ax.legend()
    return save_figure(fig, path)


def write_plots(result: EmvaResult, out_dir: Path) -> list[Path]:
    """The four figures into ``out_dir`` (names `PLOT_NAMES`)."""
    makers = (plot_photon_transfer, plot_snr, plot_linearity, plot_dark_current)
    return [make(result, out_dir / name) for make, name in zip(makers, PLOT_NAMES)]
