"""A plan's [[lights]]: each its own instrument and resource, validated when the plan loads (one line naming the key);
the deprecated light_port/protocol keep working with a one-line notice; the tank rig opens the lights by definition
and puts every one in its safe state on exit."""

from __future__ import annotations

import pytest
import yaml

from tests.support.paths import CONFIGS
from tests.support.plans import camera, write_plan
from uwlab.cli.main import main
from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.plan import load_plan
from uwlab.experiments.acquisition.rigs import HardwareRig

SWEEP = {"id": "a", "kind": "light-level", "values": [0.5]}
SIM_YAML = CONFIGS / "instruments" / "sim" / "keysight-e36100.yaml"
RESOURCE = next(iter(yaml.safe_load(SIM_YAML.read_text())["resources"]))


def light(**extra) -> dict:
    return {"instrument": "keysight-e36100", "resource": RESOURCE, "visa_library": f"{SIM_YAML}@sim", **extra}


def plan(tmp_path, *lights: dict, sweep: dict = SWEEP, **top):
    path = write_plan(tmp_path / "p.toml", "p", [sweep], camera=camera(32, 32), lights=list(lights) or None, **top)
    return load_plan(path)


def test_lights_are_named_and_their_simulator_path_is_the_plans(tmp_path):
    (tmp_path / "sim").mkdir()
    (tmp_path / "sim" / "e.yaml").write_text(SIM_YAML.read_text())
    p = plan(tmp_path, light(visa_library="sim/e.yaml@sim"), light(name="fill", level=0.3))
    assert [spec.name for spec in p.lights] == ["light0", "fill"]
    assert p.lights[0].visa_library == f"{tmp_path / 'sim' / 'e.yaml'}@sim"
    assert p.lights[1].level == 0.3 and p.notices == ()


@pytest.mark.parametrize(
    ("lights", "sweep", "key"),
    [
        ([light(instrument="no-such-light")], SWEEP, "lights[0].instrument"),
        ([light(max_current_a=5.0)], SWEEP, "lights[0].max_current_a"),  # above the E36103A's 2 A
        ([light(max_current_a=0)], SWEEP, "lights[0].max_current_a"),
        ([light(resource="")], SWEEP, "lights[0].resource"),
        ([light(name="x"), light(name="x")], SWEEP, "lights[1].name"),
        ([light()], {**SWEEP, "light": "nope"}, "sweep.a.light"),
        ([light(), light()], SWEEP, None),  # two lights, default names: fine
        ([{"instrument": "uwlab-ascii", "resource": "/dev/ttyUSB0", "visa_library": "@py"}], SWEEP, "lights[0].visa"),
        ([{"instrument": "uwlab-ascii", "resource": "/dev/ttyUSB0", "max_current_a": 1.0}], SWEEP, "lights[0].max_"),
    ],
)
def test_bad_lights_name_the_key(tmp_path, lights, sweep, key):
    if key is None:
        assert len(plan(tmp_path, *lights, sweep=sweep).lights) == 2
        return
    with pytest.raises(ConfigError) as error:
        plan(tmp_path, *lights, sweep=sweep)
    assert error.value.key.startswith(key), error.value


def test_light_port_still_works_with_a_one_line_notice(tmp_path):
    p = plan(tmp_path, instruments={"light_port": "/dev/ttyUSB0", "protocol": "uwlab-ascii"})
    assert p.instruments.light_port == "/dev/ttyUSB0"
    assert len(p.notices) == 1 and "\n" not in p.notices[0]
    assert "instruments.light_port and instruments.protocol" in p.notices[0] and "[[lights]]" in p.notices[0]
    with pytest.raises(ConfigError, match="either"):
        plan(tmp_path, light(), instruments={"light_port": "/dev/ttyUSB0"})


