"""The tank world: its optics against closed forms, its effects switchable one by one, and the extended model
(written independently) agreeing with it where they describe the same physics."""

import copy

import numpy as np
import pytest

from uwlab.sim.devices.camera import SensorConfig, SimSensor, SimTruth, flat_rate_map
from uwlab.sim.rig_state import RigState
from uwlab.sim.scene import RigScene
from uwlab.sim.devices.serial_instruments import SimLight
from uwlab.sim.rig_state import WarmUp
from uwlab.sim.world import EFFECTS, world_settings
from uwlab.errors import ConfigError
from uwlab.experiments.calibration.forward import _configuration_design, extended_roi_rates
from uwlab.model.data import read_toml
from uwlab.model.design import stage_spectra
from uwlab.model.sensor import load_sensor_profile

from tests.support.paths import ROOT

RIG = ROOT / "configs/rigs/paper-tank.toml"


@pytest.fixture
def rig():
    raw = read_toml(RIG)
    raw["sim"]["light_efficiency"] = 1.0
    return raw


def scene(raw, **world) -> RigScene:
    raw = copy.deepcopy(raw)
    raw["world"].update(world)
    return RigScene.from_dict(raw, RIG.parent)


def test_light_on_its_axis_follows_the_apparent_distance_law(rig):
    """On the light's own axis E = I(0) T / (h + t/n_p + z/n_w)² (paraxial refraction through the wall)."""
    tank = scene(rig).tank
    s = tank.settings
    x, y = s.light_offset_m
    for depth in (0.05, 0.2, 0.46):
        light = tank.light_at(np.array([x, y, tank.z_inner + depth]))
        m = -np.log(2) / np.log(np.cos(np.radians(40.0)))
        t = tank._plate(np.array(0.0))[3]
        apparent = s.light_gap_m + s.wall_thickness_m / s.wall_index + depth / tank.water_index
        assert light["e_par"] == pytest.approx((m + 1) / (2 * np.pi) * t / apparent**2, rel=1e-9)
        assert light["path_m"] == pytest.approx(depth, rel=1e-12)


def test_light_through_the_wall_conserves_its_flux(rig):
    """∫ E dA over a large plane in the water equals ∫ κ T dω over the beam (every ray that enters the water
    reaches the plane): the refraction Jacobian loses nothing."""
    tank = scene(rig).tank
    depth = 0.3
    rho = np.linspace(0.0, 40.0, 200001)
    x0, y0 = tank.settings.light_offset_m
    points = np.stack([x0 + rho, y0 + 0 * rho, tank.z_inner + depth + 0 * rho], axis=1)
    e = tank.light_at(points)["e_par"]
    on_plane = np.trapezoid(2 * np.pi * rho * e, rho)
    theta = np.linspace(0, np.pi / 2, 200001)
    beam = tank._intensity_per_flux(np.cos(theta)) * tank._plate(np.sin(theta))[3]
    expected = np.trapezoid(2 * np.pi * np.sin(theta) * beam, theta)
    assert on_plane == pytest.approx(expected, rel=2e-3)
    assert 0.9 < expected < 0.97  # the wall's Fresnel losses


@pytest.mark.parametrize("effect", EFFECTS)
def test_every_effect_switches_alone(rig, effect):
    """Turning one effect off changes what the rig renders, in the direction the physics says."""
    on, off = scene(rig), scene(rig, **{effect: False})
    if effect == "sensor_realism":
        assert on.sensor_realism()["prnu_percent"] > 0 and off.sensor_realism() == {}
        return
    if effect == "warmup_drift":
        assert on.warm_up().amplitude > 0 and off.warm_up().amplitude == 0
        return
    centre = [s.electron_rate_map((40, 48))[20, 24] for s in (on, off)]
    corner = [s.electron_rate_map((40, 48))[0, 0] for s in (on, off)]
    if effect == "vignetting":
        assert corner[0] < corner[1] and centre[0] == pytest.approx(centre[1], rel=2e-3)
    elif effect in ("backscatter", "stray_light"):
        assert centre[0] > centre[1]
    else:  # beam profile (cone vs cos-power), lens transmission (curve vs the design's number)
        assert centre[0] != pytest.approx(centre[1], rel=1e-3)


