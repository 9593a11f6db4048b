"""The readout of one design: its outputs as people read them (names, units, rounding) and the warnings on them.

`OUTPUTS` names every output of `uwlab.model.design.evaluate` once; `uwlab design` prints the rows as its text
table and `uwlab explore` shows the same rows on its page, so the two read alike (``SNR  36.5 dB``). An output the
table does not name yet (a new key of `evaluate`) is shown under its key with four significant digits. The light
budget (``light_budget_stops``, "what limits me") follows as stops lost per stage, the largest loss marked.

Warnings flag a design that does not do what its config asks; each is attached to the output row that shows the
offending number and names the inputs that change it:

- ``saturated``: the on-axis signal reaches the saturation capacity or the full scale (`evaluate`'s ``saturated``).
- ``blur``: the exposure is longer than the blur limit: the motion blur is
  ``max_blur_px · exposure_s / max_exposure_s`` pixels (the blur grows linearly with the exposure and equals
  ``max_blur_px`` at ``max_exposure_s``); it happens with a fixed exposure, or with ``max-blur`` when the sensor's
  shortest exposure is above the limit.
- ``dof``: the depth of field ``far − near`` is shorter than ``operation.min_dof_m`` (an unbounded far limit,
  ``null`` in JSON, is long enough).

Values are read from the JSON form of the result (`uwlab.jsonable.to_jsonable`: infinities are ``None``).

>>> rows({"snr_db": 36.47, "saturated": False})[1].text
'36.5'
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from uwlab.model.design import Design

# Blur within this relative margin of the limit is the limit (the exposure is clipped to it in floating point).
BLUR_TOLERANCE = 1e-9


@dataclass(frozen=True)
class Output:
    """How one output (a key of `uwlab design --json`) is shown: label, unit and a `str.format` pattern."""

    key: str
    label: str
    unit: str
    fmt: str
    parts: tuple[tuple[str, str], ...] = ()  # a table's keys and their short names, in the label as computed

    def label_for(self, value) -> str:
        """The label, with the short names of the table's parts that `value` holds, e.g. "image average (e-, DN)"."""
        if not self.parts or not isinstance(value, dict):
            return self.label
        names = dict(self.parts)
        return f"{self.label} ({', '.join(names.get(k, k) for k in value)})"


OUTPUTS = (
    Output("effective_focal_length_mm", "effective focal length", "mm", "{:.2f}"),
    Output("fov_deg", "field of view (x, y)", "deg", "{:.2f}"),
    Output("fov_m", "footprint at altitude (x, y)", "m", "{:.3f}"),
    Output("max_exposure_s", "max exposure for blur", "s", "{:.4g}"),
    Output("exposure_s", "exposure", "s", "{:.4g}"),
    Output("min_framerate_hz", "min framerate", "Hz", "{:.3g}"),
    Output("dof_m", "depth of field (near, far)", "m", "{:.3f}"),
    Output("min_f_number_for_dof", "min f-number for DoF", "", "{:.2f}"),
    Output("dome_virtual_image_m", "dome virtual image", "m", "{:.4f}"),
    Output("focus_image_m", "target's image (focus on it)", "m", "{:.4f}"),
    Output("focus_setting_m", "lens focus setting", "m", "{:.4f}"),
    Output("close_up_lens_dpt", "close-up lens needed", "dpt", "{:.2f}"),
    Output("target_irradiance_w_m2", "target irradiance", "W/m²", "{:.4g}"),
    Output("sensor_irradiance_w_m2", "sensor irradiance", "W/m²", "{:.4g}"),
    Output("mean_electrons", "mean signal (on axis)", "e-", "{:.1f}"),
    Output("mean_dn", "mean response (on axis)", "DN", "{:.1f}"),
    Output("mean_fraction", "fraction of full scale", "", "{:.3f}"),
    Output("saturated", "saturated", "", "{}"),
    Output("snr", "SNR", "", "{:.1f}"),
    Output("snr_db", "SNR", "dB", "{:.1f}"),
    Output("veil_electrons", "veiling light (on axis)", "e-", "{:.1f}"),
    Output(
        "image_average",
        "image average",
        "",
        "{:.1f}",
        (("mean_electrons", "e-"), ("mean_dn", "DN"), ("snr", "SNR"), ("veil_electrons", "veil e-")),
    ),
)
OUTPUT_BY_KEY = {o.key: o for o in OUTPUTS}
UNNAMED_FORMAT = "{:.4g}"
# The "what limits me" readout: `light_budget_stops`, stages in chain order (`uwlab.model.design.light_budget`).
BUDGET_KEY = "light_budget_stops"
BUDGET_STAGES = {
    "beam_to_view": "beam → field of view",
    "water_to_target": "water, light → target",
    "reflectance": "target reflectance",
    "water_to_camera": "water, target → camera",
    "port": "port",
    "aperture": "aperture (pupil / distance)",
    "lens_transmittance": "lens transmittance",
    "quantum_efficiency": "quantum efficiency",
}
BUDGET_FORMAT = "{:.2f}"


def format_value(value, fmt: str) -> str:
    """One output value as text: ``n/a`` for None (also an infinity, which JSON cannot hold), booleans in lower
    case, a table's values joined by ", "."""
    if value is None:
        return "n/a"
    if isinstance(value, dict):
        return ", ".join(format_value(v, fmt) for v in value.values())
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float) and math.isinf(value):
        return "inf"
    if isinstance(value, (int, float)):
        return fmt.format(value)
    return str(value)


@dataclass(frozen=True)
class Row:
    """One line of the readout: the output key, its label, the value as text and its unit."""

    key: str
    label: str
    text: str
    unit: str


