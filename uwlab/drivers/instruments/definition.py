"""Instrument definitions of lights: data, not code (``configs/instruments/NAME.toml`` with ``kind = "light"``).

A definition names ``adapter = "visa"``, the ``manual`` section its commands follow, what ``*IDN?`` must contain
(``identity_contains``: maker and model), the line settings (terminations, timeout), the drive (``drive``, e.g.
``current_a``, its ``max_drive`` the instrument accepts and the settle time after a change), the read-back
tolerance, and ``[commands]``: ``identity``, ``error`` (the error queue, e.g. ``SYST:ERR?``), ``set_output`` /
``query_output`` (``{state}`` is replaced by ``on_token`` / ``off_token``), ``set_drive`` / ``query_drive``
(``{value}`` by the drive in its unit, with ``drive_format``), where the instrument measures, ``measure``, and
``setup``: commands sent once after the identity check (a mode such as constant current), each error-checked.
A light level in [0, 1] is the drive over ``max_drive`` (a constant-current LED supply: level × max current).
Every definition says in ``[provenance]`` where ``max_drive`` comes from.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, ClassVar, Literal

from pydantic import Field, field_validator, model_validator

from uwlab.errors import ConfigError
from uwlab.model.data import config_dir, read_toml
from uwlab.model.schema import NonEmptyText, Schema, limits, parse

DriveMax = Annotated[float, limits(1e-6, 100.0, "A or V", lo_open=True, hint="amperes (or volts), not mA")]
SettleS = Annotated[float, limits(0.0, 10.0, "s")]
TimeoutMs = Annotated[float, limits(10.0, 60000.0, "ms")]


class LightCommands(Schema):
    """The command strings of a light (module docstring)."""

    identity: NonEmptyText = "*IDN?"
    error: NonEmptyText | None = Field(None, description="error queue query; None: the instrument has none")
    set_output: NonEmptyText
    query_output: NonEmptyText
    set_drive: NonEmptyText
    query_drive: NonEmptyText
    measure: NonEmptyText | None = Field(None, description="measured drive (e.g. MEAS:CURR?), where it measures")
    setup: list[NonEmptyText] = Field(
        [], description="commands sent once after the identity check (e.g. SOUR1:MODE CC), each error-checked"
    )

    @field_validator("set_output")
    @classmethod
    def _has_state(cls, text: str) -> str:
        if "{state}" not in text:
            raise ValueError("must contain {state}")
        return text

    @field_validator("set_drive")
    @classmethod
    def _has_value(cls, text: str) -> str:
        if "{value}" not in text:
            raise ValueError("must contain {value}")
        return text


class LightDefinition(Schema):
    """A light instrument definition (module docstring)."""

    adapter: Literal["visa"]
    kind: Literal["light"]
    manual: NonEmptyText
    identity_contains: list[NonEmptyText] = Field(min_length=1)
    drive: Literal["current_a", "voltage_v"]
    max_drive: DriveMax
    drive_format: NonEmptyText = ".4f"
    readback_tolerance: Annotated[float, limits(0.0, 1.0, "A or V")] = 0.001
    settle_s: SettleS = 0.0
    on_token: NonEmptyText = "1"
    off_token: NonEmptyText = "0"
    read_termination: str = "\n"
    write_termination: str = "\n"
    timeout_ms: TimeoutMs = 2000.0
    commands: LightCommands
    provenance: dict[str, NonEmptyText]

    @model_validator(mode="after")
    def _sourced(self) -> LightDefinition:
        if "max_drive" not in self.provenance:
            raise ValueError("[provenance] must say where max_drive comes from")
        return self

    @property
    def measured_key(self) -> str:
        """The read-back key of the measured drive, e.g. ``measured_current_a``."""
        return f"measured_{self.drive}"


class SerialLightCommands(Schema):
    """The command strings of a light on a serial line protocol (``{state}``: ``on_token``/``off_token``;
    ``{value}``: the level in [0, 1])."""

    identity: NonEmptyText = "*IDN?"
    set_output: NonEmptyText
    query_output: NonEmptyText
    set_drive: NonEmptyText
    query_drive: NonEmptyText
    on_token: NonEmptyText = "1"
    off_token: NonEmptyText = "0"

    @field_validator("set_output")
    @classmethod
    def _has_state(cls, text: str) -> str:
        if not text.endswith(" {state}"):
            raise ValueError("must be '<header> {state}'")
        return text

    @field_validator("set_drive")
    @classmethod
    def _has_value(cls, text: str) -> str:
        if not text.endswith(" {value}"):
            raise ValueError("must be '<header> {value}'")
        return text


class SerialLightDefinition(Schema):
    """A light on a serial port speaking an acknowledged line protocol (``protocol = "uwlab-ascii"``: every
    command answered OK or ERR, docs/serial-protocol.md); the level in [0, 1] is the drive."""

    adapter: Literal["serial"]
    kind: Literal["light"]
    manual: NonEmptyText
    protocol: Literal["uwlab-ascii"]
    identity_contains: list[NonEmptyText] = Field(min_length=1)
    baudrate: Annotated[int, limits(300, 4_000_000, "Bd", integer=True, hint="")] = 115200
    timeout_ms: TimeoutMs = 1000.0
    retries: Annotated[int, limits(0, 100, "attempts", integer=True, hint="")] = 3
    reopen_s: Annotated[float, limits(0.0, 3600.0, "s")] = 5.0
    commands: SerialLightCommands
    provenance: dict[str, NonEmptyText]

    drive: ClassVar[str] = "level"  # the level in [0, 1] is what the instrument is set to


def definition_path(name_or_file: str) -> Path:
    """``configs/instruments/<name>.toml`` for a bare name, else the file given."""
    if name_or_file.endswith(".toml") or "/" in name_or_file:
        return Path(name_or_file)
    return config_dir() / "instruments" / f"{name_or_file}.toml"


def load_light_definition(name_or_file: str) -> LightDefinition:
    """The light definition `name_or_file` (a name in configs/instruments/ or a TOML file); `ConfigError` naming
    the instrument when there is none, or the offending key."""
    path = definition_path(name_or_file)
    if not path.is_file():
        folder = config_dir() / "instruments"
        known = sorted(p.stem for p in folder.glob("*.toml")) if folder.is_dir() else []
        raise ConfigError("instrument", name_or_file, f"no such instrument definition; known: {', '.join(known)}")
    data = read_toml(path, "instrument")
    if data.get("kind") != "light" or data.get("adapter") != "visa":
        raise ConfigError("instrument", name_or_file, "is not a VISA light definition (adapter/kind)")
    return parse(LightDefinition, data, f"{path.name}:")


def load_any_light_definition(name_or_file: str) -> LightDefinition | SerialLightDefinition:
    """The light definition `name_or_file`, over VISA (`LightDefinition`) or a serial line
    (`SerialLightDefinition`), by its ``adapter``; `ConfigError` naming the instrument or the key otherwise."""
    path = definition_path(name_or_file)
    if path.is_file():
        data = read_toml(path, "instrument")
        if data.get("kind") == "light" and data.get("adapter") == "serial":
            return parse(SerialLightDefinition, data, f"{path.name}:")
    return load_light_definition(name_or_file)
