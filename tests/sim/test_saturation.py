"""The one saturation rule (`uwlab.experiments.saturation`) against simulated truth: grab, frames, points."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from uwlab.cli.main import main
from uwlab.sim.devices.camera import SensorConfig, SimSensor, SimTruth, flat_rate_map
from uwlab.errors import ConfigError
from uwlab.experiments.dataset import point_row
from uwlab.experiments.emva.simulate import simulate_photon_transfer
from uwlab.experiments.frames.stack import stack_statistics
from uwlab.experiments.saturation import (
    POINT_SATURATED_FRACTION,
    ClipLevel,
    adc_max_dn,
    clip_level,
    detect_clip_dn,
    sensor_clip_dn,
)
from uwlab.model.sensor import load_sensor_profile

IMX250 = load_sensor_profile("imx250m")


def _grab(capsys, exposure_us: float) -> dict:
    assert (
        main(["grab", "--backend", "sim", "--exposure-us", str(exposure_us), "--roi", "1000,900,256,256", "--json"])
        == 0
    )
    return json.loads(capsys.readouterr().out)["frames"][0]


def test_grab_flags_pixels_clipped_at_the_full_well_below_the_adc_maximum(capsys):
    frame = _grab(capsys, 10240)
    assert frame["max"] < adc_max_dn("Mono16")  # the sensor clips below its format's top code
    assert frame["clip_source"] == "profile" and frame["clip_level_dn"] == frame["max"]
    assert frame["saturated_fraction"] > 0.9
    assert _grab(capsys, 100)["saturated_fraction"] == 0.0


def _truth(**changes) -> SimTruth:
    return dataclasses.replace(SimTruth.from_sensor_profile(IMX250), resolution_px=(128, 96), **changes)


def test_a_sensor_clipping_below_its_profile_is_detected_from_the_pixels():
    truth = _truth(saturation_e=0.8 * IMX250.saturation_e)  # the real camera clips 20 % earlier than its profile
    sensor = SimSensor(truth, flat_rate_map(1e6), seed=3)
    cfg = SensorConfig(9000.0, 0.0, 0.0, "Mono16", 0, 0, 128, 96)  # 9000 e- mean: past the true full well
    image = sensor.render(cfg)
    true_clip = sensor_clip_dn(truth.K_dn_per_e, truth.saturation_e, truth.dark_offset_dn, 12, "Mono16")
    profile = sensor_clip_dn(IMX250.K_dn_per_e, IMX250.saturation_e, IMX250.dark_offset_dn, 12, "Mono16")
    clip = clip_level("Mono16", native_bits=12, profile_dn=profile, image=image)
    assert clip == ClipLevel(true_clip, "detected")
    mean_e, var_e = sensor.electrons(cfg, 1.0)
    truly_clipped = np.mean(mean_e >= truth.saturation_e)  # more than half the pixels, by the model's mean
    assert clip.fraction(image) == pytest.approx(truly_clipped, abs=0.1)
    assert (
        clip_level("Mono16", native_bits=12, profile_dn=profile).fraction(image) == 0.0
    )  # what the profile alone misses


def test_an_unclipped_distribution_near_the_top_is_not_taken_for_a_clip():
    rng = np.random.default_rng(0)
    image = np.clip(np.round(rng.normal(3600, 25, (200, 200))), 0, 4095).astype(np.uint16)
    assert detect_clip_dn(image, 4095) is None
    assert clip_level("Mono12", image=image) == ClipLevel(4095.0, "adc")
    narrow_dark = np.full((50, 50), 64, np.uint16)  # a dark frame is one code, far below any clip
    assert detect_clip_dn(narrow_dark, 4095) is None


def test_msb_aligned_adc_top_code_and_format_shifts():
    assert adc_max_dn("Mono16", native_bits=12) == 0xFFF0
    assert adc_max_dn("Mono8", native_bits=12) == 255
    assert sensor_clip_dn(1.0, 1e6, 0.0, 12, "Mono16") == 0xFFF0  # the ADC caps a full well beyond its range
    assert sensor_clip_dn(0.35, 10500, 16.0, 12, "Mono8") == (3691 >> 4)


def test_points_past_the_saturation_exposure_are_flagged_and_earlier_ones_not(tmp_path):
    truth = _truth()
    rate = 2.0e6
    t_sat_us = truth.saturation_e / rate * 1e6
    exposures = t_sat_us * np.array([0.2, 0.5, 0.8, 0.9, 1.1, 1.3, 2.0])
    data = simulate_photon_transfer(
        tmp_path / "pt", truth, rate_e_per_s=rate, quantum_efficiency=0.6, exposures_us=exposures, frames=2
    )
    points = data.points()
    assert points["saturated"].tolist() == [False, False, False, False, True, True, True]
    assert (points["saturated_fraction"] > POINT_SATURATED_FRACTION).tolist() == points["saturated"].tolist()
    assert set(points["clip_source"]) == {"profile"}


def test_point_row_derives_statistics_and_refuses_them_as_columns():
    frames = [np.full((4, 4), 100, np.uint16), np.full((4, 4), 102, np.uint16)]
    bright = stack_statistics(frames, 101)
    row = point_row(
        sweep_id="s",
        point_index=0,
        kind="exposure",
        bright=bright,
        dark=None,
        clip=ClipLevel(101.0, "adc"),
        exposure_us=10.0,
    )
    assert (row["mean_dn"], row["saturated_fraction"], row["saturated"], row["signal_dn"]) == (101.0, 1.0, True, None)
    with pytest.raises(ConfigError, match="point.mean_dn"):
        point_row(
            sweep_id="s",
            point_index=0,
            kind="exposure",
            bright=bright,
            dark=None,
            clip=ClipLevel(101.0, "adc"),
            mean_dn=5.0,
        )
