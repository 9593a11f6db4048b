"""The malformed-definition campaign of issue 36: every shipped VISA light definition, and every malformed variant of
each, driven through ``uwlab light`` (in process) against its twin while the bytes the twin receives are recorded;
a drive above the limit in any of them is counted, as is any traceback. Two twins: the CV/CC supply twin with an
LED load (``physics``: `uwlab.sim.devices.supply`, over TCP through pyvisa-py, which records every line it receives)
and the pyvisa-sim devices of configs/instruments/sim/ (``pyvisa-sim``: the bytes PyVISA writes are recorded). Used by
tests/unit/drivers/test_light_definition_safety.py and benchmarks/malformed_definitions.py.

Malformed variants (`MALFORMED`): a second command smuggled into every command string, token and termination (a
newline or ``;``), an output level in ``setup`` or ``protection_setup``, placeholders a command may not use
(``{0}``, ``{other}``, ``{value}`` in ``set_output``, a format spec in the placeholder), formats that are not a
plain number (``x``, ``{``, ``%``). Valid definitions whose format rounds above the limit (`ROUNDING`: ``.0f`` with
a 1.5 A maximum, ``.1f`` with 0.45 A, a rig maximum of 5e-05 A at four decimals) are run at several levels."""

from __future__ import annotations

import contextlib
import io
import re
import tomllib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from tests.support.paths import CONFIGS
from uwlab.cli.main import main

