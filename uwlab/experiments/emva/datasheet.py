"""The EMVA 1288 datasheet as one self-contained HTML page (jinja2 template ``templates/datasheet.html.j2``, figures
embedded as PNG data URIs).

Structure (EMVA 1288 Release 4.0 Linear §10.2 and the summary-sheet template of Appendix G; General §10.2): a header
with vendor, model, serial number and the date of the measurement; the operation point; the summary — the photon
transfer curve (general model: the characteristic curve) and the SNR curve beside a one-column table of every
quantity of Table 2 in the table's units (the general model's version of Table 2: K and η "N/A", every other quantity
in photons); then the verdicts and notes; then the detailed results (every other figure); and the provenance (the
source, and the software and machine that computed the page: `uwlab.provenance`). No EMVA logo: a licence is needed
to claim compliance (Preface), and this page says what it is instead.
"""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

from uwlab import __version__
from uwlab.experiments.emva.analysis import EmvaResult
from uwlab.experiments.emva.linear import linear_model_holds
from uwlab.experiments.emva.transfer import CHANNEL_NO_SPLIT, SheetInfo
from uwlab.experiments.figures import number_text, png_data_uri
from uwlab.provenance import provenance, provenance_line

TEMPLATE = "datasheet.html.j2"
SUMMARY_FIGURES = {"linear": ("photon_transfer", "snr"), "general": ("characteristic", "snr")}
CAPTIONS = {
    "photon_transfer": "Photon transfer (Fig. 7)",
    "characteristic": "Characteristic curve (General Fig. 5)",
    "snr": "Signal-to-noise ratio (Fig. 8; General Fig. 7)",
    "linearity": "Linearity (Fig. 9)",
    "stability": "Stability (Fig. 6)",
    "dark_current": "Dark current (Fig. 10)",
    "dark_current_temperature": "Dark current against temperature (Fig. 11)",
    "spatial_variances": "Spatial variances at every step (§4.3)",
    "dsnu_spectrogram": "DSNU spectrograms (Fig. 12)",
    "prnu_spectrogram": "PRNU spectrograms (Fig. 13)",
    "dsnu_profiles": "DSNU profiles (Fig. 14)",
    "prnu_profiles": "PRNU profiles (Fig. 14)",
    "dsnu_histograms": "DSNU histograms (Figs. 15a, 16a)",
    "prnu_histograms": "PRNU histograms (Figs. 15b, 16b)",
}


def _with_std(values: dict, key: str, spec: str) -> str:
    text = number_text(values.get(key), spec)
    std = values.get(f"{key}_std")
    return text if std is None or values.get(key) is None else f"{text} ± {std:{spec}}"


SPATIAL_PARTS = (("", "", "total"), (".col", "_col", "col"), (".row", "_row", "row"), (".pix", "_pixel", "pixel"))
FRAMES_FOR_PARTS = 16  # frames at 50 % saturation that resolve parts of ~0.1 % PRNU on typical ROIs (§8.2: L ≥ 16)


def missing_reason(values: dict, parts: list[str], which: str) -> str:
    """Why DSNU or PRNU (`which`) of `parts` is not given, and what change to the measurement gives it."""
    spatial = values.get("spatial_variances")
    if not spatial and values.get("channel"):
        return CHANNEL_NO_SPLIT
    if not spatial:
        return (
            "not computed: no highpassed spatial variances; record the sweep with a region of interest larger than "
            "19 px a side (§8.1's filters)"
        )
    estimates = []
    for part in parts:
        dark = float(spatial["dark"][part])
        estimates.append(dark if which == "DSNU" else float(spatial["bright"][part]) - dark)
    frames = int(spatial.get("frames") or 0)
    quantity = "s²_y.dark" if which == "DSNU" else "s²_y.50 − s²_y.dark"
    return (
        f"the variance estimates {quantity} are below zero ({', '.join(f'{e:.2g}' for e in estimates)} DN²) from "
        f"{frames} frames: below what this measurement resolves; record at least {FRAMES_FOR_PARTS} bright and "
        "dark frames at 50 % saturation (frames_per_point in the plan, or a nonuniformity stack in the descriptor)"
    )


def _or_why(values: dict, key: str, spec: str, part: str, which: str) -> str:
    """The value, or "n/a (below)" when there is none (the reason: `missing_notes`)."""
    value = values.get(key)
    return number_text(value, spec) if value is not None else "n/a (see below)"


def missing_notes(values: dict) -> list[tuple[str, str]]:
    """(symbols, why they are not given and what gives them) for the DSNU and the PRNU rows shown as n/a."""
    q = "e" if values["model"] == "linear" else "p"
    notes = []
    for which, template in (("DSNU", "dsnu{k}_" + q), ("PRNU", "prnu{k}_percent")):
        missing = [(suffix, part) for suffix, k, part in SPATIAL_PARTS if values.get(template.format(k=k)) is None]
        if missing:
            symbols = ", ".join(f"{which}1288{suffix}" for suffix, _ in missing)
            notes.append((symbols, missing_reason(values, [part for _, part in missing], which)))
    return notes


