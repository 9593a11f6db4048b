"""Geometry sweep plans (``kind = "geometry"``): what each step sets at each point, the defaults (the lens focused on
the target's image through the port), refusals naming the key (and one line, exit 2, from `uwlab sweep`); the tank's
operator is asked for the focus and the target's distance only when they change, and the values given are kept."""

from __future__ import annotations

import pytest

from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.plan import load_plan
from uwlab.experiments.acquisition.rigs import HardwareRig

from tests.support.cli import one_line_error
from tests.support.paths import CONFIGS
from tests.support.plans import camera, write_plan

PAPER_TANK = CONFIGS / "rigs" / "paper-tank.toml"
LENS = {"focal_length_mm": 12, "f_number": 4.0, "f_number_range": [1.4, 16.0]}
G = {"id": "g", "kind": "geometry", "step": "lens_focus_m", "values": [0.35, 0.37], "lens": LENS}
# The paper's tank as its rig describes it: the board 0.4927 m from the pupil behind a 20 mm air gap and a 12.7 mm
# acrylic wall (n 1.49) in water (n 1.333) appears at 0.02 + 0.0127 / 1.49 + 0.46 / 1.333 m (Hecht §5.2.3).
BOARD_M = 0.4927
BOARD_IMAGE_M = 0.02 + 0.0127 / 1.49 + 0.46 / 1.333


def plan_file(tmp_path, *sweeps: dict, rig=PAPER_TANK):
    return write_plan(tmp_path / "plan.toml", "geometry", list(sweeps), rig=rig, camera=camera(64, 64))


def test_the_shipped_focus_sweep_plan_steps_focus_and_distance():
    plan = load_plan(CONFIGS / "plans" / "tank-focus-sweep.toml")
    focus, distance = plan.sweeps
    assert (focus.table.step, distance.table.step) == ("lens_focus_m", "target_distance_m")
    assert focus.target_distance_m == distance.target_distance_m == BOARD_M
    # the focus steps straddle the board's image and the distance sweep is focused on it
    assert focus.values[0] < BOARD_IMAGE_M < focus.values[-1]
    assert distance.lens_focus_m == pytest.approx(BOARD_IMAGE_M, rel=1e-4)
    assert distance.values[0] < BOARD_M < distance.values[-1]


def test_each_step_sets_its_setting_and_the_others_stay_fixed(tmp_path):
    distance = {**G, "id": "d", "step": "target_distance_m", "values": [0.4, 0.5], "target_distance_m": BOARD_M}
    aperture = {**G, "id": "a", "step": "f_number", "values": [2.8, 8.0], "lens_focus_m": 0.38}
    moving = {
        **G,
        "id": "m",
        "step": "exposure_us",
        "values": [100, 400],
        "geometry": {"operation": {"speed_m_s": 0.5}},
    }
    focus_sweep, distance_sweep, aperture_sweep, moving_sweep = load_plan(
        plan_file(tmp_path, {**G, "target_distance_m": BOARD_M}, distance, aperture, moving)
    ).sweeps
    focus = focus_sweep.points()
    assert [(p.lens_focus_m, p.target_distance_m, p.f_number) for p in focus] == [
        (0.35, BOARD_M, 4.0),
        (0.37, BOARD_M, 4.0),
    ]
    assert [(p.target_distance_m, p.lens_focus_m) for p in distance_sweep.points()] == [
        (0.4, pytest.approx(BOARD_IMAGE_M, rel=1e-9)),
        (0.5, pytest.approx(BOARD_IMAGE_M, rel=1e-9)),
    ]
    assert [(p.f_number, p.lens_focus_m) for p in aperture_sweep.points()] == [(2.8, 0.38), (8.0, 0.38)]
    # without target_distance_m the target is the rig's operation.altitude_m (0.46 m in the paper's tank)
    assert [(p.exposure_us, p.target_distance_m) for p in moving_sweep.points()] == [(100, 0.46), (400, 0.46)]