def _output(key: str) -> Output:
    return OUTPUT_BY_KEY.get(key) or Output(key, key, "", UNNAMED_FORMAT)


def rows(result: dict) -> list[Row]:
    """The readout rows of a JSON-able result: the named outputs in table order, then any others by key (the
    light budget has its own readout, `budget_rows`)."""
    keys = [o.key for o in OUTPUTS if o.key in result]
    keys += [k for k in result if k not in OUTPUT_BY_KEY and k != BUDGET_KEY]
    return [
        Row(k, _output(k).label_for(result[k]), format_value(result[k], _output(k).fmt), _output(k).unit) for k in keys
    ]


def output_leaves(result: dict) -> list[dict]:
    """Every single output of a JSON-able result as {"name", "label", "unit"}: nested outputs by their dotted
    name (``dof_m.near``, the names `uwlab design solve --require` takes), outputs a design does not compute
    (None) left out."""
    leaves = []
    for key, value in result.items():
        if value is None:
            continue
        output = _output(key)
        if key == BUDGET_KEY:
            leaves += [
                {"name": f"{key}.{k}", "label": f"light lost: {BUDGET_STAGES.get(k, k)}", "unit": "stops"}
                for k, v in value.items()
                if v is not None
            ]
        elif isinstance(value, dict):
            leaves += [
                {"name": f"{key}.{k}", "label": f"{output.label}: {k}", "unit": output.unit}
                for k, v in value.items()
                if v is not None and not isinstance(v, dict)
            ]
        elif not isinstance(value, (list, str)):
            leaves.append({"name": key, "label": output.label, "unit": output.unit})
    return leaves


def budget_rows(stops: dict) -> tuple[list[Row], str, str]:
    """The "what limits me" readout of a result's ``light_budget_stops``: (a row per stage in chain order, the
    stage that loses the most light, the total as text), stops as text."""
    worst = max(stops, key=lambda k: -math.inf if stops[k] is None else stops[k])
    stage_rows = [
        Row(key, BUDGET_STAGES.get(key, key), format_value(stops[key], BUDGET_FORMAT), "stops")
        for key in [*BUDGET_STAGES, *(k for k in stops if k not in BUDGET_STAGES)]
        if key in stops
    ]
    total = sum(v for v in stops.values() if v is not None)
    return stage_rows, worst, BUDGET_FORMAT.format(total)


@dataclass(frozen=True)
class DesignWarning:
    """A design that does not do what its config asks: `kind` (saturated, blur, dof), the message, the output
    rows that show the offending number, and the config keys that change it."""

    kind: str
    message: str
    outputs: tuple[str, ...]
    inputs: tuple[str, ...]


def _fmt(key: str, value) -> str:
    output = _output(key)
    return f"{format_value(value, output.fmt)} {output.unit}".rstrip()


def design_warnings(design: Design, result: dict) -> list[DesignWarning]:
    """The warnings (module docstring) on a scalar design and its JSON-able result."""
    found = []
    if result.get("saturated"):
        found.append(
            DesignWarning(
                "saturated",
                f"saturated: {_fmt('mean_dn', result['mean_dn'])} on axis is at the sensor's limit",
                ("mean_dn", "saturated"),
                ("operation.exposure_s", "sensor.gain_db", "lens.f_number", "light.luminous_flux_lm"),
            )
        )
    exposure, limit = result.get("exposure_s"), result.get("max_exposure_s")
    if exposure is not None and limit is not None and exposure > limit * (1 + BLUR_TOLERANCE):
        max_blur = float(design["operation.max_blur_px"])
        found.append(
            DesignWarning(
                "blur",
                f"motion blur {max_blur * exposure / limit:.3g} px > limit {max_blur:g} px "
                f"(exposure above {_fmt('max_exposure_s', limit)})",
                ("exposure_s",),
                ("operation.exposure_s", "operation.max_blur_px", "operation.speed_m_s"),
            )
        )
    required, dof = design["operation.min_dof_m"], result.get("dof_m")
    if required is not None and dof is not None and dof["far"] is not None and dof["far"] - dof["near"] < required:
        needed = result.get("min_f_number_for_dof")
        hint = f"; needs f-number ≥ {_fmt('min_f_number_for_dof', needed)}" if needed is not None else ""
        found.append(
            DesignWarning(
                "dof",
                f"depth of field {dof['far'] - dof['near']:.3f} m < required {float(required):g} m{hint}",
                ("dof_m",),
                ("lens.f_number", "operation.min_dof_m", "operation.altitude_m"),
            )
        )
    return found


def table_text(result: dict, warnings: list[DesignWarning] = ()) -> str:
    """The text table of `uwlab design`: one row per output, warnings beside the row they concern, then the
    light lost per stage with the largest loss marked."""
    notes: dict[str, list[str]] = {}
    for warning in warnings:
        notes.setdefault(warning.outputs[0], []).append(warning.message)
    lines = []
    table = rows(result)
    width = max([32, *(len(row.label) for row in table)])
    for row in table:
        line = f"{row.label:<{width}} {row.text} {row.unit}".rstrip()
        if row.key in notes:
            line += "   ⚠ " + "; ".join(notes[row.key])
        lines.append(line)
    if result.get(BUDGET_KEY):
        stage_rows, worst, total = budget_rows(result[BUDGET_KEY])
        lines.append("light lost per stage (stops)")
        for row in stage_rows:
            lines.append(f"  {row.label:<30} {row.text}" + ("  ← limits the signal most" if row.key == worst else ""))
        lines.append(f"  {'total (lights → electrons)':<30} {total}")
    return "\n".join(lines)
