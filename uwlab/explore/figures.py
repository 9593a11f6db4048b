"""The paper's design figures as interactive Plotly figures, drawn from the same data as the PNG figures of
`uwlab design --plot` (`uwlab.experiments.design.curves`, `uwlab.model.design.stage_spectra`), with the current
design marked; and the sweep panel's figure.

Figures are Plotly figure specifications (``{"data": [traces], "layout": {...}}``, the JSON Plotly.js renders; the
page serves Plotly.js from the installed plotly package). They are written as plain dicts rather than through
``plotly.graph_objects``, whose validation costs ~100 ms per figure and would dominate a live update; the tests
validate every figure with ``plotly.graph_objects.Figure``. The page applies Plotly's ``plotly_white`` template
(`template`). Arrays may hold ``inf`` and ``nan``: `uwlab.jsonable` writes them as null, a gap in a line.
"""

from __future__ import annotations

from functools import cache

import numpy as np

from uwlab.experiments.design.curves import dof_curves, operation_curves, quantum_efficiency, water_attenuation
from uwlab.model.design import Design, stage_spectra
from uwlab.model.sensor import SensorProfile
from uwlab.model.water import water_iop

COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf")
DESIGN_MARKER = {"color": "black", "size": 10, "symbol": "circle-open", "line": {"width": 2.5}}
HIGHLIGHT, NORMAL = 3.5, 1.3


@cache
def template() -> dict:
    """Plotly's ``plotly_white`` template, as the page applies it to every figure."""
    import plotly.io as pio

    return pio.templates["plotly_white"].to_plotly_json()


def line(x, y, name: str, colour: str, width: float = 1.8, dash: str = "solid", axes: int = 1, **extra) -> dict:
    """A line trace on subplot `axes` (1: x/y, 2: x2/y2, ...)."""
    suffix = "" if axes == 1 else str(axes)
    return {
        "type": "scatter",
        "mode": "lines",
        "x": x,
        "y": y,
        "name": name,
        "xaxis": "x" + suffix,
        "yaxis": "y" + suffix,
        "line": {"color": colour, "width": width, "dash": dash},
        **extra,
    }


def marker(x: float, y: float, axes: int = 1, legend: bool = True) -> dict:
    suffix = "" if axes == 1 else str(axes)
    return {
        "type": "scatter",
        "mode": "markers",
        "x": [x],
        "y": [y],
        "name": "this design",
        "marker": DESIGN_MARKER,
        "xaxis": "x" + suffix,
        "yaxis": "y" + suffix,
        "showlegend": legend,
    }


def axis(title: str, log: bool = False, **extra) -> dict:
    return {
        "title": {"text": title, "font": {"size": 11}},
        "type": "log" if log else "linear",
        "exponentformat": "power",
        **extra,
    }


def layout(title: str, height: int, **axes) -> dict:
    return {
        "title": {"text": title, "font": {"size": 13}, "x": 0.01, "y": 0.985},
        "height": height,
        "margin": {"l": 64, "r": 14, "t": 42, "b": 44},
        "font": {"size": 11},
        "hovermode": "closest",
        "legend": {"font": {"size": 10}, "bgcolor": "rgba(255,255,255,0.75)"},
        **axes,
    }


def side_by_side(left: tuple[dict, dict], right: tuple[dict, dict], titles: tuple[str, str], gap: float = 0.1) -> dict:
    """Axes of two subplots in a row: ((x, y) of the left, (x, y) of the right) and their titles."""
    half = (1 - gap) / 2
    (x1, y1), (x2, y2) = left, right
    notes = [
        {
            "text": t,
            "showarrow": False,
            "xref": "paper",
            "yref": "paper",
            "x": x,
            "y": 1.0,
            "yanchor": "bottom",
            "xanchor": "center",
            "font": {"size": 11},
        }
        for t, x in zip(titles, (half / 2, 1 - half / 2), strict=True)
    ]
    return {
        "xaxis": {**x1, "domain": [0, half], "anchor": "y"},
        "yaxis": {**y1, "anchor": "x"},
        "xaxis2": {**x2, "domain": [1 - half, 1], "anchor": "y2"},
        "yaxis2": {**y2, "anchor": "x2"},
        "annotations": notes,
    }


