"""Simulated camera physics against the EMVA 1288 linear model in closed form."""

from __future__ import annotations

import numpy as np
import pytest

from uwlab.sim.devices.camera import SensorConfig, SimSensor, SimTruth, flat_rate_map, sensor_from_rig
from uwlab.sim.scene import RigScene
from uwlab.sim.rig_state import LightState, RigState
from uwlab.model.sensor import load_sensor_profile

TRUTH = SimTruth("test", (96, 64), 12, 0.5, 100.0, 3.0, 7000.0, 50.0, 0.0, 0.0, 10.0, 1e7, 0.0, 24.0)


def cfg(**kw) -> SensorConfig:
    base = dict(
        exposure_us=10_000.0,
        gain_db=0.0,
        black_level_dn=0.0,
        pixel_format="Mono12",
        offset_x=0,
        offset_y=0,
        width=96,
        height=64,
    )
    return SensorConfig(**{**base, **kw})


def stack(sensor: SimSensor, c: SensorConfig, n: int) -> np.ndarray:
    return np.stack([sensor.render(c).astype(np.float64) for _ in range(n)])


def test_mean_and_photon_transfer_match_closed_form():
    rate = 200_000.0
    sensor = SimSensor(TRUTH, flat_rate_map(rate), seed=4)
    c = cfg()
    frames = stack(sensor, c, 40)
    mu_e = rate * 0.01 + TRUTH.dark_current_e_per_s * 0.01
    expected_mean = TRUTH.K_dn_per_e * mu_e + TRUTH.dark_offset_dn
    expected_var = TRUTH.K_dn_per_e**2 * (mu_e + TRUTH.dark_noise_e**2) + 1 / 12
    assert frames.mean() == pytest.approx(expected_mean, rel=2e-3)
    temporal_var = np.var(frames[0::2] - frames[1::2], axis=0, ddof=1).mean() / 2
    assert temporal_var == pytest.approx(expected_var, rel=0.04)


def test_gain_db_scales_system_gain():
    sensor = SimSensor(TRUTH, flat_rate_map(100_000.0), seed=1)
    low = stack(sensor, cfg(), 4).mean() - TRUTH.dark_offset_dn
    high = stack(sensor, cfg(gain_db=20 * np.log10(2)), 4).mean() - TRUTH.dark_offset_dn
    assert high / low == pytest.approx(2.0, rel=5e-3)
    assert TRUTH.system_gain(20.0) == pytest.approx(10 * TRUTH.K_dn_per_e)


def test_full_well_saturates_and_output_format_shifts_bits():
    sensor = SimSensor(TRUTH, flat_rate_map(1e9), seed=2)
    sat_dn = round(TRUTH.K_dn_per_e * TRUTH.saturation_e + TRUTH.dark_offset_dn)
    assert np.all(sensor.render(cfg()) == sat_dn)
    assert np.all(sensor.render(cfg(pixel_format="Mono16")) == sat_dn << 4)
    assert np.all(sensor.render(cfg(pixel_format="Mono8")) == sat_dn >> 4)
    assert sensor.render(cfg(pixel_format="Mono8")).dtype == np.uint8
    assert np.all(sensor.render(cfg(gain_db=24.0)) == 4095)


def test_fixed_patterns_are_seeded_and_have_their_truth_amplitude():
    truth = SimTruth("fpn", (128, 96), 12, 1.0, 200.0, 2.0, 20000.0, 0.0, 8.0, 2.0, 10.0, 1e7, 0.0, 24.0)
    a, b, c = (SimSensor(truth, flat_rate_map(5e5), seed=s) for s in (7, 7, 8))
    np.testing.assert_array_equal(a.dsnu_map_e, b.dsnu_map_e)
    assert not np.array_equal(a.dsnu_map_e, c.dsnu_map_e)
    full = dict(width=128, height=96)
    dark = stack(a, cfg(exposure_us=10.0, **full), 32).mean(axis=0)
    assert dark.std() == pytest.approx(truth.dsnu_e, rel=0.08)
    bright = stack(a, cfg(exposure_us=5_000.0, **full), 32).mean(axis=0) - dark
    assert bright.std() / bright.mean() == pytest.approx(truth.prnu_percent / 100, rel=0.1)


def test_light_fraction_is_read_every_frame():
    state = RigState()
    sensor = SimSensor(TRUTH, flat_rate_map(300_000.0), lambda: state.light.effective_fraction, seed=3)
    dark_dn = TRUTH.K_dn_per_e * TRUTH.dark_current_e_per_s * 0.01 + TRUTH.dark_offset_dn
    full = sensor.render(cfg()).mean() - dark_dn
    state.set_light(LightState(level=0.5, flux_fraction=0.5))
    half = sensor.render(cfg()).mean() - dark_dn
    state.set_light(LightState(on=False))
    off = sensor.render(cfg()).mean() - dark_dn
    assert half / full == pytest.approx(0.5, rel=0.01)
    assert abs(off) < 0.2