SUMMARY_SPATIAL = (("dsnu_e", "DSNU"), ("dsnu_p", "DSNU"), ("prnu_percent", "PRNU"))


def missing_figures(values: dict) -> dict[str, str]:
    """{key: why it is not given} for the total DSNU and PRNU of a summary (``dsnu_e``, ``dsnu_p``,
    ``prnu_percent``) held without a value: the reason the datasheet prints under its table (`missing_reason`),
    for every summary that shows them as ``—``."""
    return {
        key: missing_reason(values, ["total"], which)
        for key, which in SUMMARY_SPATIAL
        if key in values and values[key] is None
    }


def summary_rows(values: dict) -> list[tuple[str, list[tuple[str, str, str]]]]:
    """The one-column table of Table 2: [(group, [(symbol, value, unit), ...]), ...]."""
    v = values
    linear = v["model"] == "linear"
    q = "e-" if linear else "p"
    dark_key = "dark_noise_e" if linear else "dark_noise_p"
    limit = "< " if v.get("dark_noise_upper_limit") else ""
    eta = v.get("quantum_efficiency")
    rows = [
        (
            "Quantum efficiency",
            [
                (
                    "η",
                    f"{100 * eta:.1f}" if eta is not None else "N/A (cannot be measured)",
                    "%" if eta is not None else "",
                )
            ],
        ),
        (
            "Overall system gain",
            [
                ("K", number_text(v.get("K_dn_per_e"), ".4g") if linear else "N/A", "DN/e-"),
                ("1/K", number_text(v.get("inverse_K_e_per_dn"), ".4g") if linear else "N/A", "e-/DN"),
            ],
        ),
        (
            "Temporal dark noise",
            [
                ("σ_d", limit + number_text(v.get(dark_key), ".3g"), q),
                ("σ_y.dark", number_text(v.get("dark_noise_dn"), ".3g"), "DN"),
            ],
        ),
        (
            "Signal-to-noise ratio",
            [
                ("SNR_max" if linear else "SNR_p.max", number_text(v.get("snr_max"), ".4g"), ""),
                ("", number_text(v.get("snr_max_db"), ".1f"), "dB"),
                ("1/SNR_max", number_text(v.get("inverse_snr_max_percent"), ".3g"), "%"),
            ],
        ),
    ]
    if linear:
        rows += [
            (
                "Absolute sensitivity threshold",
                [
                    ("μ_e.min", number_text(v["sensitivity_threshold_e"], ".3g"), "e-"),
                    ("μ_e.min.area", number_text(v.get("sensitivity_threshold_e_per_um2"), ".3g"), "e-/µm²"),
                ],
            ),
            (
                "Saturation capacity",
                [
                    ("μ_e.sat", number_text(v["saturation_e"], ".5g"), "e-"),
                    ("μ_e.sat.area", number_text(v.get("saturation_e_per_um2"), ".4g"), "e-/µm²"),
                ],
            ),
        ]
    else:
        rows += [
            (
                "Absolute sensitivity threshold",
                [
                    ("μ_p.min", number_text(v["sensitivity_threshold_photons"], ".3g"), "p"),
                    ("μ_p.min.area", number_text(v.get("sensitivity_threshold_photons_per_um2"), ".3g"), "p/µm²"),
                ],
            ),
            (
                "Saturation capacity",
                [
                    ("μ_p.sat", number_text(v["saturation_photons"], ".5g"), "p"),
                    ("μ_p.sat.area", number_text(v.get("saturation_photons_per_um2"), ".4g"), "p/µm²"),
                ],
            ),
        ]
    rows += [
        (
            "Dynamic range",
            [
                ("DR", number_text(v.get("dynamic_range"), ".4g"), ""),
                ("", number_text(v.get("dynamic_range_db"), ".1f"), "dB"),
            ],
        ),
        (
            "Spatial nonuniformities",
            [(f"DSNU1288{s}", _or_why(v, f"dsnu{k}_{q[0]}", ".3g", part, "DSNU"), q) for s, k, part in SPATIAL_PARTS]
            + [
                (f"PRNU1288{s}", _or_why(v, f"prnu{k}_percent", ".3g", part, "PRNU"), "%")
                for s, k, part in SPATIAL_PARTS
            ],
        ),
        ("Linearity error", [("LE", number_text(v.get("linearity_error_percent"), ".3g"), "%")]),
        (
            "Dark current",
            [
                ("μ_I.mean", _with_std(v, f"dark_current_{q[0]}_per_s", ".3g"), f"{q}/s"),
                ("μ_I.var", _with_std(v, f"dark_current_var_{q[0]}_per_s", ".3g"), f"{q}/s"),
            ],
        ),
    ]
    return rows


