"""Figures of a traced port (`uwlab.model.port_field.trace_design`): the distortion it adds and the paraxial rule's
error across the field, and where the lens must focus across the field (virtual image, depth of field); `Figure`
objects (`port_figures`) that ``uwlab port trace --plot`` writes as PNG files."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from uwlab.experiments.figures import Figure, save_figure

_STYLE = {
    "x": ("tab:blue", "along x (to the edge)"),
    "y": ("tab:green", "along y"),
    "diagonal": ("tab:red", "diagonal (to the corner)"),
}


def _port_label(design) -> str:
    h = design.values["housing"]
    if h["port"] == "dome":
        dx, dy, dz = h["dome_decenter_mm"]
        return (
            f"dome R {h['dome_radius_mm']:g} mm, t {h['dome_thickness_mm']:g} mm, decentred ({dx:g}, {dy:g}, {dz:g}) mm"
        )
    tx, ty = h["flat_tilt_deg"]
    return f"flat port t {h['flat_thickness_mm']:g} mm, air gap {h['flat_air_gap_mm']:g} mm, tilt ({tx:g}, {ty:g})°"


def plot_distortion(design, trace: dict) -> Figure:
    """Distortion the port adds [%] and the paraxial rule's image error [px] against the field angle in air."""
    profile = trace["profile"]
    fig = Figure(figsize=(11, 4.5))
    (a1, a2) = fig.subplots(1, 2)
    for name, (colour, label) in _STYLE.items():
        angle = profile["field_deg_air"][name]
        a1.plot(angle, profile["distortion_percent"][name], color=colour, label=label)
        a2.plot(profile["image_radius_px"][name], profile["distortion_px"][name], color=colour, label=label)
    a1.axhline(0.0, color="grey", linewidth=0.8)
    a2.axhline(0.0, color="grey", linewidth=0.8)
    a1.set(
        xlabel="field angle in air [deg]",
        ylabel="radial distortion added by the port [%]",
        title="Distortion the port adds (objects at infinity)",
    )
    a2.set(
        xlabel="image radius [px]",
        ylabel="image displacement [px]",
        title=f"Image error of a pinhole with f_uw = {trace['focal_ratio']:.4g}·f",
    )
    a1.legend(fontsize=8)
    fov, par = trace["fov_deg"], trace["paraxial_fov_deg"]
    fig.suptitle(
        f"{_port_label(design)} — FOV {fov['x']:.2f} × {fov['y']:.2f}° exact, "
        f"{par['x']:.2f} × {par['y']:.2f}° paraxial; corner distortion "
        f"{trace['distortion_percent']['corner']:+.2f} % ({trace['distortion_px']['corner']:+.1f} px)",
        fontsize=9,
    )
    fig.tight_layout()
    return fig


def plot_focus(design, trace: dict) -> Figure:
    """Axial distance of the virtual image of the target plane against the field angle (tangential and sagittal),
    with the lens's focus setting, its depth of field in image space and its closest focus."""
    profile, aid = trace["profile"], trace["focus"]
    fig = Figure(figsize=(8, 5))
    ax = fig.subplots()
    for name in ("x", "diagonal"):
        colour, label = _STYLE[name]
        angle = profile["field_deg_air"][name]
        ax.plot(angle, profile["virtual_image_tangential_m"][name] * 1e3, color=colour, label=f"tangential, {label}")
        ax.plot(
            angle,
            profile["virtual_image_sagittal_m"][name] * 1e3,
            color=colour,
            linestyle="--",
            label=f"sagittal, {label}",
        )
    near, far = aid["image_dof_m"]["near"], aid["image_dof_m"]["far"]
    top = far if np.isfinite(far) else ax.get_ylim()[1] / 1e3
    ax.axhspan(near * 1e3, top * 1e3, color="tab:orange", alpha=0.15, label="depth of field (image space, in air)")
    ax.axhline(aid["image_distance_m"] * 1e3, color="black", linewidth=1, label="focus on the axial image")
    min_focus = design["lens.min_focus_distance_m"]
    if min_focus is not None:
        ax.axhline(min_focus * 1e3, color="grey", linestyle=":", label=f"lens closest focus {min_focus * 1e3:.0f} mm")
    ax.set(xlabel="field angle in air [deg]", ylabel="virtual image distance from the entrance pupil [mm]")
    verdict = (
        f"edge {'IN' if aid['edge_in_focus'] else 'OUT of'} focus, "
        f"corner {'IN' if aid['corner_in_focus'] else 'OUT of'} focus"
    )
    close_up = f" with a +{aid['close_up_lens_dpt']:.2f} dpt close-up lens" if aid["close_up_lens_dpt"] else ""
    ax.set_title(
        f"{_port_label(design)}\ntarget at {design['operation.altitude_m']:g} m: lens set to "
        f"{aid['setting_m'] * 1e3:.0f} mm{close_up}, f/{design['lens.f_number']:g} — {verdict}",
        fontsize=9,
    )
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    return fig


def port_figures(design, trace: dict) -> dict[str, Figure]:
    """Both port figures of a traced design by name (``port_distortion``, ``port_focus``)."""
    return {"port_distortion": plot_distortion(design, trace), "port_focus": plot_focus(design, trace)}


def write_trace_plots(design, trace: dict, out_dir: Path) -> list[Path]:
    """Both port figures into out_dir (an existing, writable folder) as ``NAME.png``."""
    return [save_figure(fig, out_dir / f"{name}.png") for name, fig in port_figures(design, trace).items()]
