"""The validation report: one self-contained HTML file (figures embedded as PNG data URIs), rendered with jinja2
from ``templates/report.html.j2``.

`write_report(root, out)` looks under `root` (depth ≤ 2) for datasets (``metadata.json`` + ``manifest.json``),
calibrations (``summary.json`` + ``samples.parquet`` from `uwlab fit`) and EMVA 1288 characterisations
(``emva.json``), and reports: first the verdict of every calibration (adequate or not, the failing checks and the
likely causes, `uwlab.experiments.calibration.adequacy`), then the set-up in words, per calibration its checks,
the measured against predicted response per configuration with residuals in per cent and the fitted and held-out
95 % bands, the held-out table, the posterior beside the simulated truth, the posterior predictive checks per
configuration and the spectra; the EMVA summary; the provenance: what made the report and each dataset, fit and
characterisation (uwlab and its commit, Python, the numerical packages, the BLAS and its threads, the CPU:
`uwlab.provenance`), and every dataset's plan, host, times and devices.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pandas as pd
from jinja2 import Environment, PackageLoader, StrictUndefined

from uwlab.errors import ConfigError, UwlabError
from uwlab.experiments.dataset import Dataset, read_metadata
from uwlab.experiments.geometry import GEOMETRY_FIGURE, GEOMETRY_FILE
from uwlab.experiments.figures import LABEL_PT, PALETTE, TICK_PT, Figure, figure_png, number_text, png_data_uri
from uwlab.jsonable import to_jsonable
from uwlab.outputs import MANIFEST_FILE, METADATA_FILE, output_file
from uwlab.provenance import provenance, provenance_line
from uwlab.experiments.calibration.adequacy import SWEPT_LABELS
from uwlab.experiments.calibration.forward import PERCENT_PARAMETERS, parameter_label
from uwlab.experiments.calibration.output import configuration_label
from uwlab.model.bench import is_bench
from uwlab.model.data import MAX_BINARY_BYTES, MAX_TOML_BYTES, check_input_file, read_bytes, read_json, read_text
from uwlab.model.optics import BARE_SENSOR_F_NUMBER

EFFECT_NAMES = {
    "beam_profile": "the light's smooth beam",
    "vignetting": "vignetting",
    "lens_transmission": "a spectral lens transmittance",
    "backscatter": "backscatter",
    "stray_light": "stray light from the walls",
    "warmup_drift": "the light's warm-up drift",
    "sensor_realism": "sensor non-linearity, hot pixels, DSNU and PRNU",
}


def _find(root: Path, marker: str, also: str | None = None) -> list[Path]:
    found = [
        p.parent
        for p in sorted(root.glob(marker)) + sorted(root.glob(f"*/{marker}")) + sorted(root.glob(f"*/*/{marker}"))
    ]
    return [p for p in dict.fromkeys(found) if also is None or (p / also).exists()]


def _img(path: Path) -> str:
    return png_data_uri(read_bytes(path, "report", MAX_BINARY_BYTES, "PNG"))


def _table(path: Path) -> pd.DataFrame:
    """A Parquet table of a fit directory, the path checked as every input is (a regular file, bounded)."""
    return pd.read_parquet(check_input_file(path, "report", MAX_BINARY_BYTES, "Parquet"))


def _number(value, digits: int = 4) -> str:
    return number_text(value, f".{digits}g")


def _percent(value, digits: int = 1) -> str:
    return "—" if value is None or not np.isfinite(value) else f"{100 * value:.{digits}f} %"


def _value(name: str, value) -> str:
    return _percent(value, 2) if name in PERCENT_PARAMETERS else _number(value)


def _trend(row: dict) -> str:
    """A configuration's residual trend, "+0.6 → −0.6 % (exposure 20–462 µs)", or "—" for a fit written before
    the trend check (or a sweep with fewer than 4 values)."""
    start, end, variable = row.get("trend_start_percent"), row.get("trend_end_percent"), row.get("trend_variable")
    if start is None or end is None or variable is None:
        return "—"
    name, unit = SWEPT_LABELS.get(variable, (variable, ""))
    span = f"{row['trend_low']:.3g}–{row['trend_high']:.3g}{' ' + unit if unit else ''}"
    return f"{start:+.2f} → {end:+.2f} % ({name} {span})"


def _is_bare(lens: dict) -> bool:
    return lens.get("f_number") is not None and lens["f_number"] <= BARE_SENSOR_F_NUMBER


def _lens(lens: dict) -> str:
    return "none (bare sensor)" if _is_bare(lens) else f"{lens['focal_length_mm']:g} mm f/{lens['f_number']:g}"


def _label(sweep_id: str, rig: dict) -> str:
    if is_bench(rig):
        return f"{sweep_id} (EMVA 1288 bench)"
    lens = rig.get("lens", {})
    bare = _is_bare(lens)
    return configuration_label(
        rig.get("sensor", {}).get("profile", sweep_id),
        None if bare else lens.get("focal_length_mm"),
        None if bare else lens.get("f_number"),
    )


def _light(rig: dict) -> str:
    light = rig.get("light", {})
    if light.get("beam_half_angle_in_air_deg") is not None:
        beam = f"{light['beam_half_angle_in_air_deg']:g}° half-angle in air"
    else:
        beam = f"{light.get('beam_half_angle_deg', 0):g}° half-angle"
    count = light.get("count", 1)
    flux = f"{light.get('luminous_flux_lm', 0):,.0f} lm"
    return f"{count} × {flux}, {beam}, {light.get('beam_model', 'cone')} beam"


def _water(rig: dict) -> str:
    water = rig.get("water", {})
    name = {"pure-fresh": "pure fresh water", "pure-sea": "pure sea water"}.get(
        water.get("type"), str(water.get("type"))
    )
    if water.get("particle_scattering_per_m"):
        name += f" + scatterers b(550 nm) = {water['particle_scattering_per_m']:g} /m"
    if water.get("attenuation_scale", 1.0) != 1.0:
        name += f", attenuation × {water['attenuation_scale']:g}"
    return name


def _port(rig: dict) -> str:
    housing = rig.get("housing", {})
    if housing.get("port") == "dome":
        return f"dome, {housing.get('dome_radius_mm', 0):g} mm radius"
    parts = [f"flat, n = {housing.get('port_index', 1.49):g}"]
    if housing.get("flat_thickness_mm"):
        parts.append(f"{housing['flat_thickness_mm']:g} mm thick")
    if housing.get("flat_air_gap_mm"):
        parts.append(f"{housing['flat_air_gap_mm']:g} mm air gap")
    return ", ".join(parts)


def _bench_row(sweep_id: str, rig: dict, camera: str) -> dict:
    """A set-up row of an EMVA 1288 bench sweep: a bare sensor under a disk source, in air."""
    bench = rig["bench"]
    source = (
        f"disk source Ø {bench.get('source_diameter_mm', 0):g} mm at f/{bench.get('f_number', 0):g}, "
        f"{bench.get('wavelength_nm', 0):g} nm (FWHM {bench.get('fwhm_nm', 0):g} nm)"
    )
    return {
        "configuration": _label(sweep_id, rig),
        "camera": camera,
        "lens": "none (bare sensor)",
        "light": source,
        "light_distance": "—",
        "camera_distance": "—",
        "water": "none (air)",
        "port": "none",
        "reflectance": "—",
    }


def _has_bench(metadata: dict) -> bool:
    return any(is_bench(rig) for rig in (metadata.get("rigs") or {}).values())


def _bench_hint(dataset: Path) -> str:
    """What to run for an EMVA 1288 bench dataset that has no characterisation yet."""
    return (
        f"{dataset} holds an EMVA 1288 bench measurement: `uwlab emva characterize {dataset} --out DIR` writes "
        "its datasheet, which this report then includes."
    )


def _setup(metadata: dict) -> list[dict]:
    devices = metadata.get("devices") or {}
    rows = []
    for sweep_id, rig in (metadata.get("rigs") or {}).items():
        camera = devices.get(sweep_id, {}).get("camera", {})
        model = f"{camera.get('vendor', '')} {camera.get('model', '')}".strip()
        if is_bench(rig):
            rows.append(
                _bench_row(
                    sweep_id,
                    rig,
                    f"{rig.get('sensor', {}).get('profile', '').upper()}" + (f" ({model})" if model else ""),
                )
            )
            continue
        rows.append(
            {
                "configuration": _label(sweep_id, rig),
                "camera": f"{rig.get('sensor', {}).get('profile', '').upper()}" + (f" ({model})" if model else ""),
                "lens": _lens(rig.get("lens", {})),
                "light": _light(rig),
                "light_distance": _number(
                    rig.get("light", {}).get("distance_m") or rig.get("operation", {}).get("altitude_m"), 3
                ),
                "camera_distance": _number(rig.get("operation", {}).get("altitude_m"), 3),
                "water": _water(rig),
                "port": _port(rig),
                "reflectance": _number(rig.get("target", {}).get("reflectance")),
            }
        )
    return rows


def _world(metadata: dict) -> str | None:
    """The simulated world in words (None for a tank's data)."""
    worlds = [t["world"] for t in (metadata.get("sim_truth") or {}).values() if t.get("world")]
    if not metadata.get("sim"):
        return None
    if not worlds:
        return "Simulated rig."
    world = worlds[0]
    if world["preset"] == "ideal":
        return (
            "Simulated rig, ideal world: the paper's model itself renders the images (the model is checked "
            "against itself)."
        )
    effects = [EFFECT_NAMES[e] for e, on in world["effects"].items() if on]
    text = (
        f"Simulated rig, {world['preset']} world: the tank renderer (exact refraction through the wall, the light "
        f"above the camera) with {', '.join(effects) if effects else 'no further effects'}"
    )
    if world.get("particle_scattering_per_m"):
        text += f", and added scatterers, b(550 nm) = {world['particle_scattering_per_m']:g} /m"
    return text + "."


def _world_name(summary: dict) -> str:
    world = summary.get("world")
    if world is None:
        return "this rig" if not summary.get("sim") else "the simulated rig"
    return {
        "ideal": "the ideal simulated rig",
        "tank": "the simulated tank",
        "turbid": "the simulated turbid tank",
    }.get(world, f"the {world} world")


def _sharpness(coverage: dict) -> str:
    """ "±12.9 % for 0.7 % errors (18×); interval score 26 %", or "—" for a fit written before it was measured."""
    half, error = coverage.get("held_out_half_width_percent"), coverage.get("held_out_error_percent")
    if half is None or error is None:
        return "—"
    ratio = coverage.get("held_out_width_over_error")
    score = coverage.get("held_out_interval_score_percent")
    return f"±{half:.2g} % for {error:.2g} % errors ({_number(ratio, 2)}×); interval score {_number(score, 2)} %"


def _headline(summary: dict) -> str:
    coverage = summary["predictive_coverage"]["held_out_inside_95"]
    tau = summary["parameters"].get("config_discrepancy", {}).get("median")
    held = len(summary.get("cross_configuration") or [])
    text = (
        f"Each of the {held} configurations was predicted by a fit that did not see it: "
        f"{_percent(coverage, 0)} of their points lie inside the 95 % bands"
    )
    if tau is not None:
        text += f"; configurations differ from the model by {_percent(tau)} (τ)"
    if summary["model_adequate"]:
        return text + ". Every check passes: the bands of new configurations can be trusted."
    return text + "."


def _calibration(path: Path) -> dict:
    summary = read_json(path / "summary.json", "report")
    points = _table(path / "predictions.parquet")
    metadata = {}
    if summary.get("dataset") and (Path(summary["dataset"]) / METADATA_FILE).exists():
        metadata = read_metadata(Path(summary["dataset"]))[0]
    rigs = metadata.get("rigs") or {}
    label = lambda sweep_id: _label(sweep_id, rigs[sweep_id]) if sweep_id in rigs else sweep_id  # noqa: E731
    failing = [f"{c['name']}: {c['detail']}" for c in summary.get("checks", []) if not c["passed"]]
    folds = {s: f for f in summary.get("folds", []) for s in f["held_out"]}
    held_out = [
        {
            "configuration": label(r["sweep_id"]),
            "trained_on": ", ".join(label(s) for s in folds.get(r["sweep_id"], {}).get("trained_on", [])),
            "points": r["points"],
            "median_error": _percent(r["median_abs_rel_error"], 2),
            "worst_error": _percent(r["max_abs_rel_error"], 2),
            "inside": _percent(r["inside_95"], 0),
            "inside_ok": r["inside_95"] >= 0.75,
            "level": f"{r['level_offset_percent']:+.2f} %",
            "p": _number(r["level_p"], 2),
        }
        for r in summary.get("cross_configuration", [])
    ]
    posterior = []
    for name, p in summary["parameters"].items():
        truth = p.get("truth")
        posterior.append(
            {
                "label": parameter_label(name),
                "truth": _value(name, truth),
                "median": _value(name, p["median"]),
                "interval": f"{_value(name, p['p2_5'])} – {_value(name, p['p97_5'])}",
                "inside": None if truth is None else bool(p["p2_5"] <= truth <= p["p97_5"]),
                "tau": _number(p["tau"], 3),
                "rhat": f"{p['rhat']:.3f}",
            }
        )
    notes = [w for w in summary.get("warnings", []) if not w.startswith(("model inadequate", "likely cause"))]
    notes += [
        f"not separable by these data: {parameter_label(p['a'])} and {parameter_label(p['b'])} (posterior "
        f"correlation {p['rho']:+.2f})"
        for p in summary.get("not_separable", [])
    ]
    ppc = [
        {
            "configuration": label(r["sweep_id"]),
            "points": r["points"],
            "inside": _percent(r["inside_95"], 0),
            "offset": f"{r['offset_percent']:+.2f} %",
            "p": _number(r["ppc_p"], 2),
            "trend": _trend(r),
            "trend_p": _number(r.get("trend_p"), 2),
        }
        for r in summary.get("posterior_predictive_checks", [])
    ]
    delta = summary["parameters"].get("discrepancy", {}).get("median")
    tau = summary["parameters"].get("config_discrepancy", {}).get("median")
    model_name = {"paper": "the paper's model", "extended": "the extended model"}.get(summary.get("model"), "the model")
    spectra = path / "spectra.parquet"
    return {
        "path": str(path),
        "made_with": [(f"fit {path}", _made_with(summary.get("provenance")))],
        "dataset": summary.get("dataset") or "—",
        "adequate": bool(summary.get("model_adequate")),
        "model_name": model_name,
        "world_name": _world_name(summary),
        "headline": _headline(summary),
        "reasons": failing,
        "causes": summary.get("likely_causes", []) if failing else [],
        "coverage": _percent(summary["predictive_coverage"]["held_out_inside_95"], 0),
        "sharpness": _sharpness(summary["predictive_coverage"]),
        "tau": _percent(tau),
        "delta": _percent(delta, 2),
        "converged": "converged" if summary["converged"] else "NOT converged",
        "checks": summary.get("checks", []),
        "response_png": _img(path / "response.png"),
        "held_out": held_out,
        "posterior": posterior,
        "notes": notes,
        "ppc": ppc,
        "sensors": [f"{camera}: {description}" for camera, description in sorted(summary.get("sensors", {}).items())],
        "sampler": (
            f"{summary['steps']} steps × {summary['walkers']} walkers, {summary['tau_multiple']:.0f} "
            f"autocorrelation times, acceptance {summary['acceptance_fraction']:.2f}; "
            f"{summary['points_used']} points fitted, {int(points['saturated'].sum())} saturated points left out"
        ),
        "corner_png": _img(path / "corner.png"),
        "traces_png": _img(path / "traces.png"),
        "spectra_png": (
            png_data_uri(figure_png(plot_spectra(_table(spectra), label), dpi=90, tight_bbox=True))
            if spectra.exists()
            else None
        ),
        "spectra": [
            {
                "configuration": label(r["sweep_id"]),
                "position": r["position"],
                "ratio": _number(r["measured_over_predicted"], 3),
                "shape": _percent(r["shape_rms_error"], 1),
            }
            for r in summary.get("spectra", [])
        ],
    }


SPECTRA_COLUMNS = 3  # ≤ 3 panels across keeps the text ≥ 11 px on the report's 1260 px column


def plot_spectra(frame: pd.DataFrame, label) -> Figure:
    """Predicted (line, on top) and measured (dots) spectra per configuration (a fit's ``spectra.parquet``), at the
    target and at the camera, three configurations across (`uwlab.experiments.figures` rules); `label`: a
    configuration's title from its sweep id."""
    sweeps = list(dict.fromkeys(frame["sweep_id"]))
    blocks = -(-len(sweeps) // SPECTRA_COLUMNS)
    columns = min(SPECTRA_COLUMNS, len(sweeps))
    fig = Figure(figsize=(4.4 * columns, 3.4 * 2 * blocks))
    axes = fig.subplots(2 * blocks, columns, squeeze=False, sharex=True)
    for j, sweep_id in enumerate(sweeps):
        block, column = divmod(j, SPECTRA_COLUMNS)
        for i, position in enumerate(("target", "camera")):
            sel = frame[(frame["sweep_id"] == sweep_id) & (frame["position"] == position)]
            ax = axes[2 * block + i, column]
            if sel["irradiance_w_m2_nm"].notna().any():
                ax.plot(
                    sel["wavelength_nm"],
                    sel["irradiance_w_m2_nm"],
                    "o",
                    markersize=2.5,
                    color=PALETTE["orange"],
                    label="measured",
                    zorder=2,
                )
            ax.plot(
                sel["wavelength_nm"],
                sel["predicted_w_m2_nm"],
                color=PALETTE["blue"],
                linewidth=1.6,
                label="predicted",
                zorder=3,
            )
            ax.set_title(f"{label(sweep_id)}, at the {position}", fontsize=TICK_PT)
            ax.tick_params(labelsize=TICK_PT)
            if column == 0:
                ax.set_ylabel(
                    "irradiance at the target\n[W/m²/nm]" if i == 0 else "π × radiance at the camera\n[W/m²/nm]",
                    fontsize=TICK_PT,
                )
    for ax in axes[-1]:
        ax.set_xlabel("wavelength [nm]", fontsize=LABEL_PT)
    for ax in axes.ravel():  # the cells after the last configuration, in every block's rows
        if not ax.has_data():
            ax.set_visible(False)
    axes[0, 0].legend(fontsize=TICK_PT)
    fig.tight_layout()
    return fig


def _emva(path: Path) -> dict:
    doc = read_json(path / "emva.json", "report")
    keys = (
        "K_dn_per_e",
        "quantum_efficiency",
        "dark_noise_e",
        "saturation_e",
        "snr_max_db",
        "dynamic_range_db",
        "linearity_error_percent",
        "dark_current_e_per_s",
        "dsnu_e",
        "prnu_percent",
    )
    rows = [{"quantity": k, "value": _number(doc.get(k)), "std": _number(doc.get(f"{k}_std"))} for k in keys]
    made_with = [(f"EMVA 1288 characterisation {path}", _made_with(doc.get("provenance")))]
    images = [
        _img(path / n)
        for n in ("photon_transfer.png", "snr.png", "linearity.png", "dark_current.png")
        if (path / n).exists()
    ]
    return {"path": str(path), "rows": rows, "images": images, "made_with": made_with}


def _made_with(record: dict | None) -> str:
    """A `uwlab.provenance.provenance` record in one line, or why there is none."""
    return provenance_line(record) if record else "not recorded (written by a uwlab that did not record it)"


def _dataset_made_with(path: Path, metadata: dict) -> list[tuple[str, str]]:
    """(what, made with) of a dataset: the session that started it, then each that resumed it."""
    started = metadata.get("provenance")
    if started is None and metadata.get("software"):  # before provenance: the package versions only
        line = ", ".join(f"{k} {v}" for k, v in metadata["software"].items())
    else:
        line = _made_with(started)
    rows = [(f"dataset {path}", line)]
    rows += [
        (f"dataset {path}, resumed {r.get('utc', '—')} on {r.get('host', '—')}", _made_with(r.get("provenance")))
        for r in metadata.get("resumed") or []
    ]
    return rows


def _geometry(path: Path) -> dict:
    """The geometry section of a ``geometry.json`` (`uwlab.experiments.geometry`): its verdict, comparison table and
    figure."""
    figure = path / GEOMETRY_FIGURE
    doc = read_json(path / GEOMETRY_FILE, "report")
    section = _geometry_section(doc, path, _img(figure) if figure.exists() else None)
    section["made_with"] = [(f"geometry {path}", _made_with(doc.get("provenance")))]
    return section


def _dataset_geometry(path: Path) -> dict | None:
    """The geometry section computed from a dataset's geometry sweeps (`uwlab.experiments.geometry.from_dataset`),
    None for a dataset without any."""
    from uwlab.experiments.geometry import plot_geometry
    from uwlab.experiments.geometry.from_dataset import geometry_from_dataset, has_geometry

    data = Dataset.open(path)
    if not has_geometry(data.points()):
        return None
    result = geometry_from_dataset(data)
    image = png_data_uri(figure_png(plot_geometry(result)))
    section = _geometry_section(to_jsonable(result.to_json()), path, image)
    section["made_with"] = []  # the dataset's own provenance is listed with it
    return section


def _metres(value) -> str:
    return number_text(value, ".4f") + (" m" if value is not None and np.isfinite(value) else "")


def _geometry_section(doc: dict, path: Path, image: str | None) -> dict:
    """The verdict, the comparison table (the parts measured: MTF50, best focus, depth of field) and the figure."""
    depth = f"depth within {_percent(doc['tolerances']['depth'], 0)}"
    rows = [
        {
            "quantity": "MTF50, worst over the sweeps",
            "measured": f"within {_percent(doc['worst_mtf50_error'])} of the model",
            "model": "—",
            "target": f"≤ {_percent(doc['tolerances']['mtf50'], 0)}",
        }
    ]
    if doc["focus_sweep"]:
        step = doc["focus_step_m"]
        rows.append(
            {
                "quantity": "best focus setting",
                "measured": _metres(doc["best_focus_measured_m"]),
                "model": _metres(doc["best_focus_predicted_m"]),
                "target": f"within one step ({number_text(None if step is None else step * 1e3, '.1f')} mm)",
            }
        )
    if doc["distance_sweep"]:
        for name, measured, model, error in zip(
            ("near", "far"), doc["dof_measured_m"], doc["dof_model_m"], doc["dof_depth_errors"], strict=True
        ):
            rows.append(
                {
                    "quantity": f"depth of field, {name} limit",
                    "measured": _metres(measured),
                    "model": _metres(model),
                    "target": f"{depth} ({number_text(None if error is None else error * 100, '+.1f')} %)",
                }
            )
    return {
        "path": str(path),
        "adequate": doc["adequate"],
        "headline": doc["headline"],
        "lens": doc["lens"],
        "criterion": _number(doc["criterion_mtf50_cy_per_px"], 3),
        "rows": rows,
        "image": image,
    }


def _provenance(path: Path, metadata: dict) -> dict:
    rigs = metadata.get("rigs") or {}
    devices = [
        {
            "configuration": _label(s, rigs[s]) if s in rigs else s,
            "camera": f"{d.get('camera', {}).get('vendor', '')} {d.get('camera', {}).get('model', '')}",
            "serial": d.get("camera", {}).get("serial") or "—",
            "firmware": d.get("camera", {}).get("firmware") or "—",
            "light": d.get("light") or "—",
            "spectrometer": d.get("spectrometer") or "—",
        }
        for s, d in (metadata.get("devices") or {}).items()
    ]
    return {
        "path": str(path),
        "sha": metadata.get("plan_sha256") or "—",
        "version": metadata.get("uwlab_version") or "—",
        "host": metadata.get("host") or "—",
        "started": metadata.get("started_utc") or "—",
        "finished": metadata.get("finished_utc") or "—",
        "kind": "simulated rig" if metadata.get("sim") else "tank",
        "devices": devices,
        "made_with": _dataset_made_with(path, metadata),
    }


def _toml_text(path: Path) -> str:
    """A TOML file's text, or "" when it is not one uwlab reads (`uwlab.model.data.read_text`'s rule)."""
    try:
        return read_text(path, "report", MAX_TOML_BYTES, "TOML")
    except ConfigError:
        return ""


def _what_is_here(root: Path) -> str:
    """What a folder with nothing to report holds, and the command that takes it (one clause)."""
    files = [p for p in root.rglob("*") if p.is_file()][:10000]
    suffixes = {p.suffix.lower() for p in files}
    names = {p.name for p in files}
    if any(p.suffix.lower() == ".toml" and "[[sweep]]" in _toml_text(p) for p in files):
        return "it holds a sweep plan: run it with `uwlab sweep PLAN.toml` (add --sim for the simulated rig)"
    if suffixes & {".tif", ".tiff"}:
        if any(p.suffix.lower() in (".txt", ".ini") for p in files):
            return "it holds images and a descriptor: characterise them with `uwlab emva characterize DESCRIPTOR`"
        return "it holds images: `uwlab emva characterize` takes them with an EMVA descriptor file"
    if "grid.parquet" in names or "design.json" in names or suffixes == {".png"}:
        return "it holds design outputs (`uwlab design`), which have no validation report"
    if ".toml" in suffixes:
        return "it holds configs: a design (`uwlab design FILE`), a rig or a plan (`uwlab sweep PLAN.toml`)"
    return "it holds no uwlab output (`uwlab sweep`, `uwlab fit` and `uwlab emva characterize` write them)"


def write_report(root: str | Path, out: str | Path, *, replace: bool = False) -> Path:
    """Write the HTML report of everything found under `root` to `out` (an existing file only if `replace`; the
    directory must exist); returns `out`."""
    root = Path(root)
    if not root.is_dir():
        raise UwlabError(f"{root}: not a directory")
    out = output_file(out, "--out", replace=replace, replace_option="--force")
    datasets = _find(root, METADATA_FILE, MANIFEST_FILE)
    calibrations = _find(root, "summary.json", "samples.parquet")
    emva = _find(root, "emva.json")
    geometry = _find(root, GEOMETRY_FILE)
    if not (datasets or calibrations or emva or geometry):
        raise UwlabError(f"{root}: no dataset, calibration or EMVA characterisation found; {_what_is_here(root)}")
    metadata = [(d, read_metadata(d)[0]) for d in datasets]
    calibration_parts = [_calibration(c) for c in calibrations]
    emva_parts = [_emva(e) for e in emva]
    dataset_parts = [_provenance(d, m) for d, m in metadata]
    geometry_parts = [_geometry(g) for g in geometry]
    geometry_parts += [g for d in datasets if (g := _dataset_geometry(d)) is not None]
    made_with = [("this report", provenance_line(provenance()))]
    for part in (*dataset_parts, *calibration_parts, *emva_parts, *geometry_parts):
        made_with += part["made_with"]
    environment = Environment(
        loader=PackageLoader("uwlab.experiments", "templates"),
        autoescape=True,
        undefined=StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
    )
    html = environment.get_template("report.html.j2").render(
        root=str(root.resolve()),
        written=time.strftime("%Y-%m-%d %H:%M"),
        calibrations=calibration_parts,
        setup=_setup(metadata[0][1]) if metadata else [],
        world=_world(metadata[0][1]) if metadata else None,
        bench_hints=[] if emva else [_bench_hint(d) for d, m in metadata if _has_bench(m)],
        emva=emva_parts,
        geometry=geometry_parts,
        provenance=dataset_parts,
        made_with=made_with,
    )
    out.write_text(html)
    return out
