"""Set points that cannot exceed the rating, by construction (issue 36): every shipped and every malformed light
definition driven through its twin while the bytes it receives are recorded (`tests.support.light_campaign`): no
drive above the limit ever reaches the wire, and every refusal is one line, exit 2, no traceback. Also: the value is
checked as it will be sent, the read-back tolerance is relative as well as absolute, the generic definition accepts
any IEEE 488.2 instrument and a rig can pin its own."""

from __future__ import annotations

import pytest

from tests.support.cli import one_line_error
from tests.support.light_campaign import MALFORMED, campaign, counts, over_limit, recording, shipped, twin
from tests.support.paths import CONFIGS
from uwlab.cli.main import main
from uwlab.drivers.instruments import LightDefinition, open_visa_light
from uwlab.errors import ConfigError, DeviceError

KEYSIGHT = (CONFIGS / "instruments" / "keysight-e36100.toml").read_text()


def test_the_wire_check_sees_a_smuggled_current():
    # the detector the campaign relies on: it must flag what the audit found sent (and nothing legitimate)
    assert over_limit([b"CURR 0.5000\nCURR 1.9\n"], 1.0, None) == ["CURR 1.9"]
    assert over_limit([b":SOUR1:CURR 0.300;:OUTP CH1,ON\n"], 1.0, None) == []
    assert over_limit([b"CURR 100.0000%\n"], 1.0, None) == ["CURR 100.0000%"]
    assert over_limit([b":OUTP:OVP:VAL CH1,40.000\n"], 1.0, 30.0) == [":OUTP:OVP:VAL CH1,40.000"]


@pytest.mark.parametrize("kind", ["physics", "pyvisa-sim"])
def test_no_definition_sends_a_drive_above_its_limit(tmp_path, kind):
    runs = campaign(tmp_path, kind)
    summary = counts(runs)
    assert summary["runs"] == len(shipped()) * (len(MALFORMED) + 6 * 3)
    assert summary["over_limit_set_points"] == 0, [(r.label, r.over) for r in runs if r.over]
    assert summary["tracebacks"] == 0 and summary["other_exits"] == 0
    malformed = [r for r in runs if r.label.split(": ")[1].rsplit(" @ ", 1)[0] in MALFORMED]
    assert malformed and all(r.code == 2 and r.err.count("\n") == 1 for r in malformed)
    rounding = [r for r in runs if ".0f at 1.5 A" in r.label or ".1f at 0.45 A" in r.label or "5e-05" in r.label]
    assert all(r.code == 2 for r in rounding)  # every level refused: above the limit or not expressible
    assert any(r.code == 0 for r in runs)  # the shipped definitions still light the twin


@pytest.mark.parametrize(
    ("key", "value", "named"),
    [
        ("drive_format", '"x"', "drive_format"),
        ("drive_format", '"{"', "drive_format"),
        ("set_drive", '"CURR {0}"', "commands.set_drive"),
        ("set_drive", '"CURR {other}"', "commands.set_drive"),
        ("set_output", '"OUTP {value}"', "commands.set_output"),
    ],
)
def test_the_five_malformed_definitions_are_one_line(key, value, named, tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text(
        "\n".join(f"{key} = {value}" if line.startswith(f"{key} = ") else line for line in KEYSIGHT.splitlines())
    )
    resource, library = twin("keysight-e36100")
    with recording() as wire:
        err = one_line_error(
            capsys,
            [
                "light",
                "--instrument",
                str(path),
                "--resource",
                resource,
                "--visa-library",
                library,
                "--on",
                "--level",
                "1",
            ],
        )
    assert named in err and wire.sent == []  # refused when loaded: nothing opened, nothing sent


@pytest.mark.parametrize(
    ("value", "absolute", "relative", "allowed"),
    [
        (5e-05, 0.001, 0.005, 5e-06),  # capped at a tenth of the set value, whatever the absolute tolerance
        (0.3, 0.001, 0.005, 0.0015),  # 0.5 % of 0.3 A
        (0.1, 0.001, 0.005, 0.001),  # the absolute floor
        (0.0, 0.001, 0.005, 0.001),
    ],
)
def test_the_tolerance_is_relative_as_well_as_absolute(value, absolute, relative, allowed):
    assert LightDefinition.deviation_allowed(value, absolute, relative) == pytest.approx(allowed)


def test_zero_read_back_for_a_tiny_set_current_is_refused(tmp_path):
    # the DC2200 twin's current query always answers 0 A; a 0.8 mA rig maximum is within the 1 mA absolute tolerance
    path = CONFIGS / "instruments" / "sim" / "thorlabs-dc2200.yaml"
    stuck = tmp_path / "stuck.yaml"
    stuck.write_text(
        path.read_text().replace('q: "SOUR1:CCUR?"\n          r: "{:.4f}"', 'q: "SOUR1:CCUR?"\n          r: "0.0000"')
    )
    resource, _ = twin("thorlabs-dc2200")
    with open_visa_light("thorlabs-dc2200", resource, f"{stuck}@sim", max_drive=0.0008) as light:
        with pytest.raises(DeviceError, match="set 0.0008 reads back 0"):
            light.set_level(1.0)


def test_the_value_is_checked_as_sent(tmp_path):
    path = tmp_path / "round.toml"
    path.write_text(
        KEYSIGHT.replace('drive_format = ".4f"', 'drive_format = ".0f"').replace("max_drive = 2.0", "max_drive = 1.5")
    )
    resource, library = twin("keysight-e36100")
    with open_visa_light(str(path), resource, library) as light, recording() as wire:
        with pytest.raises(ConfigError, match="is sent as 2 by the format '.0f', above the 1.5 limit"):
            light.set_level(1.0)
        with pytest.raises(ConfigError, match="cannot express it"):
            light.set_level(0.9)  # 1.35 A would be sent as 1
    assert wire.sent == []


def test_the_generic_definition_takes_any_ieee_488_2_instrument_and_a_rig_pins_its_own(tmp_path, capsys):
    resource, library = twin("keysight-e36100")  # a Keysight twin speaks the generic SCPI commands
    argv = ["light", "--instrument", "scpi-dc-supply", "--resource", resource, "--visa-library", library]
    assert main([*argv, "--json"]) == 0
    assert '"identity": "Keysight Technologies,E36103A' in capsys.readouterr().out
    rig = tmp_path / "rig.toml"
    rig.write_text('max_current_a = 0.6\nidentity_contains = ["MY99999999"]\n')
    assert "not MY99999999" in one_line_error(capsys, [*argv, "--rig", str(rig)])
    three = tmp_path / "three.yaml"
    three.write_text(
        (CONFIGS / "instruments" / "sim" / "keysight-e36100.yaml")
        .read_text()
        .replace("Keysight Technologies,E36103A,MY00000001,1.0.3-1.0.3", "Keysight E36103A MY00000001")
    )
    err = one_line_error(capsys, [*argv[:-1], f"{three}@sim"])
    assert "not IEEE 488.2's maker,model,serial,firmware" in err


def test_vendor_definitions_keep_their_strict_identity(capsys):
    resource, library = twin("scpi-dc-supply")
    err = one_line_error(
        capsys, ["light", "--instrument", "keysight-e36100", "--resource", resource, "--visa-library", library]
    )
    assert "not Keysight E361" in err
