"""Instrument definitions of lights: data, not code (``configs/instruments/NAME.toml`` with ``kind = "light"``).

A definition names ``adapter = "visa"``, the ``manual`` section its commands follow, what ``*IDN?`` must contain
(``identity_contains``: maker and model; an empty list for a generic definition: every answer must have the four
IEEE 488.2 fields, maker, model, serial and firmware), the line settings (terminations, timeout), the drive
(``drive``, e.g. ``current_a``, its ``max_drive`` the instrument accepts and the settle time after a change), the
read-back tolerance (absolute
``readback_tolerance`` and relative ``readback_relative``, `LightDefinition.tolerance`), and ``[commands]``:
``identity``, ``error`` (the error queue, e.g. ``SYST:ERR?``), ``set_output`` / ``query_output`` (``{state}`` is
replaced by ``on_token`` / ``off_token``), ``set_drive`` / ``query_drive`` (``{value}`` by the drive in its unit,
with ``drive_format``), where the instrument measures, ``measure``, and ``setup``: commands sent once after the
identity check (a mode such as constant current), each error-checked, none of which may set an output level.
A light level in [0, 1] is the drive over ``max_drive`` (a constant-current LED supply: level × max current).
Every definition says in ``[provenance]`` where ``max_drive`` comes from.

A CV/CC bench supply driving an LED also has ``[constant_current]`` (`ConstantCurrent`): how it is put in
constant-current mode (the voltage limit, "compliance": the LED's maximum forward voltage plus a margin, never above
the supply's ``voltage_rating_v``; over-voltage and over-current protection where it has them) and how it tells CC
from CV (``query_mode``: a text answer, ``cc_answer``, or a status register bit, ``cc_bit``).

Set points that cannot exceed the rating, by construction (issue 36): every command string is printable ASCII
without ``;`` (a second command) and may use only its own placeholder (``set_drive`` and the constant-current set
commands exactly one ``{value}``, ``set_output`` exactly one ``{state}``, every other none); the tokens and
terminations hold no command separator; ``drive_format`` is a fixed-point format (``.Nf``, a plain decimal number);
``setup`` commands may not set or recall an output level (`LEVEL_HEADERS`). The driver checks every value as it will
be sent, after formatting (`uwlab.drivers.instruments.visa_light.VisaLight`).
"""

from __future__ import annotations

import re
import string
from pathlib import Path
from typing import Annotated, ClassVar, Literal

from pydantic import AfterValidator, Field, StrictBool, field_validator, model_validator

from uwlab.errors import ConfigError
from uwlab.model.data import config_dir, read_toml
from uwlab.model.schema import NonEmptyText, Schema, invalid, limits, parse

DriveMax = Annotated[float, limits(1e-6, 100.0, "A or V", lo_open=True, hint="amperes (or volts), not mA")]
SettleS = Annotated[float, limits(0.0, 10.0, "s")]
TimeoutMs = Annotated[float, limits(10.0, 60000.0, "ms")]
VoltageV = Annotated[float, limits(0.0, 1000.0, "V", lo_open=True, hint="volts, not mV")]
MarginV = Annotated[float, limits(0.0, 100.0, "V", hint="volts, not mV")]
RelativeTolerance = Annotated[float, limits(0.0, 0.5, "", hint="a fraction of the set value (0.01: 1 %)")]

# Command headers (any SCPI mnemonic, long or short form) that set or recall an output level: never in ``setup``,
# where no limit could be checked; the drive goes through ``set_drive``, the voltage limit through
# ``[constant_current]``, both checked as sent.
LEVEL_HEADERS = ("CUR", "VOLT", "OUTP", "APPL", "POW", "LEV", "*RCL", "RCL", "LIST", "PROG", "SEQ", "TRIG", "INIT")
TERMINATIONS = ("\n", "\r\n", "\r")
# A set value is never read back (or measured) further than this fraction of itself from what was set, whatever
# the absolute tolerance: 0 A read back for a 5e-5 A set is a failure (`LightDefinition.tolerance`).
MAX_RELATIVE_DEVIATION = 0.1
DRIVE_FORMAT = re.compile(r"\.[0-9]f")
NUMBER = re.compile(r"(?<![A-Za-z0-9_])[-+]?(\d+\.?\d*|\.\d+)")  # a numeric argument (not the 1 of CH1)


