"""Every shipped supply definition against the CV/CC supply twin with an LED load (`uwlab.sim.devices.supply`, written
from the manuals, served over TCP on the loopback and reached through pyvisa-py as a real supply is): from its reset
state (output off, 0 V) each delivers the requested current within 1 % in CC; an open LED, a short across it and a
voltage limit below its forward voltage are each refused in one line with the output off; ``uwlab light`` prints the
set and measured current and the mode; a sweep records the load's current per point and records no point once the
LED opens mid-sweep. The truth the driver cannot see is the twin's own operating point (`SupplyTwin.point`)."""

from __future__ import annotations

import json

import pytest

from tests.support.cli import one_line_error
from tests.support.plans import write_plan
from uwlab.cli.main import main
from uwlab.drivers.instruments import open_visa_light
from uwlab.errors import DeviceError
from uwlab.experiments.acquisition.plan import load_plan
from uwlab.experiments.acquisition.session import run_session
from uwlab.experiments.dataset import Dataset
from uwlab.sim.devices.supply import SupplyTwin, serve

SUPPLIES = {"rigol-dp800": "rigol-dp800", "keysight-e36100": "keysight-e36100", "scpi-dc-supply": "scpi"}
RIG_MAX_A = 0.7  # the LED's rating: level 1


@pytest.fixture(params=sorted(SUPPLIES))
def bench(request):
    twin = SupplyTwin(SUPPLIES[request.param], seed=1)
    with serve(twin, transport="tcp") as resource:
        yield request.param, twin, resource


def test_every_supply_from_reset_delivers_the_requested_current_within_one_percent(bench):
    name, twin, resource = bench
    assert twin.voltage_set_v == 0.0 and not twin.output_on  # the reset state: an LED on it would stay dark
    with open_visa_light(name, resource, "@py", max_drive=RIG_MAX_A) as light:
        for level in (0.05, 0.5, 1.0):
            light.set_level(level)
            light.set_output(True)
            truth = twin.point()
            assert truth.mode == "CC"
            assert truth.current_a == pytest.approx(level * RIG_MAX_A, rel=0.01)
            state = light.state()
            assert state["mode"] == "CC" and state["delivery"] == "ok"
            assert state["measured_current_a"] == pytest.approx(truth.current_a, rel=0.01)
        assert twin.voltage_set_v == pytest.approx(5.0)  # the compliance: 4 V assumed forward voltage + 1 V margin
    assert not twin.output_on  # dark on exit


@pytest.mark.parametrize(
    ("fault", "said"),
    [
        ("open", "for 0.350 A set: open circuit or voltage limit 5.0 V?"),
        ("short", "a short across the LED?"),
        ("knob", "for 0.350 A set: open circuit or voltage limit 2.7 V?"),  # the limit turned down on the front panel
        ("compliance", "open circuit or voltage limit 2.5 V?"),  # the rig's forward voltage given too low
    ],
)
def test_an_open_a_short_and_a_low_voltage_limit_are_refused_with_the_output_off(bench, fault, said):
    name, twin, resource = bench
    forward = 1.5 if fault == "compliance" else None
    with open_visa_light(name, resource, "@py", max_drive=RIG_MAX_A, forward_voltage_v=forward) as light:
        light.set_level(0.5)
        if fault in ("open", "short"):
            twin.set_fault(fault)
        elif fault == "knob":
            twin.voltage_limit_v = 2.7  # below the LED's ~2.96 V at 0.35 A
        with pytest.raises(DeviceError) as refused:
            light.set_output(True)
        assert said in str(refused.value) and "output switched off" in str(refused.value)
        assert "\n" not in str(refused.value)
        assert not twin.output_on and light.output() is False


@pytest.mark.parametrize("transport", ["tcp", "pty"])
def test_the_led_driver_and_a_supply_on_a_serial_line_deliver_too(transport):
    # the DC2200 (an LED driver: no voltage limit to set, it reports an open LED itself) over TCP; a generic SCPI
    # supply on a serial line (pyvisa-py ASRL on the twin's pseudo-terminal)
    name, dialect = ("thorlabs-dc2200", "thorlabs-dc2200") if transport == "tcp" else ("scpi-dc-supply", "scpi")
    twin = SupplyTwin(dialect, seed=5)
    with serve(twin, transport=transport) as resource, open_visa_light(name, resource, "@py", max_drive=0.7) as light:
        light.set_level(0.5)
        light.set_output(True)
        assert twin.point().current_a == pytest.approx(0.35, rel=0.01)
        assert light.state()["measured_current_a"] == pytest.approx(0.35, rel=0.01)
        twin.set_fault("open")
        with pytest.raises(DeviceError, match="LED open" if dialect == "thorlabs-dc2200" else "open circuit"):
            light.set_level(0.6)
            light.set_output(True)
        assert not twin.output_on