def verdicts(values: dict) -> list[tuple[str, str]]:
    """(class, text) lines shown above the details: which model, whether it holds, and the saturation choice."""
    v = values
    out = []
    if v["model"] == "linear":
        deviation, noise = v.get("photon_transfer_slope_deviation"), v.get("photon_transfer_slope_noise") or 0.0
        le = v["linearity_error_percent"]
        if deviation is None:
            out.append(("warn", "Linear model not checked (eq. 51): too few points up to saturation."))
        elif linear_model_holds(deviation, noise, le):
            out.append(
                (
                    "ok",
                    f"Linear model holds: photon transfer slope deviation {100 * deviation:.2g} % "
                    f"({100 * noise:.2g} % from noise alone; limit 3 %, eq. 51), linearity error "
                    f"{le:.2g} %.",
                )
            )
        else:
            out.append(
                (
                    "bad",
                    f"Linear model does not hold: photon transfer slope deviation {100 * deviation:.2g} % "
                    f"({100 * noise:.2g} % from noise; eq. 51), linearity error {le:.2g} % — use the "
                    "general model (--model general).",
                )
            )
    else:
        out.append(("ok", "General model (Release 4.0 General): K and η are not measured; quantities in photons."))
    out.append(
        (
            "info",
            f"Saturation at point {v['saturation_index']} by the {v['saturation_rule']}; the variance "
            f"maximum is at point {v['variance_max_index']}.",
        )
    )
    return out


def _duration(seconds: float) -> str:
    """An exposure time in s, ms or µs, three significant digits."""
    if seconds >= 1.0:
        return f"{seconds:.3g} s"
    if seconds >= 1e-3:
        return f"{seconds * 1e3:.3g} ms"
    return f"{seconds * 1e6:.3g} µs"


def operation_point(values: dict, curves: dict) -> list[tuple[str, str]]:
    """The operation-point rows of the summary sheet."""
    v = values
    exposure = curves["exposure_s"]
    varied = exposure.max() > exposure.min() * 1.0001
    exposure_text = f"{_duration(exposure.min())} – {_duration(exposure.max())}" if varied else _duration(exposure[0])
    wavelength = v.get("wavelength_nm")
    return [
        ("Exposure control", "by exposure time" if varied else "by irradiance"),
        ("Exposure time", exposure_text),
        ("Gain", f"{v['gain_db']:g} dB"),
        (
            "Data transfer mode",
            f"Mono {v['bit_depth']}" if not v.get("channel") else f"raw Bayer {v['bit_depth']}, {v['channel']} channel",
        ),
        ("Camera temperature", "—" if v.get("temperature_c") is None else f"{v['temperature_c']:.1f} °C"),
        ("Wavelength (centroid)", "—" if wavelength is None else f"{wavelength:.0f} nm"),
        ("Pixel area", "—" if not v.get("pixel_area_m2") else f"{v['pixel_area_m2'] * 1e12:.4g} µm²"),
        ("Image size", f"{v['width_px']} × {v['height_px']} px" if v.get("width_px") else "—"),
    ]


def datasheet_html(
    result: EmvaResult, figures: dict[str, bytes], info: SheetInfo, made_with: dict | None = None
) -> str:
    """The datasheet page of ``result`` with its ``figures`` as PNG by name (`uwlab.experiments.emva.plots`'
    `figure_pngs`); ``made_with``: the `uwlab.provenance.provenance` record to show (default this process's)."""
    from jinja2 import Environment, PackageLoader, select_autoescape

    env = Environment(
        loader=PackageLoader("uwlab.experiments.emva", "templates"), autoescape=select_autoescape(["html", "j2"])
    )
    v = result.values
    first = SUMMARY_FIGURES[v["model"]]
    summary = [(CAPTIONS[n], png_data_uri(figures[n])) for n in first if n in figures]
    details = [(CAPTIONS.get(n, n), png_data_uri(png)) for n, png in figures.items() if n not in first]
    return env.get_template(TEMPLATE).render(
        v=v,
        info=info,
        rows=summary_rows(v),
        missing=missing_notes(v),
        verdicts=verdicts(v),
        notes=v.get("notes", []),
        operation=operation_point(v, result.curves),
        summary=summary,
        details=details,
        version=__version__,
        made_with=provenance_line(made_with or provenance()),
        generated=datetime.now(UTC).isoformat(timespec="seconds"),
    )


def write_datasheet(
    result: EmvaResult, figures: dict[str, bytes], path: Path, info: SheetInfo, made_with: dict | None = None
) -> Path:
    path.write_text(datasheet_html(result, figures, info, made_with), encoding="utf-8")
    return path