def _printable(text: str) -> str:
    """Printable ASCII without ``;``: one command, nothing the line could split into a second one."""
    bad = next((c for c in text if not " " <= c <= "~" or c == ";"), None)
    if bad is not None:
        raise ValueError(f"{bad!r} inside a command: printable ASCII only, no ';' or line terminators")
    return text


def _placeholders(text: str) -> list[str]:
    """The replacement fields of a command string, as `str.format` reads them (``{value}`` → ``value``; a field
    with a conversion or format spec keeps it, ``{value:x}`` → ``value:x``); `ValueError` for unbalanced braces."""
    fields = []
    for _, name, spec, conversion in string.Formatter().parse(text):
        if name is not None:
            fields.append(name + (f"!{conversion}" if conversion else "") + (f":{spec}" if spec else ""))
    return fields


def placeholder_error(text: str, allowed: str | None) -> str | None:
    """Why ``text`` is not a command with exactly one ``{allowed}`` (None: with no placeholder at all), or None.
    (No braces in the reason: it becomes a message template.)"""
    try:
        fields = _placeholders(text)
    except ValueError:
        return "has an unbalanced brace"
    if allowed is None:
        return "may not contain a placeholder or brace" if fields or "{" in text or "}" in text else None
    if fields != [allowed]:
        shown = ", ".join(repr(f) for f in fields) or "none"
        return f"must hold exactly one placeholder, {allowed!r} in braces, and no other (has: {shown})"
    return None


def level_header(command: str) -> str | None:
    """The header of ``command`` when it sets or recalls an output level (`LEVEL_HEADERS`), else None."""
    header = command.strip().split(" ")[0].upper()
    return header if any(word in header for word in LEVEL_HEADERS) else None


Command = Annotated[str, Field(min_length=1, strict=True), AfterValidator(_printable)]
Token = Annotated[str, Field(min_length=1, strict=True), AfterValidator(_printable)]


def _check_format(text: str) -> str:
    if not DRIVE_FORMAT.fullmatch(text):
        raise ValueError("must be a fixed-point format '.Nf' (N digits after the point, 0-9): a plain decimal number")
    return text


def _check_termination(text: str) -> str:
    if text not in TERMINATIONS:
        raise ValueError("must be one of '\\n', '\\r\\n', '\\r'")
    return text


NumberFormat = Annotated[str, Field(strict=True), AfterValidator(_check_format)]
Termination = Annotated[str, Field(strict=True), AfterValidator(_check_termination)]


def _placeholder_rules(model: Schema, rules: dict[str, str | None]) -> None:
    """Every command field of ``model`` has exactly its allowed placeholder (`placeholder_error`); `invalid`
    naming the field otherwise."""
    for key, allowed in rules.items():
        value = getattr(model, key)
        texts = value if isinstance(value, list) else [value]
        for index, text in enumerate(texts):
            if text is None:
                continue
            problem = placeholder_error(text, allowed)
            name = f"{key}.{index}" if isinstance(value, list) else key
            if problem is not None:
                raise invalid(name, text, problem)


class LightCommands(Schema):
    """The command strings of a light (module docstring)."""

    identity: Command = "*IDN?"
    error: Command | None = Field(None, description="error queue query; None: the instrument has none")
    set_output: Command
    query_output: Command
    set_drive: Command
    query_drive: Command
    measure: Command | None = Field(None, description="measured drive (e.g. MEAS:CURR?), where it measures")
    setup: list[Command] = Field(
        [], description="commands sent once after the identity check (e.g. SOUR1:MODE CC), each error-checked"
    )

    @model_validator(mode="after")
    def _safe(self) -> LightCommands:
        rules: dict[str, str | None] = {key: None for key in type(self).model_fields}
        _placeholder_rules(self, {**rules, "set_output": "state", "set_drive": "value"})
        for index, command in enumerate(self.setup):
            if (header := level_header(command)) is not None:
                raise invalid(
                    f"setup.{index}",
                    command,
                    f"sets an output level ({header}): setup may only hold commands that set none "
                    "(the drive goes through set_drive, the voltage limit through [constant_current])",
                )
        return self


