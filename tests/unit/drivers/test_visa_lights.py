"""Every shipped VISA light definition against its pyvisa-sim device (configs/instruments/sim/NAME.yaml, a
third-party simulator answering exactly the definition's strings): identity, set and read back, the level → drive
mapping, the error queue, limits refused before anything is sent, the safe state on exit, timeouts. A new
definition file adds its row here by itself."""

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


def sim(name):
    path = CONFIGS / "instruments" / "sim" / f"{name}.yaml"
    resource = next(iter(yaml.safe_load(path.read_text())["resources"]))
    return resource, f"{path}@sim"


def test_every_visa_definition_has_its_simulator():
    assert len(DEFINITIONS) >= 3
    for name in DEFINITIONS:
        assert (CONFIGS / "instruments" / "sim" / f"{name}.yaml").is_file(), name


RIG_MAX_A = 0.6  # level 0.5: the 0.300 A the pyvisa-sim twins' load draws (the only current delivered when on)


@pytest.fixture(params=DEFINITIONS)
def light(request):
    resource, library = sim(request.param)
    with open_visa_light(request.param, resource, library, max_drive=RIG_MAX_A) as opened:
        yield opened


def test_set_and_read_back(light):
    definition = light.definition
    assert all(word.lower() in light.identity().lower() for word in definition.identity_contains)
    light.set_level(0.4)
    assert light.state()[definition.drive] == pytest.approx(0.4 * RIG_MAX_A, abs=definition.tolerance(0.24))
    light.set_level(0.5)
    light.set_output(True)
    state = light.state()
    assert state["on"] is True
    assert state[definition.drive] == pytest.approx(0.3, abs=definition.tolerance(0.3))
    assert state["level"] == pytest.approx(0.5, abs=definition.tolerance(0.3) / RIG_MAX_A)
    assert isinstance(state[definition.measured_key], float)
    light.set_output(False)
    assert light.output() is False


def test_limits_are_refused_before_anything_is_sent(light):
    light.set_level(0.2)
    before = light.drive()
    for level in (1.01, -0.1):
        with pytest.raises(ConfigError, match="level"):
            light.set_level(level)
    with pytest.raises(ConfigError, match=light.definition.drive):
        light.set_drive(light.definition.max_drive * 1.001)
    assert light.drive() == before  # the instrument never saw the refused values


def test_a_rig_maximum_lowers_the_full_scale():
    name = DEFINITIONS[0]
    resource, library = sim(name)
    full = load_light_definition(name).max_drive
    with open_visa_light(name, resource, library, max_drive=full / 4) as light:
        light.set_level(1.0)
        assert light.drive() == pytest.approx(full / 4, abs=light.definition.readback_tolerance)
        with pytest.raises(ConfigError):
            light.set_drive(full / 2)


def test_an_instrument_error_is_refused_with_its_message(light):
    with pytest.raises(DeviceError, match="Undefined header"):
        light._set("BOGUS:COMMAND 1")


def test_the_light_goes_dark_on_any_exit(light):
    light.set_level(0.5)
    light.set_output(True)
    light.close()
    assert light.safe_state_reached is True


def test_an_error_inside_the_block_switches_it_off_even_when_asked_to_keep_it():
    name = DEFINITIONS[0]
    resource, library = sim(name)
    with pytest.raises(RuntimeError), open_visa_light(name, resource, library, max_drive=RIG_MAX_A) as light:
        light.set_level(0.5)
        light.set_output(True)
        light.keep_output = True
        raise RuntimeError("camera lost")
    assert light.safe_state_reached is True


def test_a_silent_instrument_times_out_with_one_line(light):
    light._resource.timeout = 1  # ms; an unknown query gets no answer from the simulator
    with pytest.raises(DeviceError, match="no answer to 'NOSUCH\\?'"):
        light._query("NOSUCH?")


@pytest.mark.parametrize("name", DEFINITIONS)
def test_cli_json_read_back(name, capsys):
    resource, library = sim(name)
    argv = ["light", "--instrument", name, "--resource", resource, "--visa-library", library]
    assert main([*argv, "--max-current-a", str(RIG_MAX_A), "--on", "--level", "0.5", "--json"]) == 0
    import json

    state = json.loads(capsys.readouterr().out)
    definition = load_light_definition(name)
    assert state["on"] is True and state["level"] == pytest.approx(0.5)
    assert state[definition.drive] == pytest.approx(0.5 * RIG_MAX_A, abs=definition.tolerance(0.3))


@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        (["--instrument", "no-such-light"], "instrument = 'no-such-light': no such instrument definition"),
        (["--instrument", "rigol-dp800"], "not RIGOL DP8"),
        (["--instrument", "keysight-e36100", "--level", "2"], "level = 2"),
        (["--instrument", "ocean-insight"], "is not a VISA light definition"),
    ],
)
def test_bad_input_is_one_line(extra, expected, capsys):
    resource, library = sim("keysight-e36100")
    assert main(["light", "--resource", resource, "--visa-library", library, *extra]) == 2
    err = capsys.readouterr().err
    assert expected in err and len(err.strip().splitlines()) == 1, err


def test_a_definition_missing_a_command_is_named(tmp_path, capsys):
    text = (CONFIGS / "instruments" / "keysight-e36100.toml").read_text().replace('query_drive = "CURR?"\n', "")
    (tmp_path / "broken.toml").write_text(text)
    resource, library = sim("keysight-e36100")
    argv = ["light", "--instrument", str(tmp_path / "broken.toml"), "--resource", resource, "--visa-library", library]
    assert main(argv) == 2
    assert "commands.query_drive" in capsys.readouterr().err
