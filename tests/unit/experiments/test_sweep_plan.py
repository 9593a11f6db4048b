"""Plan validation: every bad key or impossible value is a ConfigError naming it; shipped plans parse."""

import numpy as np
import pytest

from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.plan import expand_values, load_plan, point_counts

from tests.support.paths import ROOT
from tests.support.plans import camera, write_plan


def plan_file(tmp_path, sweeps: list[dict], name: str | None = "unit", **top):
    return write_plan(tmp_path / "plan.toml", name, sweeps, **{"camera": camera(32, 32), **top})


def test_shipped_plans_parse_with_the_papers_cameras_and_lenses():
    tank = load_plan(ROOT / "configs" / "plans" / "tank-exposure-sweep.toml")
    pairs = {(s.sensor_profile, s.lens.label) for s in tank.sweeps}
    assert pairs == {(c, lens) for c in ("imx250m", "icx285alm") for lens in ("no-lens", "30mm-F2.0", "12mm-F4.0")}
    assert all(s.table.spectrometer == ["target", "camera"] and s.table.kind == "exposure" for s in tank.sweeps)
    emva = load_plan(ROOT / "configs" / "plans" / "emva-photon-transfer.toml")
    transfer, dark = emva.sweeps
    assert len(transfer.values) >= 50 and transfer.table.frames_per_point >= 2 and transfer.table.dark == "point"
    assert dark.table.kind == "dark" and len(dark.values) >= 3
    no_lens = tank.sweeps[0].design
    assert no_lens["lens.f_number"] == 0.5 and no_lens["lens.transmittance"] == 1.0


def test_values_ranges_and_point_counts():
    assert expand_values("v", {"start": 1, "stop": 100, "num": 3, "spacing": "log"}) == pytest.approx((1, 10, 100))
    assert expand_values("v", {"start": 0, "stop": 1, "num": 5}) == tuple(np.linspace(0, 1, 5))
    raw = {
        "defaults": {"values": [1, 2]},
        "sweep": [{"id": "a"}, {"id": "b", "values": {"start": 1, "stop": 2, "num": 7}}],
    }
    assert point_counts(raw) == {"a": 2, "b": 7}


A = {"id": "a", "kind": "exposure", "values": [100]}
LENS = {"focal_length_mm": 12, "f_number": 4.0, "f_number_range": [1.4, 16]}


@pytest.mark.parametrize(
    "sweeps, key",
    [
        ([{**A, "colour": 1}], "sweep.a.colour"),
        ([{**A, "values": [-5, 100]}], "sweep.a.values"),
        ([{**A, "kind": "zoom", "values": [1]}], "sweep.a.kind"),
        ([{**A, "frames_per_point": 1}], "sweep.a.frames_per_point"),
        ([{**A, "kind": "aperture", "values": [1.0, 4.0], "lens": LENS}], "sweep.a.values"),
        ([{**A, "lens": {**LENS, "f_number": 22.0}}], "sweep.a.lens.f_number"),
        ([{**A, "kind": "aperture", "values": [2.0], "lens": "none"}], "sweep.a.lens"),
        ([{**A, "dark": "block"}], "sweep.a.dark"),
        ([{**A, "kind": "light-level", "values": [0.5, 1.5]}], "sweep.a.values"),
        ([{**A, "kind": "gain", "values": [0, 99]}], "sweep.a.values"),
        ([{**A, "roi": [0, 0, 1]}], "sweep.a.roi"),
        ([{**A, "spectrometer": ["moon"]}], "sweep.a.spectrometer"),
        ([{**A, "values": {"start": 1, "stop": 2, "num": 3, "spacing": "cubic"}}], "sweep.a.values.spacing"),
        ([{**A, "geometry": {"lens": {"f_number": -2}}}], "sweep.a.lens.f_number"),
        ([{**A, "sensor": "nosuchsensor"}], "sweep.a.rig.sensor.profile"),
        ([{**A, "camera": {"pixel_format": "RGB8"}}], "sweep.a.camera.pixel_format"),
        ([A, {"id": "a", "kind": "gain", "values": [0]}], "sweep.id"),
    ],
)
def test_bad_plans_name_the_key(tmp_path, sweeps, key):
    with pytest.raises(ConfigError) as info:
        load_plan(plan_file(tmp_path, sweeps))
    assert info.value.key == key


def test_bad_top_level(tmp_path):
    with pytest.raises(ConfigError) as info:
        load_plan(plan_file(tmp_path, [A], speed=3))
    assert info.value.key == "speed"
    with pytest.raises(ConfigError) as info:
        load_plan(plan_file(tmp_path, [], name="x", rig=None, camera=None))
    assert info.value.key == "rig"


def test_points_follow_the_kind(tmp_path):
    plan = load_plan(
        plan_file(
            tmp_path,
            [
                {"id": "levels", "kind": "light-level", "values": [0.25, 1.0], "exposure_us": 500},
                {"id": "dark", "kind": "dark", "values": [100, 200]},
            ],
        )
    )
    levels, dark = plan.sweeps
    assert [(p.light_level, p.exposure_us, p.light_on) for p in levels.points()] == [
        (0.25, 500, True),
        (1.0, 500, True),
    ]
    assert [(p.exposure_us, p.light_on) for p in dark.points()] == [(100, False), (200, False)]
    assert plan.total_points() == 4 and len(plan.sha256) == 64
