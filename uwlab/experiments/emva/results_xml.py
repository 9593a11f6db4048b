"""The characterisation as XML with the names of the EMVA 1288 reference implementation, so that results can be
compared with other tools (github.com/EMVA1288/emva1288, ``doc/datasets/datasets_results.rst``: a ``<results>`` root,
one element per section, one per result with ``Comment``, ``Short``, ``Symbol``, ``Unit`` and ``Value``, or ``Data``
with ``bins``, ``values`` and ``model`` for the histograms; the names are those of its ``Results1288`` class).

Values follow uwlab's Release 4.0 definitions (docs/emva.md), which differ from the reference implementation's
Release 3.1 ones for μ_p.min (eq. 26), the highpass of the spatial variances (§8.1) and the dark current from the
variance (divided by K², where the reference divides by K twice after a first division): the names are shared, the
methods are those of the standard's text. An extra ``LE`` gives the Release 4.0 linearity error (eq. 63) beside the
reference's ``LE_min``/``LE_max``. Values that cannot be computed (the general model's K and η, a missing stack)
are written as ``nan``, as the reference implementation does; QE is in percent, as there. A last section,
``provenance`` (not the reference's), names the software and machine that computed the values (`uwlab.provenance`):
``uwlab`` (with a ``commit`` attribute), ``python``, one ``package`` per version, ``blas`` and ``cpu``.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from uwlab.experiments.emva.analysis import EmvaResult
from uwlab.provenance import provenance

_S2 = "spatial_variances"


def _sv(group: str, part: str | None = None):
    """The spatial variance ``group`` (``bright``/``dark`` with a ``part``, or a scalar such as ``bright_measured``)."""

    def get(v):
        value = (v.get(_S2) or {}).get(group)
        return value.get(part) if part is not None and value is not None else value

    return get


def _key(key: str, scale: float = 1.0):
    return lambda v: None if v.get(key) is None else v[key] * scale


def _by_model(linear_key: str, general_key: str):
    return lambda v: v.get(linear_key if v["model"] == "linear" else general_key)


# (section, name, short description, symbol, unit for the linear model, unit for the general model, value getter)
ENTRIES = (
    ("info", "index_start", "Start array index", "", "", "", lambda v: 0),
    ("sensitivity", "u_p_sat", "Saturation Capacity", r"$\mu_{p.sat}$", "$p$", "$p$", _key("saturation_photons")),
    (
        "sensitivity",
        "u_p_sat_area",
        "Saturation Capacity",
        r"$\mu_{p.sat.area}$",
        r"$p/\mu m^2$",
        r"$p/\mu m^2$",
        _key("saturation_photons_per_um2"),
    ),
    ("sensitivity", "u_e_sat", "Saturation Capacity", r"$\mu_{e.sat}$", "$e^-$", "$e^-$", _key("saturation_e")),
    (
        "sensitivity",
        "u_e_sat_area",
        "Saturation Capacity",
        r"$\mu_{e.sat.area}$",
        r"$e^-/\mu m^2$",
        r"$e^-/\mu m^2$",
        _key("saturation_e_per_um2"),
    ),
    ("sensitivity", "SNR_max", "Signal-to-Noise Ratio", "$SNR_{max}$", "", "", _key("snr_max")),
    (
        "sensitivity",
        "SNR_max_dB",
        "Maximum Signal to Noise Ratio in Db",
        "$SNR_{max.dB}$",
        "dB",
        "dB",
        _key("snr_max_db"),
    ),
    (
        "sensitivity",
        "SNR_max_bit",
        "Maximum Signal to Noise Ratio in Bits",
        "$SNR_{max.bit}$",
        "bit",
        "bit",
        _key("snr_max_bits"),
    ),
    (
        "sensitivity",
        "inverse_SNR_max",
        "Inverse Maximum Signal to Noise Ratio",
        "$SNR_{max}^{-1}$",
        r"\%",
        r"\%",
        _key("inverse_snr_max_percent"),
    ),
    ("sensitivity", "sigma_y_dark", "Temporal Dark Noise", r"$\sigma_{y.dark}$", "DN", "DN", _key("dark_noise_dn")),
    (
        "sensitivity",
        "sigma_d",
        "Temporal Dark Noise",
        r"$\sigma_d$",
        "$e^-$",
        "$p$",
        _by_model("dark_noise_e", "dark_noise_p"),
    ),
    ("sensitivity", "K", "System gain", "K", "$DN/e^-$", "$DN/e^-$", _key("K_dn_per_e")),
    (
        "sensitivity",
        "inverse_K",
        "Inverse of overall system gain",
        "1/K",
        "$e^-/DN$",
        "$e^-/DN$",
        _key("inverse_K_e_per_dn"),
    ),
    (
        "sensitivity",
        "R",
        "Responsivity",
        "R",
        "DN/p",
        "DN/p",
        _by_model("responsivity_dn_per_photon", "responsivity_dark_dn_per_photon"),
    ),
    ("sensitivity", "QE", "Quantum efficiency", r"$\eta$", r"\%", r"\%", _key("quantum_efficiency", 100.0)),
    (
        "sensitivity",
        "u_p_min",
        "Absolute sensitivity threshold",
        r"$\mu_{p.min}$",
        "$p$",
        "$p$",
        _key("sensitivity_threshold_photons"),
    ),
    (
        "sensitivity",
        "u_p_min_area",
        "Sensitivity threshold",
        r"$\mu_{p.min.area}$",
        r"$p/\mu m^2$",
        r"$p/\mu m^2$",
        _key("sensitivity_threshold_photons_per_um2"),
    ),
    (
        "sensitivity",
        "u_e_min",
        "Sensitivity threshold",
        r"$\mu_{e.min}$",
        "$e^-$",
        "$e^-$",
        _key("sensitivity_threshold_e"),
    ),
    (
        "sensitivity",
        "u_e_min_area",
        "Sensitivity threshold",
        r"$\mu_{e.min.area}$",
        r"$e^-/\mu m^2$",
        r"$e^-/\mu m^2$",
        _key("sensitivity_threshold_e_per_um2"),
    ),
    ("sensitivity", "DR", "Dynamic Range", "DR", "", "", _key("dynamic_range")),
    ("sensitivity", "DR_dB", "Dynamic Range", "$DR_{dB}$", "dB", "dB", _key("dynamic_range_db")),
    ("sensitivity", "index_u_ysat", "Saturation index", "", "", "", _key("saturation_index")),
    (
        "sensitivity",
        "index_sensitivity_min",
        "Sensitivity fit minimum index",
        "",
        "",
        "",
        _key("sensitivity_index_min"),
    ),
    (
        "sensitivity",
        "index_sensitivity_max",
        "Sensitivity fit maximum index",
        "",
        "",
        "",
        _key("sensitivity_index_max"),
    ),
    ("linearity", "LE", "Linearity error (Release 4.0 eq. 63)", "$LE$", r"\%", r"\%", _key("linearity_error_percent")),
    ("linearity", "LE_min", "Min Linearity error", "$LE_{min}$", r"\%", r"\%", _key("linearity_deviation_min_percent")),
    ("linearity", "LE_max", "Max Linearity error", "$LE_{max}$", r"\%", r"\%", _key("linearity_deviation_max_percent")),
    ("linearity", "index_linearity_min", "Linearity fit minimun index", "", "", "", _key("linearity_index_min")),
    ("linearity", "index_linearity_max", "Linearity fit maximum index", "", "", "", _key("linearity_index_max")),
    (
        "dark_current",
        "u_I_mean",
        "Dark Current from mean",
        r"$\mu_{I.mean}$",
        "$e^-/s$",
        "$p/s$",
        _by_model("dark_current_e_per_s", "dark_current_p_per_s"),
    ),
    (
        "dark_current",
        "u_I_mean_DN",
        "Dark Current from mean",
        r"$\mu_{I.mean.DN}$",
        "$DN/s$",
        "$DN/s$",
        _key("dark_current_dn_per_s"),
    ),
    (
        "dark_current",
        "u_I_var",
        "Dark Current from variance",
        r"$\mu_{I.var}$",
        "$e^-/s$",
        "$p/s$",
        _by_model("dark_current_var_e_per_s", "dark_current_var_p_per_s"),
    ),
    (
        "dark_current",
        "u_I_var_DN",
        "Dark Current from variance",
        r"$\mu_{I.var.DN}$",
        "$DN/s$",
        "$DN/s$",
        lambda v: (
            None
            if v.get("dark_current_var_dn2_per_s") is None
            else v["dark_current_var_dn2_per_s"]
            / (v["K_dn_per_e"] if v["model"] == "linear" else v["responsivity_dark_dn_per_photon"])
        ),
    ),
    ("spatial", "s_2_y", "Spatial variance from image", "$s^2_{y}$", "DN2", "DN2", _sv("bright", "total")),
    ("spatial", "s_2_y_dark", "Spatial variance from image", "$s^2_{y.dark}$", "DN2", "DN2", _sv("dark", "total")),
    (
        "spatial",
        "s_2_y_measured",
        "Spatial variance measure",
        "$s^2_{y.measured}$",
        "DN2",
        "DN2",
        _sv("bright_measured"),
    ),
    (
        "spatial",
        "s_2_y_measured_dark",
        "Spatial variance measured dark",
        "$s^2_{y.measured.dark}$",
        "DN2",
        "DN2",
        _sv("dark_measured"),
    ),
    (
        "spatial",
        "sigma_2_y_stack",
        "Temporal variance stack",
        r"$\sigma^2_{y.stack}$",
        "DN2",
        "DN2",
        _sv("bright_stack_var"),
    ),
    (
        "spatial",
        "sigma_2_y_stack_dark",
        "Temporal variance stack dark",
        r"$\sigma^2_{y.stack.dark}$",
        "DN2",
        "DN2",
        _sv("dark_stack_var"),
    ),
    ("spatial", "s_2_y_cav", "Spatial variance from image", "$s^2_{y.cav}$", "DN2", "DN2", _sv("bright_cav")),
    ("spatial", "s_2_y_cav_dark", "Spatial variance from image", "$s^2_{y.cav.dark}$", "DN2", "DN2", _sv("dark_cav")),
    ("spatial", "s_2_y_rav", "Spatial variance from image", "$s^2_{y.rav}$", "DN2", "DN2", _sv("bright_rav")),
    ("spatial", "s_2_y_rav_dark", "Spatial variance from image", "$s^2_{y.rav.dark}$", "DN2", "DN2", _sv("dark_rav")),
    *(
        (
            "spatial",
            f"s_2_y_{part}{dark}",
            "Spatial variance from image",
            f"$s^2_{{y.{part}{dark.replace('_', '.')}}}$",
            "DN2",
            "DN2",
            _sv("dark" if dark else "bright", part),
        )
        for part in ("col", "row", "pixel")
        for dark in ("", "_dark")
    ),
    ("spatial", "DSNU1288", "DSNU", "$DSNU_{1288}$", "$e^-$", "$p$", _by_model("dsnu_e", "dsnu_p")),
    ("spatial", "DSNU1288_DN", "DSNU in DN", "$DSNU_{1288.DN}$", "DN", "DN", _key("dsnu_dn")),
    *(
        (
            "spatial",
            f"DSNU1288_{part}",
            f"DSNU{part}",
            f"$DSNU_{{1288.{part}}}$",
            "$e^-$",
            "$p$",
            _by_model(f"dsnu_{part}_e", f"dsnu_{part}_p"),
        )
        for part in ("row", "col", "pixel")
    ),
    ("spatial", "PRNU1288", "PRNU", "$PRNU_{1288}$", r"\%", r"\%", _key("prnu_percent")),
    *(
        (
            "spatial",
            f"PRNU1288_{part}",
            f"PRNU{part}",
            f"$PRNU_{{1288.{part}}}$",
            r"\%",
            r"\%",
            _key(f"prnu_{part}_percent"),
        )
        for part in ("row", "col", "pixel")
    ),
)
HISTOGRAMS = (
    ("histogram_DSNU", "DSNU histogram", "dsnu_histograms", "log"),
    ("histogram_DSNU_accumulated", "accumulated DSNU histogram", "dsnu_histograms", "accumulated"),
    ("histogram_PRNU", "PRNU histogram", "prnu_histograms", "log"),
    ("histogram_PRNU_accumulated", "accumulated PRNU histogram", "prnu_histograms", "accumulated"),
)
SECTIONS = ("info", "sensitivity", "linearity", "dark_current", "spatial", "defect_pixel")


def _text(value) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "nan"
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    return repr(float(value))


def _array(values) -> str:
    return " ".join(_text(float(x)) for x in np.asarray(values, float).ravel())


def results_element(result: EmvaResult, made_with: dict | None = None) -> ET.Element:
    """The ``<results>`` tree of a characterisation; ``made_with``: its `uwlab.provenance.provenance` record
    (default this process's)."""
    v = result.values
    linear = v["model"] == "linear"
    root = ET.Element("results")
    sections = {name: ET.SubElement(root, name) for name in SECTIONS}
    for section, name, short, symbol, unit_linear, unit_general, getter in ENTRIES:
        element = ET.SubElement(sections[section], name)
        for tag, text in (
            ("Comment", ""),
            ("Short", short),
            ("Symbol", symbol),
            ("Unit", unit_linear if linear else unit_general),
            ("Value", _text(getter(v))),
        ):
            ET.SubElement(element, tag).text = text
    for name, short, attribute, kind in HISTOGRAMS:
        element = ET.SubElement(sections["defect_pixel"], name)
        ET.SubElement(element, "Comment").text = "" if result.images else "no nonuniformity stacks"
        ET.SubElement(element, "Short").text = short
        ET.SubElement(element, "Symbol").text = ""
        data = ET.SubElement(element, "Data")
        if result.images is not None:
            hist = getattr(result.images, attribute)[kind]
            ET.SubElement(data, "bins").text = _array(hist.centres_dn)
            ET.SubElement(data, "values").text = _array(hist.counts)
            if hist.model is not None:
                ET.SubElement(data, "model").text = _array(hist.model)
        ET.SubElement(element, "Unit").text = ""
    root.append(_provenance_element(made_with or provenance()))
    return root


def _provenance_element(record: dict) -> ET.Element:
    element = ET.Element("provenance")
    uwlab = ET.SubElement(element, "uwlab", commit=str(record["commit"]), modified=str(record["modified"]))
    uwlab.text = record["uwlab"]
    ET.SubElement(element, "python").text = record["python"]
    for name, version in record["packages"].items():
        ET.SubElement(element, "package", name=name).text = version
    blas = record["blas"]
    ET.SubElement(element, "blas", version=str(blas["version"]), threads=str(blas["threads"])).text = blas["library"]
    ET.SubElement(element, "cpu", cores=str(record["cpus"])).text = record["cpu"]
    return element


def results_xml(result: EmvaResult, made_with: dict | None = None) -> str:
    """The XML document (UTF-8 text, indented)."""
    tree = ET.ElementTree(results_element(result, made_with))
    ET.indent(tree)
    root = tree.getroot()
    assert root is not None  # the tree was built from its root
    return ET.tostring(root, encoding="unicode", xml_declaration=True) + "\n"


def write_results_xml(result: EmvaResult, path: Path, made_with: dict | None = None) -> Path:
    path.write_text(results_xml(result, made_with), encoding="utf-8")
    return path