def test_roi_and_binning_select_and_sum_charge():
    def ramp(shape):
        return np.broadcast_to(np.arange(shape[1], dtype=np.float32) * 1000.0, shape).copy()

    sensor = SimSensor(TRUTH, ramp, seed=5)
    mean, _, _ = sensor.expected_dn(cfg(offset_x=10, width=20, height=8))
    dark = TRUTH.dark_current_e_per_s * 0.01
    np.testing.assert_allclose(
        mean[0], TRUTH.K_dn_per_e * (np.arange(10, 30) * 10.0 + dark) + TRUTH.dark_offset_dn, rtol=1e-5
    )
    binned, _, _ = sensor.expected_dn(cfg(offset_x=1, width=4, height=2, binning_h=2, binning_v=2))
    cols = np.arange(2, 10).reshape(4, 2).sum(axis=1) * 10.0 * 2
    np.testing.assert_allclose(binned[0], TRUTH.K_dn_per_e * (cols + 4 * dark) + TRUTH.dark_offset_dn, rtol=1e-5)


def test_poisson_mode_has_poisson_statistics_at_low_signal():
    truth = SimTruth("p", (64, 64), 16, 1.0, 1000.0, 0.0, 1e6, 0.0, 0.0, 0.0, 10.0, 1e7, 0.0, 24.0)
    sensor = SimSensor(truth, flat_rate_map(300.0), seed=6, shot_noise="poisson")
    frames = stack(sensor, cfg(pixel_format="Mono16", width=64, height=64), 20) - 1000.0
    assert frames.mean() == pytest.approx(3.0, rel=0.03)
    assert frames.var() == pytest.approx(3.0, rel=0.06)
    assert np.all(frames == np.round(frames))


def test_truth_from_model_sensor_profile():
    profile = load_sensor_profile("imx250m")
    truth = SimTruth.from_sensor_profile(profile)
    assert truth.resolution_px == tuple(profile.resolution_px)
    assert truth.K_dn_per_e == profile.K_dn_per_e and truth.saturation_e == profile.saturation_e


def test_rig_scene_drives_the_sensor():
    """The default rig's board, seen on axis, reads the scene's on-axis electron rate through the EMVA model
    (μ_y = μ_y,dark + K μ_e, MSB-aligned in Mono16); the darker surround reads less by the reflectance ratio."""
    scene = RigScene.from_toml(None)
    sensor = sensor_from_rig(None, seed=0)
    truth = sensor.truth
    t = 0.4 * truth.saturation_e / scene.on_axis_rate_e_per_s()  # 40 % of the full well on the board
    width, height = truth.resolution_px
    image = sensor.render(cfg(width=width, height=height, pixel_format="Mono16", exposure_us=t * 1e6))
    assert image.shape == (height, width)
    native = image.astype(float) / 2 ** (16 - truth.bit_depth)
    centre = native[height // 2 - 16 : height // 2 + 16, width // 2 - 16 : width // 2 + 16].mean()
    electrons = scene.on_axis_rate_e_per_s() * t + truth.dark_current_e_per_s * t
    assert centre == pytest.approx(truth.dark_offset_dn + truth.K_dn_per_e * electrons, rel=0.01)
    corner = native[:32, :32].mean() - truth.dark_offset_dn
    ratio = scene.sim.surround_reflectance / scene.design["target.reflectance"]
    assert corner < 1.2 * ratio * (centre - truth.dark_offset_dn)


def test_the_default_simulated_grab_is_well_exposed():
    """The simulated camera powers on where continuous auto-exposure settles: the brightest 1 % of the default rig's
    scene at half the saturation capacity, so a grab with no settings clips nothing and uses the range."""
    import uwlab

    shot = uwlab.grab()
    row = shot.stats.iloc[0]
    assert row["saturated_fraction"] == 0.0 and row["pixel_format"] == "Mono16"
    profile = RigScene.from_toml().sensor
    scale = 2.0 ** (16 - profile.bit_depth)  # Mono16 carries the 12-bit ADC's counts shifted up
    electrons = (shot.images[0] / scale - profile.dark_offset_dn) / profile.K_dn_per_e
    assert np.quantile(electrons, 0.99) / profile.saturation_e == pytest.approx(0.5, abs=0.05)
