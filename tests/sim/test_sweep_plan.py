"""Plan validation: every bad key or impossible value is a ConfigError naming it; shipped plans parse."""
from pathlib import Path

import numpy as np
import pytest

from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.plan import expand_values, load_plan, point_counts

ROOT = Path(__file__).resolve().parents[2]
RIG = ROOT / "configs" / "rigs" / "sim-tank.toml"

BASE = f"""
name = "unit"
rig = "{RIG}"
[camera]
pixel_format = "Mono12"
window = [1192, 1000, 32, 32]
"""


def plan_file(tmp_path, sweeps: str, header: str = BASE) -> Path:
    path = tmp_path / "plan.toml"
    path.write_text(header + sweeps)
    return path


def test_shipped_plans_parse_with_the_papers_cameras_and_lenses():
    tank = load_plan(ROOT / "configs" / "plans" / "tank-exposure-sweep.toml")
    pairs = {(s.sensor_profile, s.lens.label) for s in tank.sweeps}
    assert pairs == {(c, l) for c in ("imx250m", "icx285alm") for l in ("no-lens", "30mm-F2.0", "12mm-F4.0")}
    assert all(s.spectrometer == ("target", "camera") and s.kind == "exposure" for s in tank.sweeps)
    emva = load_plan(ROOT / "configs" / "plans" / "emva-photon-transfer.toml")
    transfer, dark = emva.sweeps
    assert len(transfer.values) >= 50 and transfer.frames_per_point >= 2 and transfer.dark == "point"
    assert dark.kind == "dark" and len(dark.values) >= 3
    no_lens = tank.sweeps[0].design
    assert no_lens["lens.f_number"] == 0.5 and no_lens["lens.transmittance"] == 1.0


def test_values_ranges_and_point_counts():
    assert expand_values("v", {"start": 1, "stop": 100, "num": 3, "spacing": "log"}) == pytest.approx((1, 10, 100))
    assert expand_values("v", {"start": 0, "stop": 1, "num": 5}) == tuple(np.linspace(0, 1, 5))
    raw = {"defaults": {"values": [1, 2]}, "sweep": [{"id": "a"}, {"id": "b", "values": {"start": 1, "stop": 2, "num": 7}}]}
    assert point_counts(raw) == {"a": 2, "b": 7}


@pytest.mark.parametrize("sweep, key", [
    ('id = "a"\nkind = "exposure"\nvalues = [100]\ncolour = 1', "sweep.a.colour"),
    ('id = "a"\nkind = "exposure"\nvalues = [-5, 100]', "sweep.a.values"),
    ('id = "a"\nkind = "zoom"\nvalues = [1]', "sweep.a.kind"),
    ('id = "a"\nkind = "exposure"\nvalues = [100]\nframes_per_point = 1', "sweep.a.frames_per_point"),
    ('id = "a"\nkind = "aperture"\nvalues = [1.0, 4.0]\nlens = {focal_length_mm = 12, f_number = 4.0, '
     'f_number_range = [1.4, 16]}', "sweep.a.values"),
    ('id = "a"\nkind = "exposure"\nvalues = [100]\nlens = {focal_length_mm = 12, f_number = 22.0, '
     'f_number_range = [1.4, 16]}', "sweep.a.lens.f_number"),
    ('id = "a"\nkind = "aperture"\nvalues = [2.0]\nlens = "none"', "sweep.a.lens"),
    ('id = "a"\nkind = "exposure"\nvalues = [100]\ndark = "block"', "sweep.a.dark"),
    ('id = "a"\nkind = "light-level"\nvalues = [0.5, 1.5]', "sweep.a.values"),
    ('id = "a"\nkind = "gain"\nvalues = [0, 99]', "sweep.a.values"),
    ('id = "a"\nkind = "exposure"\nvalues = [100]\nroi = [0, 0, 1]', "sweep.a.roi"),
    ('id = "a"\nkind = "exposure"\nvalues = [100]\nspectrometer = ["moon"]', "sweep.a.spectrometer"),
    ('id = "a"\nkind = "exposure"\nvalues = {start = 1, stop = 2, num = 3, spacing = "cubic"}',
     "sweep.a.values.spacing"),
    ('id = "a"\nkind = "exposure"\nvalues = [100]\ngeometry = {lens = {f_number = -2}}', "sweep.a.lens.f_number"),
    ('id = "a"\nkind = "exposure"\nvalues = [100]\nsensor = "nosuchsensor"', "sweep.a.rig.sensor.profile"),
    ('id = "a"\nkind = "exposure"\nvalues = [100]\ncamera = {pixel_format = "RGB8"}', "sweep.a.camera.pixel_format"),
    ('id = "a"\nkind = "exposure"\nvalues = [100]\n[[sweep]]\nid = "a"\nkind = "gain"\nvalues = [0]', "sweep.id"),
])
def test_bad_plans_name_the_key(tmp_path, sweep, key):
    with pytest.raises(ConfigError) as info:
        load_plan(plan_file(tmp_path, "[[sweep]]\n" + sweep))
    assert info.value.key == key


def test_bad_top_level(tmp_path):
    with pytest.raises(ConfigError) as info:
        load_plan(plan_file(tmp_path, '[[sweep]]\nid = "a"\nkind = "exposure"\nvalues = [100]\n', "speed = 3\n" + BASE))
    assert info.value.key == "speed"
    with pytest.raises(ConfigError) as info:
        load_plan(plan_file(tmp_path, "", 'name = "x"\n'))
    assert info.value.key == "rig"


def test_points_follow_the_kind(tmp_path):
    plan = load_plan(plan_file(tmp_path, """
[[sweep]]
id = "levels"
kind = "light-level"
values = [0.25, 1.0]
exposure_us = 500
[[sweep]]
id = "dark"
kind = "dark"
values = [100, 200]
"""))
    levels, dark = plan.sweeps
    assert [(p.light_level, p.exposure_us, p.light_on) for p in levels.points()] == [(0.25, 500, True), (1.0, 500, True)]
    assert [(p.exposure_us, p.light_on) for p in dark.points()] == [(100, False), (200, False)]
    assert plan.total_points() == 4 and len(plan.sha256) == 64