SIM = CONFIGS / "instruments" / "sim"
DIALECTS = {"keysight-e36100": "keysight-e36100", "rigol-dp800": "rigol-dp800", "scpi-dc-supply": "scpi"}
DIALECTS["thorlabs-dc2200"] = "thorlabs-dc2200"
NUMBER = re.compile(r"(?<![A-Za-z0-9_])[-+]?(\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
LEVELS = (0.5, 0.9, 1.0)


def shipped() -> list[str]:
    """The shipped VISA light definitions (each has a twin in configs/instruments/sim/)."""
    return sorted(
        p.stem
        for p in (CONFIGS / "instruments").glob("*.toml")
        if tomllib.loads(p.read_text()).get("adapter") == "visa"
    )


def twin(name: str) -> tuple[str, str]:
    """The twin's resource and PyVISA library of the shipped definition ``name``."""
    path = SIM / f"{name}.yaml"
    return next(iter(yaml.safe_load(path.read_text())["resources"])), f"{path}@sim"


def _set(text: str, key: str, value: str, section: str = "") -> str:
    """``text`` with ``key = value`` (TOML) replacing the key's first line, or added at the top of ``section``
    (the top level when empty)."""
    line = re.compile(rf"^{re.escape(key)} = .*$", re.M)
    if line.search(text):
        return line.sub(lambda _: f"{key} = {value}", text, count=1)
    if section:
        return text.replace(f"[{section}]\n", f"[{section}]\n{key} = {value}\n", 1)
    return text.replace('kind = "light"\n', f'kind = "light"\n{key} = {value}\n', 1)


def _string(text: str) -> str:
    """A TOML basic string holding ``text`` (newlines escaped)."""
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n").replace("\r", "\\r") + '"'


def _command(definition: dict, key: str) -> str:
    return definition["commands"][key]


def _over(definition: dict) -> str:
    """A current well above the definition's maximum, as text."""
    return f"{2 * definition['max_drive'] + 0.9:.4f}"


Edit = Callable[[str, dict], str]
MALFORMED: dict[str, Edit] = {
    "drive_format x": lambda t, d: _set(t, "drive_format", '"x"'),
    "drive_format {": lambda t, d: _set(t, "drive_format", '"{"'),
    "drive_format %": lambda t, d: _set(t, "drive_format", '".4%"'),
    "drive_format e": lambda t, d: _set(t, "drive_format", '".2e"'),
    "set_drive {0}": lambda t, d: _set(t, "set_drive", _string(_command(d, "set_drive").replace("{value}", "{0}"))),
    "set_drive {other}": lambda t, d: _set(
        t, "set_drive", _string(_command(d, "set_drive").replace("{value}", "{other}"))
    ),
    "set_drive {value:.9f}": lambda t, d: _set(
        t, "set_drive", _string(_command(d, "set_drive").replace("{value}", "{value:.9f}"))
    ),
    "set_drive two values": lambda t, d: _set(
        t, "set_drive", _string(_command(d, "set_drive") + " " + _command(d, "set_drive"))
    ),
    "set_output {value}": lambda t, d: _set(
        t, "set_output", _string(_command(d, "set_output").replace("{state}", "{value}"))
    ),
    "set_drive newline": lambda t, d: _set(
        t,
        "set_drive",
        _string(_command(d, "set_drive") + "\n" + _command(d, "set_drive").replace("{value}", _over(d))),
    ),
    "set_drive ;": lambda t, d: _set(
        t, "set_drive", _string(_command(d, "set_drive") + ";" + _command(d, "set_drive").replace("{value}", _over(d)))
    ),
    "set_output ;": lambda t, d: _set(
        t,
        "set_output",
        _string(_command(d, "set_output") + ";" + _command(d, "set_drive").replace("{value}", _over(d))),
    ),
    "identity newline": lambda t, d: _set(
        t, "identity", _string("*IDN?\n" + _command(d, "set_drive").replace("{value}", _over(d))), "commands"
    ),
    "error ;": lambda t, d: _set(
        t, "error", _string(_command(d, "error") + ";" + _command(d, "set_drive").replace("{value}", _over(d)))
    ),
    "query_drive carriage return": lambda t, d: _set(
        t,
        "query_drive",
        _string(_command(d, "query_drive") + "\r" + _command(d, "set_drive").replace("{value}", _over(d))),
    ),
    "on_token newline": lambda t, d: _set(
        t, "on_token", _string("1\n" + _command(d, "set_drive").replace("{value}", _over(d)))
    ),
    "off_token ;": lambda t, d: _set(
        t, "off_token", _string("0;" + _command(d, "set_drive").replace("{value}", _over(d)))
    ),
    "write_termination": lambda t, d: _set(
        t, "write_termination", _string("\n" + _command(d, "set_drive").replace("{value}", _over(d)) + "\n")
    ),
    "setup sets current": lambda t, d: _set(
        t, "setup", "[" + _string(_command(d, "set_drive").replace("{value}", _over(d))) + "]", "commands"
    ),
    "setup recalls": lambda t, d: _set(t, "setup", '["*RCL 1"]', "commands"),
    "set_voltage ;": lambda t, d: (
        _set(t, "set_voltage", _string("VOLT {value};" + _command(d, "set_drive").replace("{value}", _over(d))))
        if "constant_current" in d
        else _set(t, "drive_format", '"{"')
    ),
    "protection_setup level": lambda t, d: (
        _set(t, "protection_setup", '["CURR:PROT 9.9"]', "constant_current")
        if "constant_current" in d
        else _set(t, "setup", '["CURR:PROT 9.9"]', "commands")
    ),
}

# Valid definitions whose format or rig maximum rounds a level's drive: (label, edit, rig max_current_a or None).
ROUNDING: dict[str, tuple[Edit, float | None]] = {
    ".0f at 1.5 A": (lambda t, d: _set(_set(t, "drive_format", '".0f"'), "max_drive", "1.5"), None),
    ".1f at 0.45 A": (lambda t, d: _set(_set(t, "drive_format", '".1f"'), "max_drive", "0.45"), None),
    ".4f, rig 5e-05 A": (lambda t, d: _set(t, "drive_format", '".4f"'), 5e-05),
    "as shipped, rig 1e-07 A": (lambda t, d: t, 1e-07),
    "as shipped": (lambda t, d: t, None),
    "as shipped, rig 0.3 A": (lambda t, d: t, 0.3),
}


@dataclass
class Wire:
    """Every message written to any PyVISA resource, as the bytes sent (termination included)."""

    sent: list[bytes] = field(default_factory=list)


@contextlib.contextmanager
def recording() -> Iterator[Wire]:
    """Record the bytes every PyVISA message-based resource writes (the twin's input), while the block runs."""
    from pyvisa.resources.messagebased import MessageBasedResource

    wire = Wire()
    original = MessageBasedResource.write_raw

    def write_raw(self, message: bytes) -> int:
        wire.sent.append(bytes(message))
        return original(self, message)

    MessageBasedResource.write_raw = write_raw  # type: ignore[method-assign]
    try:
        yield wire
    finally:
        MessageBasedResource.write_raw = original  # type: ignore[method-assign]


def over_limit(sent: list[bytes], current_limit_a: float, voltage_limit_v: float | None) -> list[str]:
    """The commands in ``sent`` (split at every terminator and ``;``, as an instrument's parser would) that carry a
    current above ``current_limit_a`` (any header naming a current, or over-current protection) or a voltage above
    ``voltage_limit_v`` (a header naming a voltage, or over-voltage protection)."""
    found = []
    for message in sent:
        for command in re.split(r"[\r\n;]", message.decode("latin-1")):
            header, _, arguments = command.strip().partition(" ")
            header = header.upper()
            values = [float(m.group(0)) for m in NUMBER.finditer(arguments)]
            current = "CUR" in header or "OCP" in header
            voltage = "VOLT" in header or "OVP" in header
            if current and any(v > current_limit_a * (1 + 1e-12) for v in values):
                found.append(command)
            elif voltage and voltage_limit_v is not None and any(v > voltage_limit_v for v in values):
                found.append(command)
            elif not (current or voltage) and "%" in arguments:
                found.append(command)
    return found


@dataclass
class Run:
    label: str
    argv: list[str]
    code: int | None
    err: str
    traceback: bool
    over: list[str]


def _run(
    argv: list[str], current_limit_a: float, voltage_limit_v: float | None, label: str, received: list[str]
) -> Run:
    """``uwlab ARGV`` in process: its exit code, stderr, whether a traceback escaped, and the commands over the limit
    in what PyVISA wrote and in what the twin says it received (``received``, appended to while it runs)."""
    err = io.StringIO()
    code: int | None
    traceback = False
    before = len(received)
    with recording() as wire, contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = main(argv)
        except BaseException:  # anything escaping the CLI is a traceback for the user
            code, traceback = None, True
    text = err.getvalue()
    seen = wire.sent + [line.encode("latin-1") for line in received[before:]]
    return Run(
        label, argv, code, text, traceback or "Traceback" in text, over_limit(seen, current_limit_a, voltage_limit_v)
    )


@contextlib.contextmanager
def _twin(name: str, kind: str) -> Iterator[tuple[str, str, list[str]]]:
    """The twin of the definition ``name``: its resource, PyVISA library and the lines it received (the physics
    twin's own record; empty for pyvisa-sim, whose input is PyVISA's recorded writes)."""
    if kind == "pyvisa-sim":
        yield (*twin(name), [])
        return
    from uwlab.sim.devices.supply import SupplyTwin, serve

    supply = SupplyTwin(DIALECTS[name], seed=0)
    with serve(supply, transport="tcp") as resource:
        yield resource, "@py", supply.received


def campaign(folder: Path, kind: str = "physics") -> list[Run]:
    """Every shipped definition and every variant of each (`MALFORMED`, `ROUNDING`), written to ``folder`` and
    driven by ``uwlab light --on --level L --json`` on its twin (``kind``: ``physics``, the CV/CC supply twin, or
    ``pyvisa-sim``); the runs, each with what went over the limit."""
    runs = []
    for name in shipped():
        text = (CONFIGS / "instruments" / f"{name}.toml").read_text()
        data = tomllib.loads(text)
        rating_v = data.get("constant_current", {}).get("voltage_rating_v")
        cases = [(label, edit, None, (1.0,)) for label, edit in MALFORMED.items()]
        cases += [(label, edit, rig, LEVELS) for label, (edit, rig) in ROUNDING.items()]
        with _twin(name, kind) as (resource, library, received):
            for label, edit, rig, levels in cases:
                path = folder / f"{kind}-{name}-{re.sub(r'[^a-z0-9]+', '-', label.lower())}.toml"
                path.write_text(edit(text, data))
                intended = tomllib.loads(path.read_text())
                limit = min(intended.get("max_drive", data["max_drive"]), data["max_drive"], rig or float("inf"))
                for level in levels:
                    argv = ["light", "--instrument", str(path), "--resource", resource, "--visa-library", library]
                    argv += [] if rig is None else ["--max-current-a", repr(rig)]
                    argv += ["--on", "--level", repr(level), "--json"]
                    runs.append(_run(argv, limit, rating_v, f"{kind} {name}: {label} @ {level}", received))
    return runs


def counts(runs: list[Run]) -> dict[str, int]:
    """The campaign's counts: runs, refusals (exit 2 in one line), over-limit set points, tracebacks."""
    return {
        "runs": len(runs),
        "refused_one_line": sum(r.code == 2 and r.err.count("\n") == 1 for r in runs),
        "accepted": sum(r.code == 0 for r in runs),
        "over_limit_set_points": sum(len(r.over) for r in runs),
        "tracebacks": sum(r.traceback for r in runs),
        "other_exits": sum(r.code not in (0, 2) for r in runs),
    }