def test_a_fault_after_switching_on_is_caught_at_the_next_set(bench):
    name, twin, resource = bench
    with open_visa_light(name, resource, "@py", max_drive=RIG_MAX_A) as light:
        light.set_level(0.5)
        light.set_output(True)
        twin.set_fault("open")
        assert light.state()["delivery"].startswith("measured")  # what a sweep's read-back sees
        with pytest.raises(DeviceError, match="open circuit"):
            light.set_level(0.6)
        assert not twin.output_on


def test_cli_generic_supply_with_a_makers_identity(capsys):
    twin = SupplyTwin("scpi", idn="Keysight Technologies,E36103A,MY00000001,1.0", seed=2)
    with serve(twin, transport="tcp") as resource:
        argv = ["light", "--instrument", "scpi-dc-supply", "--resource", resource, "--visa-library", "@py"]
        assert main([*argv, "--max-current-a", "0.5", "--on", "--level", "0.6", "--json"]) == 0
        state = json.loads(capsys.readouterr().out)
        assert {"on", "level", "current_a", "measured_current_a", "mode"} <= set(state)
        assert state["on"] is True and state["mode"] == "CC" and state["current_a"] == pytest.approx(0.3)
        assert state["measured_current_a"] == pytest.approx(0.3, rel=0.01)
        assert twin.output_on and twin.point().current_a == pytest.approx(0.3)  # --on leaves it on
        twin.set_fault("open")
        err = one_line_error(capsys, [*argv, "--max-current-a", "0.5", "--on", "--level", "0.6"])
        assert "open circuit or voltage limit" in err and not twin.output_on
        err = one_line_error(capsys, [*argv, "--max-current-a", "0.5", "--on", "--level", "1.2"])
        assert "level = 1.2" in err  # refused before anything is sent
        twin.set_fault(None)
        before = len(twin.received)
        err = one_line_error(capsys, [*argv, "--max-current-a", "1.5", "--on", "--level", "1"])
        assert "max_current_a = 1.5" in err and len(twin.received) == before  # above the definition's 1 A: unsent


def test_a_definition_without_a_mode_query_where_cc_checking_is_asked_is_one_line(tmp_path, capsys):
    from tests.support.paths import CONFIGS

    text = (CONFIGS / "instruments" / "scpi-dc-supply.toml").read_text()
    path = tmp_path / "no-mode.toml"
    path.write_text(text.replace('query_mode = "STAT:OPER:COND?"\n', ""))
    err = one_line_error(capsys, ["light", "--instrument", str(path), "--resource", "TCPIP::127.0.0.1::1::SOCKET"])
    assert "constant_current.query_mode" in err


def _sweep_plan(tmp_path, resource, name="twin"):
    sweep = {"id": "l", "kind": "light-level", "values": [0.25, 0.5, 0.75, 1.0], "exposure_us": 300}
    sweep |= {"frames_per_point": 2, "dark": "none"}
    light = {"name": "led", "instrument": "scpi-dc-supply", "resource": resource, "visa_library": "@py"}
    light |= {"max_current_a": RIG_MAX_A, "forward_voltage_v": 3.5}
    camera = {"backend": "sim", "pixel_format": "Mono12", "window": [0, 0, 32, 24]}
    return load_plan(write_plan(tmp_path / f"{name}.toml", name, [sweep], camera=camera, lights=[light]))


def test_a_sweep_records_the_loads_current_per_point(tmp_path):
    twin = SupplyTwin("scpi", seed=3)
    with serve(twin, transport="tcp") as resource:
        currents = []
        plan = _sweep_plan(tmp_path, resource)
        data = Dataset.open(run_session(plan, tmp_path / "d", progress=lambda e: currents.append(twin.point())))
        assert not twin.output_on
    points = data.points()
    assert points["light_current_a_readback"].tolist() == pytest.approx([0.175, 0.35, 0.525, 0.7], rel=1e-3)
    truth = [point.current_a for point in currents]  # the load's current right after each point
    assert points["light_measured_current_a"].tolist() == pytest.approx(truth, rel=0.01)
    states = [json.loads(text)["led"] for text in points["lights_readback"]]
    assert all(s["mode"] == "CC" and s["delivery"] == "ok" for s in states)
    assert [s["measured_voltage_v"] for s in states] == sorted(s["measured_voltage_v"] for s in states)  # LED curve
    assert data.metadata["lights_safe_state"]["led"]["off"] is True


def test_no_wrong_point_when_the_led_opens_mid_sweep(tmp_path):
    twin = SupplyTwin("scpi", seed=4)
    with serve(twin, transport="tcp") as resource:
        plan = _sweep_plan(tmp_path, resource, "opens")

        def open_after_second(event):
            if event.done == 2:
                twin.set_fault("open")

        with pytest.raises(DeviceError, match="open circuit or voltage limit") as stopped:
            run_session(plan, tmp_path / "d", progress=open_after_second)
        assert "\n" not in str(stopped.value) and not twin.output_on
    points = Dataset.open(tmp_path / "d").points()
    assert len(points) == 2  # the two measured before the LED opened; none after
    assert points["light_measured_current_a"].tolist() == pytest.approx([0.175, 0.35], rel=0.01)
