"""Geometry sweeps on the simulated tank (issue 35): a focus sweep through the paper's tank wall, its slanted edge
rendered by `uwlab.sim.edge_chart`'s ray sampling, measured by the sweep engine's e-SFR and checked against the
model (`uwlab.experiments.geometry.from_dataset`), which is given only the rig as the dataset records it; the dataset
passes its check, an interrupted sweep resumes to the same points; a colour camera's channels are measured each on
its own sites."""

from __future__ import annotations

import numpy as np
import pytest

from uwlab.experiments.acquisition.dataset_check import check
from uwlab.experiments.acquisition.plan import load_plan
from uwlab.experiments.acquisition.sim_rig import SimRig
from uwlab.experiments.acquisition.sweep import SweepRunner, open_for_resume
from uwlab.experiments.dataset import Dataset
from uwlab.experiments.geometry.from_dataset import geometry_from_dataset
from uwlab.model import port

from tests.support.paths import CONFIGS
from tests.support.plans import record, write_plan

PAPER_TANK = CONFIGS / "rigs" / "paper-tank.toml"
# The board 0.4927 m from the pupil (20 mm gap + 12.7 mm acrylic + the 46 cm tank) appears at this air-equivalent
# distance through the wall (the model's flat port; the renderer traces it).
BOARD_M = 0.02 + 0.0127 + 0.46
IMAGE_M = float(port.flat_apparent_distance(BOARD_M, 1.333, 0.02, 0.0127, 1.49))
FOCUS_STEPS = [round(IMAGE_M * f, 5) for f in (0.88, 0.94, 1.0, 1.06, 1.12)]
GEOMETRY = {
    "kind": "geometry",
    "sensor": "imx250m",
    "lens": {"focal_length_mm": 12, "f_number": 4.0, "f_number_range": [1.4, 16.0]},
    "target_distance_m": BOARD_M,
    "exposure_us": 150,
    "frames_per_point": 4,
    "dark": "none",
    "camera": {"pixel_format": "Mono12", "window": [1176, 976, 96, 96]},
}
FOCUS = {"id": "focus", "step": "lens_focus_m", "values": FOCUS_STEPS}


def focus_plan(path):
    return load_plan(write_plan(path, "focus", [FOCUS], rig=PAPER_TANK, defaults=GEOMETRY))


@pytest.fixture(scope="module")
def tank_rig():
    with SimRig(PAPER_TANK) as rig:
        yield rig


@pytest.fixture(scope="module")
def focus_sweep(tmp_path_factory, tank_rig):
    tmp = tmp_path_factory.mktemp("focus")
    plan = focus_plan(tmp / "plan.toml")
    return plan, record(plan, tmp / "data", tank_rig)


def test_measured_mtf50_is_within_5_percent_of_the_model_and_the_best_focus_within_a_step(focus_sweep):
    _, data = focus_sweep
    result = geometry_from_dataset(data)
    errors = [p.error for p in result.focus]
    assert len(errors) == len(FOCUS_STEPS) and max(abs(e) for e in errors) < 0.05, errors
    assert result.best_focus_steps_off is not None and result.best_focus_steps_off <= 1
    # the sweep reaches out of focus: the check covers a sharp edge and one blurred to well under half its MTF50
    measured = [p.measured_mtf50 for p in result.focus]
    assert min(measured) < 0.5 * max(measured)
    assert result.adequate


def test_a_geometry_point_records_its_settings_and_edge_beside_the_radiometry(focus_sweep):
    _, data = focus_sweep
    points = data.points()
    assert points["lens_focus_m"].tolist() == pytest.approx(FOCUS_STEPS)
    assert (points["target_distance_m"] == BOARD_M).all() and (points["geometry_set_by"] == "rig").all()
    assert np.allclose(points["edge_angle_deg"].abs(), 5.0, atol=0.1)  # the chart's tilt, found by the e-SFR
    assert (points["mtf_nyquist"] < points["mtf50_cy_per_px"]).all()
    assert points["mean_dn"].notna().all() and points["red_mtf50_cy_per_px"].isna().all()  # monochrome


def test_the_dataset_passes_its_check(focus_sweep):
    _, data = focus_sweep
    report = check(data)
    assert report.ok, report.summary_line()


