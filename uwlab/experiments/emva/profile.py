"""A sensor profile (schema of ``configs/sensors/*.toml``, read by `uwlab.model.sensor.load_sensor_profile`)
from an EMVA 1288 characterisation, so that ``uwlab design`` can use a measured camera directly
(``sensor.profile = "path/to/profile.toml"``).

The profile holds values at 0 dB gain (K₀ = K / 10^(gain_dB/20), `SensorProfile.gain_k`). The QE curve is
flat at the measured η: a photon-transfer measurement gives η at the light's (photon-weighted mean)
wavelength only, so the flat curve is an assumption flagged in ``[flags]`` and explained in ``[provenance]``.
Geometry and limits come from the dataset's named sensor profile when there is one, else from the sweep
(ROI size, exposure and gain used), also flagged as assumed.
"""

from __future__ import annotations

import json
import math

from uwlab.errors import ConfigError
from uwlab.model.schema import parse
from uwlab.model.sensor import ResponseCurve, SensorProfile
from uwlab.provenance import provenance as current_provenance, provenance_line

QE_RANGE_NM = (300.0, 1100.0)


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        if isinstance(value, float) and not math.isfinite(value):
            raise ConfigError("profile", value, "non-finite value")
        return repr(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return json.dumps(str(value), ensure_ascii=False)


def _rounded(x: float, digits: int = 5) -> float:
    return float(f"{x:.{digits}g}")


def profile_documents(
    values: dict,
    *,
    name: str,
    width_px: int,
    height_px: int,
    exposure_range_us: tuple,
    pixel_size_um: float | None,
    base: SensorProfile | None = None,
    made_with: dict | None = None,
) -> tuple[str, str]:
    """(profile TOML text, QE CSV text) for the characterisation ``values`` (`EmvaResult.values`); the CSV is
    to be written as ``<name>_qe.csv`` beside the TOML. The TOML's header names the software and machine that
    measured it (``made_with``, a `uwlab.provenance.provenance` record; default this process's)."""
    size_um = pixel_size_um or (base.pixel_size_um if base else None)
    if not size_um:
        raise ConfigError("--pixel-size-um", None, "needed for a sensor profile (no sensor profile in the data)")
    gain_db = float(values["gain_db"])
    eta = float(values["quantum_efficiency"])
    lam = values.get("wavelength_nm")
    at = f"at {lam:.1f} nm (photon-weighted mean wavelength of the light)" if lam else "at the light used"
    measured = f"EMVA 1288 Release 4.0 (linear) characterisation by uwlab of {values['source']}"
    keys = {
        "name": name,
        "description": f"measured: {measured}",
        "color": False,
        "pixel_size_um": float(size_um),
        "resolution_px": list(base.resolution_px) if base else [int(width_px), int(height_px)],
        "bit_depth": int(values["bit_depth"]),
        "K_dn_per_e": _rounded(values["K_dn_per_e"] / 10 ** (gain_db / 20.0)),
        **(
            {"K_dn_per_e_std": _rounded(values["K_dn_per_e_std"] / 10 ** (gain_db / 20.0))}
            if values.get("K_dn_per_e_std")
            else {}
        ),
        "dark_offset_dn": _rounded(values["dark_offset_dn"]),
        "dark_noise_e": _rounded(values["dark_noise_e"]),
        "saturation_e": _rounded(values["saturation_e"]),
        "exposure_min_us": float(base.exposure_min_us if base else exposure_range_us[0]),
        "exposure_max_us": float(base.exposure_max_us if base else exposure_range_us[1]),
        "gain_min_db": float(base.gain_min_db if base else gain_db),
        "gain_max_db": float(base.gain_max_db if base else gain_db),
        "qe_csv": f"{name}_qe.csv",
    }
    for key in ("dark_current_e_per_s", "dsnu_e", "prnu_percent"):
        if values.get(key) is not None:
            keys[key] = _rounded(max(values[key], 0.0))
    limits = f"sensor profile {base.name}" if base else "the sweep (ROI size, exposures and gain used)"
    provenance = {
        "K_dn_per_e": f"{measured}: K = {values['K_dn_per_e']:.5g} DN/e- at {gain_db:g} dB, referred to 0 dB",
        "dark_offset_dn": f"{measured}: mean dark level at t_exp -> 0, including the camera's black level setting",
        "dark_noise_e": f"{measured}: temporal dark noise sigma_d",
        "saturation_e": f"{measured}: mu_e.sat = eta mu_p.sat at the saturation point ({values['saturation_rule']})",
        "qe_csv": f"FLAT at the measured quantum efficiency {eta:.4f} {at}; the spectral shape is not measured",
        "pixel_size_um": "--pixel-size-um" if pixel_size_um else f"sensor profile {base.name if base else ''}",
        "resolution_px": f"from {limits}",
        "exposure_min_us": f"from {limits}",
        "exposure_max_us": f"from {limits}",
        "gain_min_db": f"from {limits}",
        "gain_max_db": f"from {limits}",
    }
    for key in ("dark_current_e_per_s", "dsnu_e", "prnu_percent"):
        if key in keys:
            provenance[key] = measured
    assumed = ["qe_csv"] + (
        [] if base else ["resolution_px", "exposure_min_us", "exposure_max_us", "gain_min_db", "gain_max_db"]
    )
    lines = [
        f"# Sensor profile measured by uwlab: {measured}.",
        "# Values at 0 dB gain; the QE curve is flat at the measured eta (see [provenance], [flags]).",
        f"# Made with {provenance_line(made_with or current_provenance())}.",
        "",
    ]
    lines += [f"{k} = {_toml_value(v)}" for k, v in keys.items()]
    lines += ["", "[provenance]"] + [f"{k} = {_toml_value(v)}" for k, v in provenance.items()]
    measured_keys = [k for k, text in provenance.items() if text.startswith(measured)]
    lines += ["", "[flags]", f"measured = {_toml_value(measured_keys)}", f"assumed = {_toml_value(assumed)}", ""]
    response = values.get("response")
    if response is not None:  # the measured response curve, checked as the profile's reader will
        fields = parse(ResponseCurve, response, "response").model_dump()
        lines += ["[response]"] + [f"{k} = {_toml_value(v)}" for k, v in fields.items()] + [""]
    csv = (
        f"# Quantum efficiency of {name} [fraction]: FLAT at the value measured {at} by {measured}.\n"
        "# Assumption: the spectral shape is unknown; only the value at the measurement wavelength is measured.\n"
        f"wavelength_nm,qe\n{QE_RANGE_NM[0]:g},{eta:.6f}\n{QE_RANGE_NM[1]:g},{eta:.6f}\n"
    )
    return "\n".join(lines), csv
