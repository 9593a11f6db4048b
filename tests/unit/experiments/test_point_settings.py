"""A point's exposure is its own setting, in µs, checked against the sensor once where the plan is read: it is never
written into the rig's design and read back, and the rig's own design exposure cannot refuse a sweep."""

from __future__ import annotations

import copy
import tomllib

import pytest
import tomli_w

from tests.support.paths import SIM_TANK
from tests.support.plans import write_plan
from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.plan import load_plan
from uwlab.experiments.calibration.forward import _configuration_design

SWEEP = {
    "id": "s",
    "kind": "gain",
    "values": [0, 6, 12],
    "frames_per_point": 2,
    "sensor": "imx250m",
    "exposure_us": 2500.0,
}


def test_the_sweeps_exposure_is_the_points_and_not_the_designs(tmp_path):
    plan = load_plan(write_plan(tmp_path / "plan.toml", "p", [SWEEP]))
    (sweep,) = plan.sweeps
    assert [p.exposure_us for p in sweep.points()] == [2500.0] * 3  # exactly as written, in µs
    rig_file = tomllib.loads(SIM_TANK.read_text())
    assert sweep.rig_raw["operation"]["exposure_s"] == rig_file["operation"]["exposure_s"]  # the rig's own, untouched
    assert sweep.design["operation.exposure_s"] == "max-blur"  # the rate design carries no exposure


def test_an_exposure_outside_the_sensor_is_refused_once_in_microseconds(tmp_path):
    path = write_plan(tmp_path / "plan.toml", "p", [{**SWEEP, "exposure_us": 60e6}])  # 60 s; IMX250: 30 s at most
    with pytest.raises(ConfigError) as caught:
        load_plan(path)
    assert caught.value.key == "sweep.s.exposure_us" and "µs" in caught.value.reason


def test_the_rig_files_exposure_cannot_refuse_a_sweep(tmp_path):
    rig = tomllib.loads(SIM_TANK.read_text())
    rig["operation"]["exposure_s"] = 100.0  # beyond every sensor's range: a rig's design exposure is not measured
    rig_path = tmp_path / "rig.toml"
    rig_path.write_text(tomli_w.dumps(rig))
    plan = load_plan(write_plan(tmp_path / "plan.toml", "p", [SWEEP], rig=rig_path))
    design, _ = _configuration_design(copy.deepcopy(plan.sweeps[0].rig_raw), SIM_TANK.parent, "imx250m", 30, 2, None)
    assert design["operation.exposure_s"] == "max-blur"