@pytest.mark.parametrize(
    "sweep, key",
    [
        ({**G, "step": None}, "sweep.g.step"),
        ({**G, "step": "zoom"}, "sweep.g.step"),
        ({**G, "kind": "exposure", "values": [100]}, "sweep.g.step"),
        ({"id": "g", "kind": "exposure", "values": [100], "edge_roi": [0, 0, 32, 32]}, "sweep.g.edge_roi"),
        ({"id": "g", "kind": "exposure", "values": [100], "lens_focus_m": 0.4}, "sweep.g.lens_focus_m"),
        ({**G, "edge_roi": [0, 0, 32]}, "sweep.g.edge_roi"),
        ({**G, "lens": "none"}, "sweep.g.lens"),
        ({**G, "values": [0.005, 0.4]}, "sweep.g.values"),  # inside the 12 mm focal length: no lens focuses there
        ({**G, "step": "target_distance_m", "values": [0.02, 0.4]}, "sweep.g.values"),  # inside the tank's wall
        ({**G, "step": "target_distance_m", "values": [0.4], "lens_focus_m": 0.01}, "sweep.g.lens_focus_m"),
        ({**G, "target_distance_m": 0.03}, "sweep.g.target_distance_m"),
        ({**G, "step": "f_number", "values": [1.0, 4.0]}, "sweep.g.values"),
        ({**G, "step": "exposure_us", "values": [100, 200]}, "sweep.g.step"),  # a still target has no motion blur
        ({**G, "target_distance_m": -1}, "sweep.g.target_distance_m"),
    ],
)
def test_bad_geometry_sweeps_name_the_key(tmp_path, sweep, key):
    with pytest.raises(ConfigError) as info:
        load_plan(plan_file(tmp_path, {k: v for k, v in sweep.items() if v is not None}))
    assert info.value.key == key


def test_an_exposure_step_with_a_moving_target_cannot_share_one_dark_block(tmp_path):
    moving = {**G, "step": "exposure_us", "values": [100, 200], "dark": "block"}
    with pytest.raises(ConfigError) as info:
        load_plan(plan_file(tmp_path, {**moving, "geometry": {"operation": {"speed_m_s": 0.5}}}))
    assert info.value.key == "sweep.g.dark"


def test_the_emva_bench_has_no_target(tmp_path):
    with pytest.raises(ConfigError) as info:
        bare = {**G, "lens": "none"}  # the bench is a bare sensor
        load_plan(plan_file(tmp_path, bare, rig=CONFIGS / "rigs" / "sim-emva-bench.toml"))
    assert info.value.key == "sweep.g.kind"


def test_uwlab_sweep_refuses_a_bad_geometry_plan_in_one_line(tmp_path, capsys):
    plan = plan_file(tmp_path, {**G, "step": "exposure_us", "values": [100, 200]})
    line = one_line_error(capsys, ["sweep", str(plan), "--sim", "--out", str(tmp_path / "d")])
    assert "sweep.g.step" in line and "speed_m_s" in line
    assert not (tmp_path / "d").exists()


def test_the_operator_is_asked_only_when_a_setting_changes_and_the_values_given_are_kept(tmp_path):
    plan = load_plan(plan_file(tmp_path, {**G, "values": [0.35, 0.35, 0.37], "target_distance_m": BOARD_M}))
    sweep = plan.sweeps[0]
    asked = []

    def operator(message, requested):
        asked.append(message)
        return requested + 0.001  # the ring's marks are coarse: the operator reports what they set

    rig = HardwareRig(plan, ask_value=operator)
    settings = [rig.set_geometry(sweep, point) for point in sweep.points()]
    assert asked == [
        "set the lens focus to 0.35 m (air-equivalent)",
        "place the target 0.4927 m from the lens's pupil",
        "set the lens focus to 0.37 m (air-equivalent)",
    ]
    assert [(s.lens_focus_m, s.target_distance_m, s.set_by) for s in settings] == [
        (pytest.approx(0.351), pytest.approx(0.4937), "operator"),
        (pytest.approx(0.351), pytest.approx(0.4937), "operator"),
        (pytest.approx(0.371), pytest.approx(0.4937), "operator"),
    ]
    with pytest.raises(ConfigError, match="--non-interactive") as info:
        HardwareRig(plan).set_geometry(sweep, sweep.points()[0])
    assert info.value.key == "sweep.g.lens_focus_m"