class ConstantCurrent(Schema):
    """``[constant_current]``: how a CV/CC supply drives an LED at constant current, and how it is checked.

    The voltage limit (``set_voltage``, read back by ``query_voltage``) is the compliance voltage: the LED's maximum
    forward voltage (the rig's ``forward_voltage_v``, else this definition's assumed ``forward_voltage_v``) plus
    ``compliance_margin_v``, refused above ``voltage_rating_v``; ``set_ovp`` (over-voltage protection, where the
    supply has it) ``ovp_margin_v`` above it, never above the rating; ``set_ocp`` (over-current protection, where it
    is a level of its own) at the current limit; ``protection_setup`` switches them on (no output level allowed).
    With ``check``, after every set and switch-on with the output on, the supply must report CC (``query_mode``:
    ``cc_answer`` the text it answers, or ``cc_bit`` the bit of the status register it answers) and measure the set
    current within ``measure_tolerance_a`` / ``measure_relative`` (`LightDefinition.tolerance`) at a voltage of at
    least ``short_below_v`` (below it: a short across the LED)."""

    check: StrictBool = Field(True, description="check mode and measured current after every set and switch-on")
    voltage_rating_v: VoltageV = Field(description="the supply's maximum output voltage (data sheet)")
    set_voltage: Command = Field(description="sets the voltage limit, e.g. 'VOLT {value}'")
    query_voltage: Command = Field(description="reads the voltage limit back, e.g. 'VOLT?'")
    measure_voltage: Command | None = Field(None, description="measured output voltage, e.g. 'MEAS:VOLT?'")
    voltage_format: NumberFormat = ".3f"
    set_ovp: Command | None = Field(None, description="over-voltage protection level, e.g. 'VOLT:PROT {value}'")
    ovp_margin_v: MarginV = 0.5
    set_ocp: Command | None = Field(None, description="over-current protection level, e.g. ':OUTP:OCP:VAL CH1,{value}'")
    protection_setup: list[Command] = Field([], description="commands switching protection on (no level)")
    query_mode: Command | None = Field(None, description="the query telling CC from CV")
    cc_answer: Token | None = Field(None, description="what query_mode answers in CC (e.g. 'CC')")
    cc_bit: Annotated[int, limits(0, 15, "", integer=True, hint="")] | None = Field(
        None, description="the bit query_mode's register sets in CC (e.g. 10 for 1024)"
    )
    forward_voltage_v: VoltageV = Field(4.0, description="assumed LED maximum forward voltage (the rig's overrides)")
    compliance_margin_v: MarginV = 1.0
    short_below_v: MarginV = Field(0.5, description="a measured voltage below it with current flowing: a short")
    measure_tolerance_a: Annotated[float, limits(0.0, 1.0, "A")] = 0.002
    measure_relative: RelativeTolerance = 0.01

    @model_validator(mode="after")
    def _consistent(self) -> ConstantCurrent:
        rules: dict[str, str | None] = {
            "set_voltage": "value",
            "query_voltage": None,
            "measure_voltage": None,
            "set_ovp": "value",
            "set_ocp": "value",
            "protection_setup": None,
            "query_mode": None,
        }
        _placeholder_rules(self, rules)
        for index, command in enumerate(self.protection_setup):
            if NUMBER.search(command.strip().partition(" ")[2]):
                raise invalid(f"protection_setup.{index}", command, "may only switch protection on, not set a level")
        if self.check and self.query_mode is None:
            raise invalid("query_mode", None, "CC checking (check = true) needs the query that tells CC from CV")
        if self.query_mode is not None and (self.cc_answer is None) == (self.cc_bit is None):
            raise invalid("cc_answer", self.cc_answer, "give exactly one of cc_answer and cc_bit with query_mode")
        if self.forward_voltage_v + self.compliance_margin_v > self.voltage_rating_v:
            raise invalid(
                "forward_voltage_v",
                self.forward_voltage_v,
                f"plus the {self.compliance_margin_v:g} V margin exceeds the {self.voltage_rating_v:g} V rating",
            )
        return self