def test_an_interrupted_geometry_sweep_resumes_to_the_same_points(tmp_path, focus_sweep, tank_rig):
    plan, complete = focus_sweep
    stop_after = 2

    def interrupt(event):
        if event.done == stop_after:
            raise KeyboardInterrupt

    data = Dataset.create(tmp_path / "d", plan.raw, plan_sha256=plan.sha256, sim=True)
    with pytest.raises(KeyboardInterrupt):
        SweepRunner(plan, data, tank_rig, progress=interrupt).run()
    data.close()
    assert len(Dataset.open(tmp_path / "d").completed()) == stop_after
    with open_for_resume(tmp_path / "d", plan, sim=True) as resumed:
        SweepRunner(plan, resumed, tank_rig).run()
    resumed_points = Dataset.open(tmp_path / "d").points().sort_values("point_index")
    reference = complete.points().sort_values("point_index")
    assert resumed_points["point_index"].tolist() == reference["point_index"].tolist()
    assert resumed_points["lens_focus_m"].tolist() == reference["lens_focus_m"].tolist()
    # the same chart at each point; only the camera's noise differs between the runs
    assert resumed_points["mtf50_cy_per_px"].to_numpy() == pytest.approx(
        reference["mtf50_cy_per_px"].to_numpy(), rel=0.02
    )
    assert check(Dataset.open(tmp_path / "d")).ok


def test_a_colour_cameras_channels_each_measure_the_edge(tmp_path, sim_rig):
    """A raw Bayer point's edge per channel, each on its own sites: the three see the same optics (a chart in grey),
    so their MTF50s agree, and the whole-edge columns are green's."""
    colour = {
        **GEOMETRY,
        "id": "colour",
        "sensor": "imx250c",
        "step": "lens_focus_m",
        "target_distance_m": None,
        "exposure_us": 1000,
        "camera": {"pixel_format": "BayerRG12", "window": [1144, 944, 160, 160], "bayer": "RG"},
    }
    colour = {key: value for key, value in colour.items() if value is not None}
    plan = load_plan(write_plan(tmp_path / "plan.toml", "colour", [{**colour, "values": [0.75, 0.8]}]))
    points = record(plan, tmp_path / "data", sim_rig).points()
    for channel in ("red", "green", "blue"):
        assert points[f"{channel}_mtf50_cy_per_px"].notna().all()
        assert np.allclose(points[f"{channel}_edge_angle_deg"].abs(), 5.0, atol=0.3)
    assert points["mtf50_cy_per_px"].tolist() == points["green_mtf50_cy_per_px"].tolist()
    assert points["red_mtf50_cy_per_px"].to_numpy() == pytest.approx(points["blue_mtf50_cy_per_px"], rel=0.1)


def test_motion_blur_and_the_aperture_follow_the_model(tmp_path, tank_rig):
    """An exposure step with the target moving at the rig's speed (0.5 m/s: up to about 4 px of travel) and an
    f-number step (diffraction and defocus change together): every point's MTF50 within 5 % of the model's."""
    moving = {"id": "moving", "step": "exposure_us", "values": [100, 400, 800], "light_level": 0.6}
    moving["geometry"] = {"operation": {"speed_m_s": 0.5}}
    aperture = {"id": "aperture", "step": "f_number", "values": [2.8, 11.0], "light_level": 0.6, "exposure_us": 300}
    plan = load_plan(
        write_plan(tmp_path / "plan.toml", "moving", [moving, aperture], rig=PAPER_TANK, defaults=GEOMETRY)
    )
    result = geometry_from_dataset(record(plan, tmp_path / "data", tank_rig))
    errors = [p.error for p in [*result.exposure, *result.aperture]]
    assert len(errors) == 5 and max(abs(e) for e in errors) < 0.05, errors
    blurred = [p.measured_mtf50 for p in result.exposure]
    assert blurred[-1] < 0.5 * blurred[0]  # the motion dominates at the longest exposure


def test_a_fit_leaves_geometry_sweeps_out(focus_sweep, capsys):
    """A geometry sweep's window holds the chart's black half: its points are not radiometry, and a dataset of
    geometry sweeps alone has nothing to fit (one line, exit 2)."""
    from tests.support.cli import one_line_error

    _, data = focus_sweep
    line = one_line_error(capsys, ["fit", str(data.root), "--out", str(data.root.parent / "fit")])
    assert "no points to fit outside geometry sweeps" in line