def test_the_sweep_cli_prints_the_notice_once(tmp_path, capsys):
    path = write_plan(
        tmp_path / "old.toml", "old", [SWEEP], camera=camera(32, 32), instruments={"light_port": str(tmp_path / "no")}
    )
    assert main(["sweep", str(path), "--out", str(tmp_path / "d"), "--non-interactive"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert sum("deprecated: instruments.light_port" in line for line in err) == 1
    assert "no" in err[-1]  # then the port that does not open, in one line


def test_the_tank_rig_opens_lights_by_definition_and_leaves_them_dark(tmp_path):
    p = plan(tmp_path, light(name="led", max_current_a=0.6), light(name="fill", level=0.25))
    with HardwareRig(p) as rig:
        assert list(rig.lights) == ["led", "fill"] and rig.light is rig.lights["led"]
        assert rig.hold_levels == {"led": 1.0, "fill": 0.25}
        rig.light.set_level(0.5)
        rig.light.set_output(True)  # the pyvisa-sim twin's LED draws 0.3 A: delivered in CC
        assert rig.light.state()["current_a"] == pytest.approx(0.3)  # half the rig's 0.6 A, not of the 2 A rating
    assert rig.safe_states == {"led": True, "fill": True}


def test_a_light_that_does_not_open_leaves_the_others_dark(tmp_path):
    p = plan(tmp_path, light(name="led"), light(name="gone", resource="USB0::0x0::0x0::NOPE::INSTR"))
    with pytest.raises(ConfigError, match="NOPE"), HardwareRig(p):
        pass


def test_points_written_before_the_light_current_columns_still_read():
    import pyarrow as pa

    from uwlab.experiments.dataset import POINT_SCHEMA
    from uwlab.experiments.dataset_store import conform

    new = ("light_current_a_readback", "light_measured_current_a", "lights_readback")
    old_schema = pa.schema([f for f in POINT_SCHEMA if f.name not in new])
    row = {name: None for name in old_schema.names} | {"sweep_id": "a", "point_index": 0, "light_level_readback": 0.5}
    table = conform(pa.Table.from_pylist([row], schema=old_schema), POINT_SCHEMA)
    assert table.schema == POINT_SCHEMA
    assert table.column("light_level_readback").to_pylist() == [0.5]
    assert all(table.column(name).to_pylist() == [None] for name in new)


def placed_rig(tmp_path, *names: str | None) -> str:
    """The simulated tank's rig with one [[lights]] placement per name (None: unnamed), 10 cm apart."""
    text = (CONFIGS / "rigs" / "sim-tank.toml").read_text()
    for number, name in enumerate(names):
        named = "" if name is None else f'name = "{name}"\n'
        text += f"\n[[lights]]\n{named}position_m = [{0.1 * number}, -0.1, 0.0]\n"
    path = tmp_path / "placed-rig.toml"
    path.write_text(text)
    return str(path)


def test_each_plan_light_drives_the_rig_placement_of_its_name(tmp_path):
    rig = placed_rig(tmp_path, "key", "fill")
    p = plan(tmp_path, light(name="fill", level=0.5), light(name="key"), rig=rig)
    assert {spec.name: spec.placement for spec in p.lights} == {"fill": 1, "key": 0}


def test_unnamed_placements_are_driven_in_order(tmp_path):
    p = plan(tmp_path, light(name="a"), light(name="b"), rig=placed_rig(tmp_path, None, None))
    assert [spec.placement for spec in p.lights] == [0, 1]
    # a rig that places none (the paper's light.count identical lights): no placement to drive
    assert [spec.placement for spec in plan(tmp_path, light(), light()).lights] == [None, None]


@pytest.mark.parametrize(
    ("names", "lights", "key", "says"),
    [
        ((None, None), [light()], "lights", "places 2 lights"),
        ((None,), [light(), light()], "lights", "places 1 lights"),
        (("key", "fill"), [light(name="key"), light(name="rim")], "lights[1].name", "places key, fill"),
    ],
)
def test_a_light_without_its_placement_is_refused(tmp_path, names, lights, key, says):
    with pytest.raises(ConfigError) as error:
        plan(tmp_path, *lights, rig=placed_rig(tmp_path, *names))
    assert error.value.key == key and says in str(error.value)


@pytest.mark.parametrize(
    ("extra", "key"),
    [
        ({"instrument": "thorlabs-dc2200", "forward_voltage_v": 3.4}, "lights[0].forward_voltage_v"),
        ({"forward_voltage_v": 19.5}, "forward_voltage_v"),  # + 1 V margin above the E36103A's 20 V
        ({"max_current_a": 2.5}, "lights[0].max_current_a"),
        ({"identity_contains": ["MY99999999"]}, "instrument"),  # the rig pins another supply
    ],
)
def test_a_lights_rig_keys_are_checked_before_anything_is_driven(tmp_path, extra, key):
    with pytest.raises(ConfigError) as refused:
        with HardwareRig(plan(tmp_path, light(**extra))) as rig:
            rig.light.set_level(0.1)
    assert refused.value.key == key


def test_a_lights_rig_keys_reach_the_supply(tmp_path):
    with HardwareRig(plan(tmp_path, light(forward_voltage_v=3.0, identity_contains=["MY00000001"]))) as rig:
        assert rig.light.state()["voltage_limit_v"] == pytest.approx(4.0)  # 3 V + the 1 V margin, read back