def dof_figure(design: Design) -> dict:
    curves = dof_curves(design)
    n_design, altitude = float(design["lens.f_number"]), float(design["operation.altitude_m"])
    data = []
    for i, (s, near, far) in enumerate(zip(curves["focus_m"], curves["near_m"], curves["far_m"], strict=True)):
        width = HIGHLIGHT if np.isclose(s, altitude) else NORMAL
        data.append(line(curves["f_number"], far, f"focus {s:.3g} m", COLOURS[i], width, legendgroup=str(i)))
        data.append(
            line(
                curves["f_number"],
                near,
                f"near, focus {s:.3g} m",
                COLOURS[i],
                width,
                "dash",
                legendgroup=str(i),
                showlegend=False,
            )
        )
    distance = curves["distance_m"]
    data += [
        line(distance, curves["far_at_distance_m"], "far limit", "#444", 2, axes=2, showlegend=False),
        line(
            distance,
            curves["near_at_distance_m"],
            "near limit",
            "#444",
            2,
            "dash",
            axes=2,
            showlegend=False,
            fill="tonexty",
            fillcolor="rgba(31,119,180,0.15)",
        ),
        line(distance, distance, "focus distance", "#999", 1, "dot", axes=2, showlegend=False),
        marker(n_design, altitude),
        marker(altitude, altitude, axes=2, legend=False),
    ]
    axes = side_by_side(
        (axis("f-number N", log=True), axis("object distance in water [m]", log=True)),
        (axis("focus distance in water [m]", log=True), axis("", log=True)),
        (
            "limits against the f-number (far solid, near dashed)",
            f"in focus (shaded) against the focus distance, N = {n_design:g}",
        ),
    )
    return {"data": data, "layout": layout("Depth of field", 360, **axes)}


STAGES = (
    ("source_w_nm", "source Φe", "W/nm"),
    ("target_irradiance_w_m2_nm", "at target E_t", "W/m²/nm"),
    ("return_radiance_w_m2_sr_nm", "at camera L_w", "W/m²/sr/nm"),
    ("sensor_irradiance_w_m2_nm", "on sensor E_s", "W/m²/nm"),
    ("absorbed_w_m2_nm", "absorbed E_s·η", "W/m²/nm"),
)


def spectra_figure(design: Design) -> dict:
    spectra = stage_spectra(design)
    n, gap = len(STAGES), 0.03
    height = (1 - gap * (n - 1)) / n
    data, axes = [], {}
    for i, (key, label, unit) in enumerate(STAGES):
        suffix = "" if i == 0 else str(i + 1)
        data.append(
            line(
                spectra["wavelength_nm"],
                spectra[key],
                label,
                COLOURS[i],
                axes=i + 1,
                showlegend=False,
                hovertemplate=f"%{{x:.0f}} nm: %{{y:.4g}} {unit}<extra>{label}</extra>",
            )
        )
        top = 1 - i * (height + gap)
        axes["yaxis" + suffix] = {**axis(f"{label}<br>[{unit}]"), "domain": [top - height, top], "anchor": "x" + suffix}
        axes["xaxis" + suffix] = {
            **axis("wavelength [nm]" if i == n - 1 else ""),
            "anchor": "y" + suffix,
            "showticklabels": i == n - 1,
            **({"matches": "x"} if i else {}),
        }
    return {"data": data, "layout": layout("Spectrum along the on-axis chain", 580, **axes)}


def operation_figure(design: Design, result: dict) -> dict:
    curves = operation_curves(design)
    altitude, speed = float(design["operation.altitude_m"]), float(design["operation.speed_m_s"])
    data = []
    for i, (h, framerate, exposure) in enumerate(
        zip(curves["altitude_m"], curves["min_framerate_hz"], curves["max_exposure_s"], strict=True)
    ):
        width = HIGHLIGHT if np.isclose(h, altitude) else NORMAL
        data.append(line(curves["speed_m_s"], framerate, f"altitude {h:.3g} m", COLOURS[i], width, legendgroup=str(i)))
        data.append(
            line(
                curves["speed_m_s"],
                np.asarray(exposure) * 1e3,
                f"altitude {h:.3g} m",
                COLOURS[i],
                width,
                axes=2,
                legendgroup=str(i),
                showlegend=False,
            )
        )
    if speed > 0:
        data += [marker(speed, result["min_framerate_hz"]), marker(speed, result["max_exposure_s"] * 1e3, 2, False)]
    exposure_ms = result["exposure_s"] * 1e3
    data.append(
        line(
            [curves["speed_m_s"][0], curves["speed_m_s"][-1]],
            [exposure_ms, exposure_ms],
            f"exposure {exposure_ms:.3g} ms",
            "#d62728",
            1.5,
            "dot",
            axes=2,
        )
    )
    axes = side_by_side(
        (axis("vehicle speed [m/s]"), axis("framerate [Hz]")),
        (axis("vehicle speed [m/s]"), axis("exposure [ms]", log=True)),
        ("minimum framerate for the overlap", "maximum exposure for the blur limit"),
    )
    return {"data": data, "layout": layout("Framerate and exposure limits", 340, **axes)}


