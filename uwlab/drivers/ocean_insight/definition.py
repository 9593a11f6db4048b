"""Instrument definitions of Ocean Insight spectrometers: ``configs/instruments/<name>.toml`` with ``adapter =
"seabreeze"``.

Keys (unknown keys are refused): ``adapter`` ("seabreeze"), ``kind`` ("spectrometer"), ``backend`` (python-seabreeze
backend: "auto" = ``cseabreeze`` where it is installed, else ``pyseabreeze``, the pure-Python one over pyusb),
``collection_area_cm2`` (A of the irradiance relation: the collecting area of the cosine corrector or fibre the
calibration was made with), ``collection_optic``, ``manual`` (the manual sections the definition follows),
``default_integration_ms`` (set on opening: seabreeze cannot read the device's integration time back, so the driver
starts from a known one), ``nonlinearity_correction`` (apply the device's stored nonlinearity polynomial, recorded
with each reading) and a ``[provenance]`` table (where each value comes from; ``collection_area_cm2`` must be
there).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal, get_args

from pydantic import Field, field_validator

from uwlab.drivers.serial.base import IntegrationMs
from uwlab.errors import ConfigError
from uwlab.model.data import config_dir, read_toml
from uwlab.model.schema import NonEmptyText, Schema, limits, parse

Backend = Literal["auto", "pyseabreeze", "cseabreeze"]
BACKENDS = get_args(Backend)
CollectionAreaCm2 = Annotated[
    float, limits(1e-5, 10.0, "cm²", lo_open=True, hint="cm², not mm² (a CC-3 cosine corrector is 0.119 cm²)")
]


class OceanInsightDefinition(Schema):
    adapter: Literal["seabreeze"]
    kind: Literal["spectrometer"]
    backend: Backend = "auto"
    collection_area_cm2: CollectionAreaCm2
    collection_optic: NonEmptyText
    manual: NonEmptyText
    default_integration_ms: IntegrationMs = Field(10.0)
    nonlinearity_correction: bool = True
    provenance: dict[str, NonEmptyText]

    @field_validator("provenance")
    @classmethod
    def _area_sourced(cls, provenance: dict[str, str]) -> dict[str, str]:
        if "collection_area_cm2" not in provenance:
            raise ValueError("must say where collection_area_cm2 comes from")
        return provenance


def instrument_path(name: str) -> Path:
    """``configs/instruments/<name>.toml`` (under ``$UWLAB_CONFIG_DIR`` when set)."""
    if not name or "/" in name or "\\" in name or name.startswith("."):
        raise ConfigError("instrument", name, "must be the name of a file in configs/instruments/ (no path)")
    return config_dir() / "instruments" / f"{name}.toml"


def load_definition(name: str) -> OceanInsightDefinition:
    """The definition ``name`` (``ConfigError`` on ``instrument`` when there is none, or on the offending key)."""
    path = instrument_path(name)
    if not path.is_file():
        known = sorted(p.stem for p in path.parent.glob("*.toml")) if path.parent.is_dir() else []
        raise ConfigError("instrument", name, f"no such instrument definition; known: {', '.join(known) or 'none'}")
    data = read_toml(path, "instrument")
    if data.get("adapter") != "seabreeze":
        raise ConfigError(f"{path.name}: adapter", data.get("adapter"), "this command needs a seabreeze spectrometer")
    return parse(OceanInsightDefinition, data, f"{path.name}:")
