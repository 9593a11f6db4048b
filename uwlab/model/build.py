"""Building a `Design` from a design config: validation (`uwlab.model.config`), file and name resolution, the
sensor's ranges; the spectral weights are resolved at once so that a bad spectrum, water or curve fails here."""

from __future__ import annotations

from pathlib import Path

from uwlab.model.config import apply_override, load_raw, validate
from uwlab.model.data import resolve_path
from uwlab.model.design import Design
from uwlab.model.grid import WavelengthGrid
from uwlab.model.schema import within
from uwlab.model.sensor import load_sensor_profile
from uwlab.model.spectra import NAMED_SPECTRA
from uwlab.model.target import NAMED_REFLECTANCE
from uwlab.model.water import WATER_TYPES
from uwlab.model.weights import spectral_weights


def _resolve(value, base: Path | None, names: tuple[str, ...] = ()):
    """Names stay names; anything else that is a string is a path relative to the config file."""
    if isinstance(value, str) and value not in names:
        return str(resolve_path(value, base))
    return value


def build_design(raw: dict, base_dir: Path | None = None) -> Design:
    """Validate a raw config dict and resolve its data; raises ConfigError naming the offending key."""
    values = validate(raw)
    sp = values["spectral"]
    grid = WavelengthGrid(sp["start_nm"], sp["stop_nm"], sp["step_nm"])
    light, sensor_cfg = values["light"], values["sensor"]
    light["spectrum"] = _resolve(light["spectrum"], base_dir, NAMED_SPECTRA)
    values["water"]["type"] = _resolve(values["water"]["type"], base_dir, WATER_TYPES)
    refl = values["target"]["reflectance"]
    values["target"]["reflectance"] = NAMED_REFLECTANCE.get(refl, refl) if isinstance(refl, str) else refl
    values["target"]["reflectance"] = _resolve(values["target"]["reflectance"], base_dir)
    values["lens"]["transmittance"] = _resolve(values["lens"]["transmittance"], base_dir)
    sensor = load_sensor_profile(sensor_cfg["profile"], base_dir)
    if sensor_cfg["bit_depth"] is None:
        sensor_cfg["bit_depth"] = sensor.bit_depth
    within("sensor.gain_db", sensor_cfg["gain_db"], sensor.gain_min_db, sensor.gain_max_db, f"{sensor.name}'s range")
    exposure = values["operation"]["exposure_s"]
    if not isinstance(exposure, str):
        within(
            "operation.exposure_s",
            exposure,
            sensor.exposure_min_us * 1e-6,
            sensor.exposure_max_us * 1e-6,
            f"{sensor.name}'s range",
        )
    design = Design(values=values, grid=grid, sensor=sensor, base_dir=base_dir)
    spectral_weights(design)  # resolve spectra, water and curves now, so bad names fail before evaluation
    return design


def load_design(path: str | Path, overrides: dict | None = None) -> Design:
    """Read a design TOML, apply ``{"section.key": value}`` overrides, validate and resolve."""
    raw = load_raw(path)
    for dotted, value in (overrides or {}).items():
        apply_override(raw, dotted, value)
    return build_design(raw, Path(path).resolve().parent)
