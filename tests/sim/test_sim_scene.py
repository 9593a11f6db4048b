"""The simulated rig's scene renders the model: centre pixel = model on-axis rate, linear in the light."""

import numpy as np
import pytest

from uwlab.sim.rig_state import LightState, RigState
from uwlab.sim.scene import RigScene
from uwlab.errors import ConfigError
from uwlab.model.design import evaluate


@pytest.fixture(scope="module")
def scene():
    return RigScene.from_toml()


def test_centre_pixel_follows_the_model(scene):
    out = evaluate(scene.design)
    rate = scene.electron_rate_map((205, 245))
    centre = rate[102, 122]
    expected = scene.sim.light_efficiency * float(out["mean_electrons"]) / float(out["exposure_s"])
    assert not out["saturated"] and scene.sim.light_efficiency == 0.8
    assert centre == pytest.approx(expected, rel=1e-3)  # the centre pixel is 0.3 pixel off axis


def test_rate_is_linear_in_flux_and_board_is_brighter(scene):
    full = scene.electron_rate_map((64, 80), 1.0)
    half = scene.electron_rate_map((64, 80), 0.5)
    assert np.allclose(half, 0.5 * full)
    x, y, w, h = scene.board_roi((64, 80))
    board = full[y : y + h, x : x + w]
    assert board.min() > full[0, 0] and board.mean() > 5 * full[:2, :].mean()
    assert full[32, 40] >= board.max() * 0.999  # vignetting: the centre is the brightest


def test_spectra_integrate_to_model_irradiance(scene):
    nm, target = scene.spectral_irradiance("target", 0.25)
    out = evaluate(scene.design)
    efficiency = scene.sim.light_efficiency
    assert scene.design.grid.integrate(target) == pytest.approx(
        0.25 * efficiency * float(out["target_irradiance_w_m2"])
    )
    nm, camera = scene.spectral_irradiance("camera")
    assert 0 < scene.design.grid.integrate(camera) < scene.design.grid.integrate(target / 0.25)
    with pytest.raises(ConfigError, match="position"):
        scene.spectral_irradiance("ceiling")


def test_rig_state_is_shared_through_a_file(tmp_path):
    path = tmp_path / "state.json"
    writer = RigState(path, LightState(on=True, level=1.0, flux_fraction=1.0))
    reader = RigScene.from_toml(state=RigState(path))
    writer.set_light(LightState(on=True, level=0.5, flux_fraction=0.5**2.2))
    assert reader.flux_fraction() == pytest.approx(0.5**2.2)
    writer.set_light(LightState(on=False, level=0.5, flux_fraction=0.5**2.2))
    assert reader.flux_fraction() == 0.0


def test_unknown_sim_key_is_refused(tmp_path):
    from tests.support.paths import ROOT

    text = (ROOT / "configs/rigs/sim-tank.toml").read_text().replace("seed = 1288", "seeed = 1288")
    bad = tmp_path / "rig.toml"
    bad.write_text(text)
    with pytest.raises(ConfigError, match="sim.seeed"):
        RigScene.from_toml(bad)


def test_set_lens_rerenders_with_inverse_square_f_number():
    scene = RigScene.from_toml()
    before = scene.electron_rate_map((20, 24))[10, 12]
    scene.set_lens(f_number=4.0)
    assert scene.electron_rate_map((20, 24))[10, 12] == pytest.approx(before / 4.0, rel=1e-5)
    with pytest.raises(ConfigError, match="lens.f_number"):
        scene.set_lens(f_number=-1)


def test_no_lens_sees_pi_times_radiance_uniformly():
    scene = RigScene.from_toml()
    f_number, t_lens = scene.design["lens.f_number"], scene.design["lens.transmittance"]
    with_lens = scene.electron_rate_map((20, 24))[10, 12]
    scene.remove_lens()
    bare = scene.electron_rate_map((20, 24))
    assert np.ptp(bare) == 0
    # camera equation: E = L T π/(4N²) → bare sensor: E = π L
    assert bare[0, 0] == pytest.approx(with_lens * 4 * f_number**2 / t_lens, rel=1e-3)
