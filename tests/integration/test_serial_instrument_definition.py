"""The uwlab-ascii light through its instrument definition (configs/instruments/uwlab-ascii.toml, adapter "serial")
against the serial simulator on a real pseudo-terminal: set and read back, the definition's strings on the wire,
limits refused before sending, the safe state on exit, the CLI's JSON, an *IDN? that does not match."""

from __future__ import annotations

import json

import pytest

from uwlab.cli.main import main
from uwlab.drivers.instruments import SerialLight, open_light_instrument
from uwlab.errors import ConfigError
from uwlab.sim.devices.serial_sim import SerialRig, SerialSimSettings


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    with SerialRig(tmp_path_factory.mktemp("serial"), SerialSimSettings(), seed=3, command_log=True) as rig:
        yield rig


def sent(rig) -> list[str]:
    return rig.log_path("light").read_text().splitlines()


def test_set_and_read_back_through_the_definition(rig):
    with open_light_instrument("uwlab-ascii", str(rig.ports["light"])) as light:
        assert isinstance(light, SerialLight) and light.identity().startswith("UWLAB,")
        light.set_output(True)
        light.set_level(0.35)
        assert light.state() == {"on": True, "level": 0.35}
        before = len(sent(rig))
        with pytest.raises(ConfigError, match="level"):
            light.set_level(1.2)
        assert len(sent(rig)) == before  # nothing reached the instrument
    assert light.safe_state_reached is True
    assert [line for line in sent(rig) if line.startswith(("OUTP", "LEV"))][-1] == "OUTP?"
    assert "OUTP OFF" in sent(rig) and "LEV 0.35" in sent(rig)


def test_the_cli_drives_it_by_name(rig, capsys):
    port = str(rig.ports["light"])
    assert main(["light", "--instrument", "uwlab-ascii", "--resource", port, "--on", "--level", "0.5", "--json"]) == 0
    state = json.loads(capsys.readouterr().out)
    assert state["on"] is True and state["level"] == 0.5 and state["identity"].startswith("UWLAB,")
    assert main(["light", "--instrument", "uwlab-ascii", "--resource", port, "--off", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["on"] is False


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["--visa-library", "@py"], "is a serial instrument"),
        (["--resource", "/dev/nonexistent-uwlab-port"], "/dev/nonexistent-uwlab-port"),
    ],
)
def test_bad_input_is_one_line(rig, tmp_path, capsys, argv, expected):
    base = ["light", "--instrument", "uwlab-ascii", "--resource", str(rig.ports["light"])]
    assert main([*base, *argv, "--json"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expected in err[0]


def test_an_identity_that_does_not_match_is_refused(rig, tmp_path, capsys):
    from tests.support.paths import CONFIGS

    other = tmp_path / "other.toml"
    other.write_text((CONFIGS / "instruments" / "uwlab-ascii.toml").read_text().replace('["UWLAB"]', '["ACME"]'))
    assert main(["light", "--instrument", str(other), "--resource", str(rig.ports["light"])]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not ACME" in err[0]
