"""More of the conformance suite, over every shipped VISA light definition and its pyvisa-sim twin (a new definition
file adds its rows): the simulator answers exactly the definition's strings, refused values never reach the wire,
the instrument's own refusals come back from its error queue, setup commands leave the queue empty, and a resource
that does not exist or does not answer is one line, exit 2."""

from __future__ import annotations

import tomllib

import pytest
import yaml

from tests.support.paths import CONFIGS
from uwlab.cli.main import main
from uwlab.drivers.instruments import load_light_definition, open_visa_light
from uwlab.errors import ConfigError, DeviceError

DEFINITIONS = sorted(
    p.stem for p in (CONFIGS / "instruments").glob("*.toml") if tomllib.loads(p.read_text()).get("adapter") == "visa"
)


def simulator(name):
    path = CONFIGS / "instruments" / "sim" / f"{name}.yaml"
    return path, next(iter(yaml.safe_load(path.read_text())["resources"])), f"{path}@sim"


class Wire:
    """Records every write and query sent to a PyVISA resource (and passes it on)."""

    def __init__(self, resource):
        self.sent: list[str] = []
        self._write, self._query = resource.write, resource.query
        resource.write = self.write
        resource.query = self.query

    def write(self, text, *args, **kwargs):
        self.sent.append(text)
        return self._write(text, *args, **kwargs)

    def query(self, text, *args, **kwargs):
        self.sent.append(text)
        return self._query(text, *args, **kwargs)


ON_LEVEL, RIG_MAX_A = 0.5, 0.6  # the pyvisa-sim twins' load draws 0.300 A: the only current delivered when on


@pytest.fixture(params=DEFINITIONS)
def opened(request):
    _, resource, library = simulator(request.param)
    with open_visa_light(request.param, resource, library, max_drive=RIG_MAX_A) as light:
        yield light


@pytest.mark.parametrize("name", DEFINITIONS)
def test_the_simulator_answers_the_definitions_own_strings(name):
    path, _, _ = simulator(name)
    text = path.read_text()
    definition = load_light_definition(name)
    c = definition.commands
    header = path.read_text().splitlines()[0]
    assert f"configs/instruments/{name}.toml" in header  # each simulator says which definition it twins
    cc = definition.constant_current
    more = [] if cc is None else [cc.query_voltage, cc.measure_voltage, cc.query_mode, *cc.protection_setup]
    for query in [c.identity, c.query_output, c.query_drive, c.measure, c.error, *c.setup, *more]:
        if query is not None:
            assert f'"{query}"' in text or f'"{query.split()[0]} ' in text, query
    assert f'"{c.set_output.split("{state}")[0]}' in text
    assert f'"{c.set_drive.replace("{value}", "{:" + definition.drive_format + "}")}"' in text
    if cc is not None:
        for command in (cc.set_voltage, cc.set_ovp):
            assert command is None or f'"{command.replace("{value}", "{:" + cc.voltage_format + "}")}"' in text
        if cc.set_ocp is not None:
            assert f'"{cc.set_ocp.replace("{value}", "{:" + definition.drive_format + "}")}"' in text
    assert definition.manual and "max_drive" in definition.provenance


def test_refused_values_never_reach_the_wire(opened):
    opened.set_level(0.3)
    wire = Wire(opened._resource)
    full = opened.max_drive
    for refuse in (
        lambda: opened.set_level(1.0001),
        lambda: opened.set_level(-0.01),
        lambda: opened.set_drive(full * 1.01),
    ):
        with pytest.raises(ConfigError):
            refuse()
    assert wire.sent == []  # nothing written, nothing asked
    assert opened.level() == pytest.approx(0.3, abs=opened.level_tolerance)


def test_a_rig_maximum_is_enforced_before_sending(opened):
    wire = Wire(opened._resource)
    with pytest.raises(ConfigError, match=opened.definition.drive):
        opened.set_drive(RIG_MAX_A * 1.25)
    assert wire.sent == []


def test_the_instruments_own_refusal_comes_from_its_error_queue(opened):
    d = opened.definition
    opened.set_level(0.5)
    beyond = d.commands.set_drive.format(value=format(d.max_drive * 10, d.drive_format))  # bypasses our limits
    with pytest.raises(DeviceError, match=f"{opened.name} on .*gave the error"):
        opened._set(beyond)
    assert opened.level() == pytest.approx(0.5, abs=opened.level_tolerance)  # the instrument kept its setting


def test_setup_and_sets_leave_the_error_queue_empty(opened):
    opened.set_level(0.7)
    opened.set_level(ON_LEVEL)
    opened.set_output(True)
    answer = opened._query(opened.definition.commands.error)
    assert int(float(answer.split(",")[0])) == 0, answer


def test_a_resource_that_does_not_exist_is_one_line(capsys):
    name = DEFINITIONS[0]
    _, resource, library = simulator(name)
    missing = resource.replace(resource.split("::")[-2], "NOSUCH")
    assert main(["light", "--instrument", name, "--resource", missing, "--visa-library", library, "--json"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "NOSUCH" in err[0] and "resource" in err[0]


def test_a_resource_that_does_not_answer_times_out_in_one_line(tmp_path, capsys):
    name = "keysight-e36100"
    path, resource, _ = simulator(name)
    mute = tmp_path / "mute.yaml"
    mute.write_text(path.read_text().replace('- q: "*IDN?"', '- q: "*IDN-NOT?"'))
    definition = tmp_path / "fast.toml"
    text = (CONFIGS / "instruments" / f"{name}.toml").read_text()
    definition.write_text(text.replace("settle_s = 0.0", "settle_s = 0.0\ntimeout_ms = 50"))
    argv = ["light", "--instrument", str(definition), "--resource", resource, "--visa-library", f"{mute}@sim"]
    assert main([*argv, "--json"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no answer to '*IDN?'" in err[0]