def test_turbid_water_adds_veiling_light(rig):
    lensed = []
    for world in (
        {"backscatter": False},
        {},
        {"particle_scattering_per_m": 1.8, "backscatter": False},
        {"particle_scattering_per_m": 1.8},
    ):
        s = scene(rig, **world)
        lensed.append(s.on_axis_rate_e_per_s())
    clear_veil, turbid_veil = lensed[1] / lensed[0] - 1, lensed[3] / lensed[2] - 1
    assert 0 < clear_veil < 0.005 < 0.02 < turbid_veil
    with pytest.raises(ConfigError, match="world.backscatter"):
        world_settings({"preset": "ideal", "backscatter": True})


def test_extended_model_agrees_with_the_tank_where_they_share_physics(rig):
    """With the effects the model leaves out switched off (stray light, the lens's spectral transmittance), the
    extended model (point lights at their apparent positions, paraxial-free rays through the port) and the tank
    renderer (exact refraction of the light and the camera through the wall) agree to 0.5 %; the bare sensor's
    hemisphere to 1 %."""
    raw = copy.deepcopy(rig)
    raw["world"].update(stray_light=False, lens_transmission=False)
    for lens in ((30.0, 2.0), (12.0, 4.0), None):
        s = RigScene.from_dict(copy.deepcopy(raw), RIG.parent)
        s.set_lens(*lens) if lens else s.remove_lens()
        design, has_lens = _configuration_design(raw, RIG.parent, "imx250m", *(lens or (None, None)), "extended")
        model = float(sum(extended_roi_rates(design, has_lens, 1.0, 1.0)))
        assert s.on_axis_rate_e_per_s() == pytest.approx(model, rel=0.005 if lens else 0.01), lens
    spectra = stage_spectra(design)
    nm, measured = s.spectral_irradiance("target")
    assert np.trapezoid(measured, nm) == pytest.approx(np.trapezoid(spectra["facing_light_w_m2_nm"], nm), rel=0.005)


def test_warm_up_drift_settles_with_use(tmp_path):
    """A cold light gives 1 + A of its settled output; each switch-on moves it towards settled by e^(−1/n); the
    drift follows the light's use, the same in every run."""
    state = RigState(tmp_path / "state.json")
    light = SimLight(state, gamma=1.0, drift=WarmUp(0.02, 20.0))
    for command in ("LEV 1", "OUTP ON"):
        light.handle(command)
    assert state.light.effective_fraction == pytest.approx(1 + 0.02 * np.exp(-1 / 20))
    for _ in range(19):
        light.handle("OUTP OFF")
        assert state.light.effective_fraction == 0.0
        light.handle("OUTP ON")
    assert state.light.effective_fraction == pytest.approx(1 + 0.02 * np.exp(-1.0))
    light.handle("LEV 0.5")  # dimming is not a switch-on
    assert state.light.effective_fraction == pytest.approx(0.5 * (1 + 0.02 * np.exp(-1.0)))
    light.handle("*RST")  # a reset is a power cycle: cold again
    light.handle("LEV 1")
    light.handle("OUTP ON")
    assert state.light.effective_fraction == pytest.approx(1 + 0.02 * np.exp(-1 / 20))


def test_sensor_realism_hot_pixels_and_compression():
    """Hot pixels carry their own dark current; the world's compression bends a full well down by its fraction."""
    profile = load_sensor_profile("imx250m")
    realism = RigScene.from_toml(ROOT / "configs" / "rigs" / "paper-tank.toml").sensor_realism()
    truth = SimTruth.from_sensor_profile(
        profile,
        resolution_px=(256, 256),
        hot_pixel_fraction=0.01,
        hot_pixel_dark_current_e_per_s=5e5,
        nonlinearity=realism["nonlinearity"],
    )
    sensor = SimSensor(truth, flat_rate_map(0.0), seed=1)
    cfg = SensorConfig(10000.0, 0.0, 0.0, "Mono16", 0, 0, 256, 256)
    mean, _ = sensor.electrons(cfg, 1.0)
    hot = mean > 1000
    assert hot.mean() == pytest.approx(0.01, abs=0.003)
    assert np.median(mean[hot]) == pytest.approx(5e5 * 0.01, rel=1e-3)
    bright = SimSensor(truth, flat_rate_map(truth.saturation_e / 0.001), seed=1)
    dn = bright.render(cfg).astype(float) / 2 ** (16 - truth.bit_depth)
    electrons = (np.median(dn[~hot]) - truth.dark_offset_dn) / truth.system_gain(0.0)
    assert realism["nonlinearity"] == 0.01
    assert electrons == pytest.approx(truth.saturation_e * (1 - 0.01), rel=2e-3)
