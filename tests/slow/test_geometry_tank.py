"""The paper's geometry on the simulated tank (issue 35's targets): a slanted edge rendered by ray sampling through
the tank's wall (`uwlab.sim.edge_chart`), measured with the e-SFR, against the model's MTF, best focus and depth of
field given the rig as a user describes it."""

from __future__ import annotations

import numpy as np
import pytest

from uwlab.experiments.geometry.tank import validate_tank_geometry
from uwlab.model import port
from uwlab.sim.edge_chart import TankOptics


@pytest.fixture(scope="module")
def geometry():
    return validate_tank_geometry(seed=3)


def test_measured_mtf50_follows_the_prediction_across_the_focus_and_distance_sweeps(geometry):
    errors = [p.error for p in [*geometry.focus, *geometry.distance]]
    assert max(abs(e) for e in errors) < 0.05, errors
    # The sweeps reach well out of focus: the check covers blur from the pixel alone to several pixels.
    measured = [p.measured_mtf50 for p in geometry.focus]
    assert min(measured) < 0.5 * max(measured)


def test_the_measured_best_focus_is_within_one_step_of_the_model(geometry):
    assert abs(geometry.best_focus_measured_m - geometry.best_focus_predicted_m) <= geometry.focus_step_m * 1.001
    assert geometry.best_focus_predicted_m == pytest.approx(geometry.focus_image_m, abs=geometry.focus_step_m)


def test_the_measured_depth_of_field_is_within_10_percent_of_the_model(geometry):
    near, far = geometry.dof_measured_m
    model_near, model_far = geometry.dof_model_m
    assert near < geometry.target_distance_m < far
    assert all(abs(e) < 0.10 for e in geometry.depth_errors()), (geometry.dof_measured_m, geometry.dof_model_m)


def test_the_renderers_ray_trace_through_the_wall_agrees_with_the_ports_closed_form():
    """Two constructions of the apparent distance behind a flat wall with an air gap: Snell's law on a traced ray
    (the renderer) and offset + s / n_w (`uwlab.model.port`)."""
    optics = TankOptics(
        0.012, 4.0, 3.45e-6, camera_gap_m=0.02, wall_thickness_m=0.0127, wall_index=1.49, water_index=1.335
    )
    for s in (0.3, 0.49, 1.2):
        closed = port.flat_apparent_distance(s, 1.335, 0.02, 0.0127, 1.49)
        assert optics.apparent_distance_m(s) == pytest.approx(float(closed), rel=1e-6)
    assert np.isfinite(optics.image_distance_m(0.37))
