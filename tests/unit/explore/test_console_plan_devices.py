"""The console on the devices a plan names (what `uwlab console PLAN.toml` opens on the tank): the plan's camera
and its [[lights]] by instrument definition — here the simulated camera backend and a Keysight E36100 on pyvisa-sim,
through the hardware rig's code path (`HardwareRig`) — with the light's drive current read back, no spectrometer,
and the light in its safe state (read back off) once the console closes."""

from __future__ import annotations

import pytest
import yaml
from starlette.testclient import TestClient

from tests.support.paths import CONFIGS
from tests.support.plans import camera, write_plan
from uwlab.errors import ConfigError
from uwlab.explore.console import create_console
from uwlab.explore.console_rig import Live, Runs, Source

KEYSIGHT_YAML = CONFIGS / "instruments" / "sim" / "keysight-e36100.yaml"
KEYSIGHT_RESOURCE = next(iter(yaml.safe_load(KEYSIGHT_YAML.read_text())["resources"]))
MAX_CURRENT_A = 1.0


def test_the_plans_devices_with_their_read_backs(tmp_path):
    plan = write_plan(
        tmp_path / "tank.toml",
        "tank",
        [{"id": "e", "kind": "exposure", "values": [100, 200]}],
        camera=camera(32, 24),
        lights=[
            {
                "name": "led",
                "instrument": "keysight-e36100",
                "resource": KEYSIGHT_RESOURCE,
                "visa_library": f"{KEYSIGHT_YAML}@sim",
                "max_current_a": MAX_CURRENT_A,
            }
        ],
    )
    live = Live(Source(plan, sim=False))
    live.start()
    try:
        with TestClient(create_console(live, Runs(live, sim=False)), base_url="http://127.0.0.1:8060") as c:
            rig = c.get("/api/rig").json()
            assert rig["camera"]["backend"] == "sim" and rig["spectrometer"] is None
            assert set(rig["lights"]) == {"led"} and rig["lights"]["led"]["on"] is False
            # The pyvisa-sim supply measures a constant 0.300 A in CC: the driver's CC check passes at that set only.
            light = c.post("/api/lights/led", json={"on": True, "level": 0.3}).json()
            assert light["on"] is True and light["level"] == pytest.approx(0.3)
            assert light["current_a"] == pytest.approx(0.3 * MAX_CURRENT_A)
            answer = c.get("/api/spectrometer")
            assert answer.status_code == 422 and "no spectrometer" in answer.json()["error"]
            assert c.post("/api/lights/led", json={"level": 1.5}).json()["key"] == "level"
            lights = live.devices.lights
    finally:
        live.close()
    assert lights["led"].safe_state_reached is True


def test_a_rig_file_without_sim_is_refused():
    with pytest.raises(ConfigError, match="simulated only"):
        Source(CONFIGS / "rigs" / "sim-tank.toml", sim=False)
