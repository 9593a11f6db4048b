"""The console's focusing aid on the simulated tank: a slanted edge on the far wall rendered by ray sampling through
the tank's wall (`uwlab.sim.edge_chart`: defocus traced through the pupil, diffraction, pixel integration, noise),
the lens focus stepped through the target's image distance; the sharpness the console computes peaks within one
step of the focus setting the model gives (`uwlab port trace`'s), and reads the same at half the exposure."""

from __future__ import annotations

import numpy as np
import pytest

from tests.support.paths import CONFIGS
from uwlab.explore.console_rig import focus_model, sharpness
from uwlab.sim.edge_chart import TankOptics, render_edge
from uwlab.sim.scene import RigScene

STEPS = 9
SPAN = 0.08  # ± the relative focus range stepped


@pytest.fixture(scope="module")
def tank():
    scene = RigScene.from_toml(CONFIGS / "rigs" / "paper-tank.toml")
    world, design = scene.world, scene.design
    sensor = design.sensor
    optics = TankOptics(
        focal_length_m=float(design["lens.focal_length_mm"]) * 1e-3,
        f_number=float(design["lens.f_number"]),
        pixel_pitch_m=sensor.pixel_size_um * 1e-6,
        camera_gap_m=world.camera_gap_m,
        wall_thickness_m=world.wall_thickness_m,
        wall_index=world.wall_index,
        water_index=float(design["housing.water_index"]),
    )
    exposure = {
        "k_dn_per_e": float(sensor.gain_k(0.0, sensor.bit_depth)),
        "dark_noise_e": sensor.dark_noise_e,
        "bit_depth": sensor.bit_depth,
        "bright_e": 0.6 * sensor.saturation_e,
        "dark_e": 0.06 * sensor.saturation_e,
        "shape_yx": (120, 96),
    }
    return optics, design, exposure


def test_the_sharpness_peak_is_within_one_step_of_the_models_focus_setting(tank):
    optics, design, exposure = tank
    model = focus_model(design)
    target_m = float(design["operation.altitude_m"])
    # The stepped settings straddle the target's image distance as the sim traces it (not the model's number).
    image_m = optics.apparent_distance_m(target_m)
    settings = image_m * np.linspace(1 - SPAN, 1 + SPAN, STEPS)
    step = settings[1] - settings[0]
    measures = [sharpness(render_edge(optics, target_m, f, seed=i, **exposure)) for i, f in enumerate(settings)]
    for name in ("tenengrad", "laplacian"):
        values = [m[name] for m in measures]
        best = settings[int(np.argmax(values))]
        assert abs(best - model["setting_m"]) <= step * 1.001, (name, best, model["setting_m"], step)
        assert max(values) > 2 * values[0] and max(values) > 2 * values[-1]  # a peak, not a plateau


def test_the_sharpness_reads_the_same_at_half_the_exposure(tank):
    optics, design, exposure = tank
    target_m = float(design["operation.altitude_m"])
    focus_m = optics.apparent_distance_m(target_m)
    full = sharpness(render_edge(optics, target_m, focus_m, seed=1, **exposure))
    half = {**exposure, "bright_e": exposure["bright_e"] / 2, "dark_e": exposure["dark_e"] / 2}
    halved = sharpness(render_edge(optics, target_m, focus_m, seed=2, **half))
    # Unnormalised, both would drop fourfold. The dark offset (DN) does not scale with the exposure and shot noise
    # adds gradients (relatively more at half the signal; the Laplacian, a second derivative, feels it more).
    assert halved["tenengrad"] == pytest.approx(full["tenengrad"], rel=0.1)
    assert halved["laplacian"] == pytest.approx(full["laplacian"], rel=0.2)
