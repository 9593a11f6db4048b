"""A sweep on the simulated rig with its light on pyvisa-sim (a plan's [[lights]], the Thorlabs DC2200 definition, an
LED driver: the CV/CC supplies' constant-current check needs a twin whose current follows the set one):
the same points as with the serial simulator's light, the light's read-back and measured current in every point,
the safe state recorded, a read-back that disagrees never recorded, several lights (one swept, the others hold)."""

from __future__ import annotations

import json

import pytest
import yaml

from tests.support.paths import CONFIGS
from tests.support.plans import camera, write_plan
from uwlab.errors import DeviceError
from uwlab.experiments.acquisition.plan import load_plan
from uwlab.experiments.acquisition.session import run_session
from uwlab.experiments.dataset import CLOCK_COLUMNS, Dataset

KEYSIGHT_YAML = CONFIGS / "instruments" / "sim" / "thorlabs-dc2200.yaml"
KEYSIGHT_RESOURCE = next(iter(yaml.safe_load(KEYSIGHT_YAML.read_text())["resources"]))
RIGOL_YAML = CONFIGS / "instruments" / "sim" / "rigol-dp800.yaml"
RIGOL_RESOURCE = next(iter(yaml.safe_load(RIGOL_YAML.read_text())["resources"]))
LEVELS = [0.25, 0.5, 1.0]  # exact at the definition's 4 decimals of ampere: the read-back is the level asked
SWEEP = {"id": "l", "kind": "light-level", "values": LEVELS, "exposure_us": 300, "frames_per_point": 4}
LIGHT_COLUMNS = ("light_current_a_readback", "light_measured_current_a", "lights_readback")


def keysight(**extra) -> dict:
    return {
        "name": "led",
        "instrument": "thorlabs-dc2200",
        "resource": KEYSIGHT_RESOURCE,
        "visa_library": f"{KEYSIGHT_YAML}@sim",
        **extra,
    }


def sweep(tmp_path, name, *sweeps, **tables):
    plan = load_plan(write_plan(tmp_path / f"{name}.toml", name, list(sweeps), camera=camera(32, 24), **tables))
    return plan, Dataset.open(run_session(plan, tmp_path / name, sim=True))


def test_a_pyvisa_sim_light_records_the_serial_simulators_points(tmp_path):
    _, serial = sweep(tmp_path, "serial", SWEEP)
    plan, visa = sweep(tmp_path, "visa", SWEEP, lights=[keysight(max_current_a=1.0)])
    assert [light.name for light in plan.lights] == ["led"]
    a, b = serial.points(), visa.points()
    assert len(a) == len(b) == len(LEVELS)
    same = [c for c in a.columns if c not in CLOCK_COLUMNS and c not in LIGHT_COLUMNS]
    assert a[same].equals(b[same])  # equal seeds, the same light state: the same frames, the same numbers
    assert a[list(LIGHT_COLUMNS[:2])].isna().all().all()  # the serial light has no drive to read back
    assert [json.loads(t)["light"]["level"] for t in a["lights_readback"]] == LEVELS
    # the VISA light's read-back in every point: the current is level x the rig's 1 A maximum
    assert b["light_current_a_readback"].tolist() == pytest.approx([0.25, 0.5, 1.0], abs=1e-3)
    assert b["light_measured_current_a"].tolist() == pytest.approx([0.499] * 3)  # what the simulator measures
    states = [json.loads(text) for text in b["lights_readback"]]
    assert [s["led"]["on"] for s in states] == [True] * 3
    assert visa.metadata["devices"]["l"]["light"].startswith("Thorlabs,DC2200")
    assert visa.metadata["lights_safe_state"]["led"]["off"] is True
    assert serial.metadata["lights_safe_state"]["light"]["off"] is True


def test_several_lights_one_swept_the_others_hold(tmp_path):
    rigol = {
        "name": "fill",
        "instrument": "rigol-dp800",
        "resource": RIGOL_RESOURCE,
        "visa_library": f"{RIGOL_YAML}@sim",
        "max_current_a": 0.6,
        "level": 0.5,
    }
    plan, data = sweep(tmp_path, "two", {**SWEEP, "light": "led"}, lights=[keysight(), rigol])
    states = [json.loads(text) for text in data.points()["lights_readback"]]
    assert [s["led"]["level"] for s in states] == pytest.approx(LEVELS)
    assert [s["fill"]["level"] for s in states] == pytest.approx([0.5] * 3)  # held while the other is swept
    assert [s["fill"]["current_a"] for s in states] == pytest.approx([0.3] * 3)  # 0.5 x the rig's 0.6 A
    assert [s["fill"]["mode"] for s in states] == ["CC"] * 3  # the supply delivering in constant current
    assert set(data.metadata["lights_safe_state"]) == {"led", "fill"}
    assert all(entry["off"] for entry in data.metadata["lights_safe_state"].values())


def test_a_light_that_reads_back_otherwise_records_no_point_and_goes_dark(tmp_path):
    # the simulator's current setter accepts any value, its query always answers 0.1 A: the read-back disagrees
    text = KEYSIGHT_YAML.read_text().replace('r: "{:.4f}"', 'r: "0.1000"')
    broken = tmp_path / "stuck.yaml"
    broken.write_text(text)
    plan = load_plan(
        write_plan(
            tmp_path / "stuck.toml",
            "stuck",
            [SWEEP],
            camera=camera(32, 24),
            lights=[keysight(visa_library=f"{broken}@sim")],
        )
    )
    with pytest.raises(DeviceError, match="reads back 0.1"):
        run_session(plan, tmp_path / "stuck", sim=True)
    data = Dataset.open(tmp_path / "stuck")
    assert len(data.points()) == 0
    assert data.metadata["lights_safe_state"]["led"]["off"] is True


@pytest.mark.parametrize("stop", [KeyboardInterrupt, RuntimeError])
def test_ctrl_c_or_an_error_mid_sweep_leaves_the_light_dark_and_says_so(tmp_path, stop):
    plan = load_plan(write_plan(tmp_path / "p.toml", "p", [SWEEP], camera=camera(32, 24), lights=[keysight()]))

    def interrupt(event):
        raise stop("after the first point")

    with pytest.raises(stop):
        run_session(plan, tmp_path / "d", sim=True, progress=interrupt)
    data = Dataset.open(tmp_path / "d")
    assert len(data.points()) == 1  # the point completed before the interruption is kept
    assert data.metadata["lights_safe_state"]["led"]["off"] is True


def test_the_dataset_records_which_placement_each_light_drives(tmp_path):
    rig = tmp_path / "placed.toml"
    rig.write_text(
        (CONFIGS / "rigs" / "sim-tank.toml").read_text() + '\n[[lights]]\nname = "led"\nposition_m = [0.0, -0.1, 0.0]\n'
    )
    plan = load_plan(
        write_plan(
            tmp_path / "placed-plan.toml", "placed", [SWEEP], rig=rig, camera=camera(32, 24), lights=[keysight()]
        )
    )
    data = Dataset.open(run_session(plan, tmp_path / "placed", sim=True))
    assert data.metadata["devices"]["l"]["light_placements"] == {
        "led": {"placement": 0, "position_m": [0.0, -0.1, 0.0]}
    }
    assert data.metadata["rigs"]["l"]["lights"][0]["name"] == "led"  # the resolved rig the fit reads