class LightDefinition(Schema):
    """A light instrument definition (module docstring)."""

    adapter: Literal["visa"]
    kind: Literal["light"]
    manual: NonEmptyText
    identity_contains: list[NonEmptyText] = Field(
        description="words *IDN? must contain (maker, model); [] for a generic definition: any instrument whose "
        "answer has the four IEEE 488.2 fields"
    )
    drive: Literal["current_a", "voltage_v"]
    max_drive: DriveMax
    drive_format: NumberFormat = ".4f"
    readback_tolerance: Annotated[float, limits(0.0, 1.0, "A or V")] = 0.001
    readback_relative: RelativeTolerance = 0.005
    settle_s: SettleS = 0.0
    on_token: Token = "1"
    off_token: Token = "0"
    read_termination: Termination = "\n"
    write_termination: Termination = "\n"
    timeout_ms: TimeoutMs = 2000.0
    commands: LightCommands
    constant_current: ConstantCurrent | None = None
    provenance: dict[str, NonEmptyText]

    @model_validator(mode="after")
    def _sourced(self) -> LightDefinition:
        if "max_drive" not in self.provenance:
            raise ValueError("[provenance] must say where max_drive comes from")
        for key in ("on_token", "off_token"):
            if placeholder_error(getattr(self, key), None) is not None:
                raise invalid(key, getattr(self, key), "may not contain a brace")
        cc = self.constant_current
        if cc is not None and self.drive != "current_a":
            raise invalid("constant_current", self.drive, "applies to a drive of current_a")
        if cc is not None and cc.check and self.commands.measure is None:
            raise invalid("commands.measure", None, "CC checking (constant_current.check) needs the measured current")
        return self

    @property
    def measured_key(self) -> str:
        """The read-back key of the measured drive, e.g. ``measured_current_a``."""
        return f"measured_{self.drive}"

    @staticmethod
    def deviation_allowed(value: float, absolute: float, relative: float) -> float:
        """How far a read-back (or measurement) of the set ``value`` may be from it: the larger of ``absolute`` and
        ``relative`` × |value|, but never more than `MAX_RELATIVE_DEVIATION` × |value| (a set of 0: ``absolute``)."""
        size = abs(value)
        if size == 0.0:
            return absolute
        return min(max(absolute, relative * size), MAX_RELATIVE_DEVIATION * size)

    def tolerance(self, value: float) -> float:
        """The read-back tolerance of a drive set to ``value`` (`deviation_allowed` of ``readback_tolerance`` and
        ``readback_relative``)."""
        return self.deviation_allowed(value, self.readback_tolerance, self.readback_relative)


MaxCurrentA = Annotated[float, limits(0.0, 100.0, "A", lo_open=True, hint="amperes, not mA")]


class LightRig(Schema):
    """What a rig says of the light an instrument drives (``uwlab light --rig FILE``, a plan's ``[[lights]]``,
    `uwlab.open_light`): the LED's rating ``max_current_a`` (the full level; refused beyond, never above the
    definition's ``max_drive``), its maximum forward voltage ``forward_voltage_v`` (a CV/CC supply's compliance
    voltage: this plus the definition's margin) and ``identity_contains``, words the instrument's ``*IDN?`` must
    contain besides the definition's (pinning the rig's own instrument, e.g. its serial number)."""

    max_current_a: MaxCurrentA | None = Field(None, description="the LED's rated current [A]: the full level")
    forward_voltage_v: VoltageV | None = Field(None, description="the LED's maximum forward voltage [V]")
    identity_contains: list[NonEmptyText] = Field([], description="words *IDN? must contain (the rig's instrument)")


def load_light_rig(path: str | Path) -> LightRig:
    """A light rig file (`LightRig`, TOML); `ConfigError` naming the key."""
    return parse(LightRig, read_toml(Path(path), "rig"), f"{Path(path).name}:")


class SerialLightCommands(Schema):
    """The command strings of a light on a serial line protocol (``{state}``: ``on_token``/``off_token``;
    ``{value}``: the level in [0, 1])."""

    identity: Command = "*IDN?"
    set_output: Command
    query_output: Command
    set_drive: Command
    query_drive: Command
    on_token: Token = "1"
    off_token: Token = "0"

    @model_validator(mode="after")
    def _safe(self) -> SerialLightCommands:
        rules: dict[str, str | None] = {key: None for key in type(self).model_fields}
        _placeholder_rules(self, {**rules, "set_output": "state", "set_drive": "value"})
        return self

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
    if not path.exists():  # a FIFO or a device is there: read_toml refuses it for what it is
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