def water_figure(design: Design) -> dict:
    nm, chosen = design.grid.nm, design["water.type"]
    data = [
        line(nm, c, name, COLOURS[i % len(COLOURS)], HIGHLIGHT if name == chosen else NORMAL)
        for i, (name, c) in enumerate(water_attenuation(design.grid).items())
    ]
    scale = float(design["water.attenuation_scale"])
    data.append(
        line(nm, water_iop(chosen, design.grid).c_per_m * scale, f"this design (× {scale:g})", "black", 2, "dot")
    )
    return {
        "data": data,
        "layout": layout(
            "Water attenuation",
            290,
            xaxis=axis("wavelength [nm]"),
            yaxis=axis("beam attenuation c = a + b [1/m]", log=True),
        ),
    }


def qe_figure(design: Design, extra: tuple[SensorProfile, ...] = ()) -> dict:
    data = [
        line(nm, qe, name, COLOURS[i % len(COLOURS)], HIGHLIGHT if name == design.sensor.name else NORMAL)
        for i, (name, (nm, qe)) in enumerate(quantum_efficiency((*extra, design.sensor)).items())
    ]
    return {
        "data": data,
        "layout": layout(
            "Sensor quantum efficiency (mono / combined)",
            290,
            xaxis=axis("wavelength [nm]"),
            yaxis=axis("quantum efficiency η"),
        ),
    }


def budget_figure(stage_rows: list, worst: str, stops: dict) -> dict:
    """Light lost per stage [stops] as horizontal bars in chain order, the largest loss highlighted."""
    labels = [row.label for row in stage_rows][::-1]
    values = [stops[row.key] for row in stage_rows][::-1]
    colours = ["#d62728" if row.key == worst else "#1f77b4" for row in stage_rows][::-1]
    bars = {
        "type": "bar",
        "orientation": "h",
        "x": values,
        "y": labels,
        "marker": {"color": colours},
        "text": [row.text for row in stage_rows][::-1],
        "textposition": "outside",
        "cliponaxis": False,
        "hovertemplate": "%{y}: %{x:.2f} stops<extra></extra>",
        "name": "stops lost",
    }
    return {
        "data": [bars],
        "layout": {
            **layout("", 250, xaxis=axis("light lost [stops]"), yaxis={"automargin": True}),
            "margin": {"l": 10, "r": 40, "t": 8, "b": 40},
        },
    }


def design_figures(design: Design, result: dict, extra_sensors: tuple[SensorProfile, ...] = ()) -> dict[str, dict]:
    """The page's figures by name: dof, spectra, operation, water, qe."""
    return {
        "dof": dof_figure(design),
        "spectra": spectra_figure(design),
        "operation": operation_figure(design, result),
        "water": water_figure(design),
        "qe": qe_figure(design, extra_sensors),
    }


def sweep_figure(axes: dict[str, list], values: np.ndarray, output: str, label: str, unit: str) -> dict:
    """One key: the output against it (a line, or bars over words); two keys: a heatmap of the output."""
    keys = list(axes)
    title = f"{label} [{unit}]" if unit else label
    numeric = [all(isinstance(v, (int, float)) for v in axes[k]) for k in keys]
    if len(keys) == 1:
        x = axes[keys[0]]
        kind = {"type": "scatter", "mode": "lines+markers", "marker": {"size": 4}} if numeric[0] else {"type": "bar"}
        trace = kind | {
            "x": x,
            "y": values,
            "name": output,
            "hovertemplate": f"{keys[0]} = %{{x}}<br>{output} = %{{y:.4g}}<extra></extra>",
        }
        return {"data": [trace], "layout": layout(f"Sweep: {title}", 380, xaxis=axis(keys[0]), yaxis=axis(title))}
    heat = {
        "type": "heatmap",
        "x": axes[keys[1]],
        "y": axes[keys[0]],
        "z": values,
        "colorscale": "Viridis",
        "colorbar": {"title": {"text": title, "side": "right"}},
        "hovertemplate": f"{keys[1]} = %{{x}}<br>{keys[0]} = %{{y}}<br>{output} = %{{z:.4g}}<extra></extra>",
    }
    return {"data": [heat], "layout": layout(f"Sweep: {title}", 420, xaxis=axis(keys[1]), yaxis=axis(keys[0]))}
