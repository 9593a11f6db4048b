"""Colour (raw Bayer) acquisition: per-channel statistics in ``uwlab grab --json`` from Aravis's fake camera and the
simulated colour camera; a Bayer layout the device does not deliver is refused in one line.

Truth for ``Fake_1``: Aravis's own RGB8 rendition of the same diagonal ramp (``arv_fake_camera_diagonal_ramp``:
pixel (x, y) of frame f shows colour ``jet[(x + y + f) mod 255]`` at 10 ms, gain 0), acquired straight through
Aravis; it also shows the fake's quirk recorded in its profile, red at (0, 0) of its BayerBG8 and at (1, 1) of its
BayerRG8. Truth for the simulated camera: the design model's per-channel electron rate at the image centre.
"""

from __future__ import annotations

import json

import gi
import numpy as np
import pytest

from uwlab.cli.main import main
from uwlab.errors import ConfigError
from uwlab.model.sensor import load_sensor_profile
from uwlab.sim.devices.camera import SimNodeMap, SimTruth
from uwlab.sim.devices.gige_xml import genicam_xml
from tests.support.paths import CONFIGS

gi.require_version("Aravis", "0.8")
from gi.repository import Aravis  # noqa: E402

# Which colour the fake camera writes at each cell position, read in arvfakecamera.c (and checked against RGB8 here)
FAKE_CELLS = {"BayerRG8": ("BG", "GR"), "BayerBG8": ("RG", "GB"), "BayerGR8": ("GR", "BG"), "BayerGB8": ("GB", "RG")}
WIDTH, HEIGHT = 256, 32


@pytest.fixture(scope="module")
def jet():
    """The fake camera's colour of ramp value k (0-254), ``{"R"|"G"|"B": array}``, from an RGB8 frame of its own."""
    Aravis.enable_interface("Fake")
    try:
        camera = Aravis.Camera.new("Fake_1")
        camera.set_region(0, 0, WIDTH, 1)
        camera.set_pixel_format_from_string("RGB8")
        buffer = camera.acquisition(5_000_000)
        rgb = np.frombuffer(buffer.get_data(), np.uint8).reshape(WIDTH, 3)
        k = (np.arange(WIDTH) + buffer.get_frame_id()) % 255
        table = np.zeros((255, 3), np.uint8)
        table[k] = rgb
        return {colour: table[:, i] for i, colour in enumerate("RGB")}
    finally:
        Aravis.disable_interface("Fake")


def grab(capsys, *argv) -> dict:
    assert main(["grab", "--json", *argv]) == 0, capsys.readouterr().err
    return json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("fmt", sorted(FAKE_CELLS))
def test_fake_1_channels_match_aravis_rgb(capsys, jet, fmt):
    doc = grab(
        capsys,
        "--backend",
        "aravis",
        "--device",
        "Fake_1",
        "--pixel-format",
        fmt,
        "--frames",
        "2",
        "--roi",
        f"0,0,{WIDTH},{HEIGHT}",
    )
    for frame in doc["frames"]:
        y, x = np.mgrid[0:HEIGHT, 0:WIDTH]
        k = (x + y + frame["frame_id"]) % 255
        colour_at = np.array([list(row) for row in FAKE_CELLS[fmt]])[y % 2, x % 2]
        assert set(frame["channels"]) == {"R", "G", "B"}
        for colour, stats in frame["channels"].items():
            truth = jet[colour][k[colour_at == colour]]
            assert stats["mean"] == pytest.approx(float(truth.mean()), abs=1e-9)
            saturated = float(np.mean(truth >= frame["clip_level_dn"]))
            assert stats["saturated_fraction"] == pytest.approx(saturated, abs=1e-12)
        assert frame["bayer"] == FAKE_CELLS[fmt][0]


def test_bayer_layout_not_delivered_is_refused_in_one_line(capsys):
    assert (
        main(["grab", "--backend", "aravis", "--device", "Fake_1", "--pixel-format", "BayerGB8", "--bayer", "RG"]) == 2
    )
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "bayer = 'RG'" in err and "BayerGB8 is Bayer GB" in err
    assert main(["grab", "--pixel-format", "Mono12", "--bayer", "GR"]) == 2
    assert "Mono12 is monochrome" in capsys.readouterr().err


def test_mono_frames_carry_no_channels(capsys):
    doc = grab(capsys, "--backend", "aravis", "--device", "Fake_1", "--pixel-format", "Mono8", "--roi", "0,0,64,8")
    assert doc["frames"][0]["channels"] is None and doc["frames"][0]["bayer"] is None


def test_sim_colour_camera_channels_follow_the_model(capsys):
    from uwlab.sim.scene import RigScene

    rig = CONFIGS / "rigs" / "sim-tank-colour.toml"
    scene = RigScene.from_toml(rig)
    sensor = scene.sensor
    rates = {}
    for colour, channel in (("R", "red"), ("G", "green"), ("B", "blue")):
        scene.design = scene.design.with_values(**{"sensor.channel": channel})
        rates[colour] = scene.on_axis_rate_e_per_s()
    exposure_us = 400.0
    width, height = 64, 48
    x0, y0 = (sensor.resolution_px[0] - width) // 2, (sensor.resolution_px[1] - height) // 2
    doc = grab(
        capsys,
        "--config",
        str(rig),
        "--pixel-format",
        "BayerRG12",
        "--exposure-us",
        str(exposure_us),
        "--roi",
        f"{x0},{y0},{width},{height}",
        "--frames",
        "4",
        "--bayer",
        "RG",
    )
    for colour, rate in rates.items():
        measured = np.mean([f["channels"][colour]["mean"] for f in doc["frames"]]) - sensor.dark_offset_dn
        predicted = sensor.K_dn_per_e * (rate * exposure_us * 1e-6 + sensor.dark_current_e_per_s * exposure_us * 1e-6)
        assert measured == pytest.approx(predicted, rel=0.02), colour
    assert rates["G"] > rates["R"] and rates["G"] > rates["B"]


def test_bayer_buffers_through_harvesters(monkeypatch, capsys):
    """Viky (the genicam wheel's producer) has no Bayer format: its Mono8 buffers are labelled BayerGR8 at the one
    place harvesters reports a buffer's format (``Component2DImage.data_format``), so its real buffers take the
    harvesters backend's Bayer path unchanged. Viky's Mono8 image is binary (0/255): a channel's mean is 255 times
    its saturated fraction at the 255 clip level, which holds only if both count the same sites."""
    from harvesters.core import Component2DImage

    monkeypatch.delenv("GENICAM_GENTL64_PATH", raising=False)
    monkeypatch.setattr(Component2DImage, "data_format", property(lambda self: "BayerGR8"))
    doc = grab(
        capsys,
        "--backend",
        "harvesters",
        "--fake",
        "--device",
        "VikyTL_DEV_green",
        "--pixel-format",
        "Mono8",
        "--roi",
        "0,0,160,120",
        "--frames",
        "2",
    )
    for frame in doc["frames"]:
        assert frame["pixel_format"] == "BayerGR8" and frame["bayer"] == "GR" and frame["clip_level_dn"] == 255
        channels = frame["channels"]
        assert sum(c["mean"] * n for c, n in zip(channels.values(), (1, 2, 1), strict=True)) / 4 == pytest.approx(
            frame["mean"]
        )
        for stats in channels.values():
            assert stats["mean"] == pytest.approx(255 * stats["saturated_fraction"])


def test_sim_colour_camera_windows_by_whole_bayer_cells(capsys):
    """A colour sensor's window steps by its 2 × 2 Bayer cell, as real colour cameras' (GenICam Inc = 2): an odd
    offset, which would shift the mosaic under an unchanged PixelFormat, is refused in one line, and so is binning;
    an even one keeps the layout."""
    rig = str(CONFIGS / "rigs" / "sim-tank-colour.toml")
    base = ["grab", "--config", rig, "--pixel-format", "BayerRG12", "--frames", "2", "--bayer", "RG"]
    assert main([*base, "--roi", "1001,1000,64,48"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "1001" in err and "multiple of 2" in err
    doc = grab(capsys, *base[1:], "--roi", "1002,1000,64,48")
    assert doc["frames"][0]["bayer"] == "RG"
    nodes = SimNodeMap(SimTruth.from_sensor_profile(load_sensor_profile("imx250c")))
    with pytest.raises(ConfigError, match="BinningHorizontal"):
        nodes.set("BinningHorizontal", 2)
    assert b"<Inc>2</Inc>" in genicam_xml(nodes)


def test_emva_on_a_fake_1_bayer_sweep_goes_per_channel_and_refuses_in_one_line(tmp_path, capsys):
    """A BayerRG8 sweep of ``Fake_1`` through the hardware rig records per-channel statistics (here BG: the fake's
    quirk) and ``uwlab emva characterize`` reads them per channel; the fake has no light to switch off, so the
    sweep has no dark frames and EMVA 1288 refuses it in one line, with or without --channel."""
    from uwlab.experiments.acquisition.plan import load_plan
    from uwlab.experiments.acquisition.rigs import HardwareRig
    from uwlab.experiments.acquisition.sweep import SweepRunner
    from uwlab.experiments.dataset import Dataset
    from tests.support.plans import write_plan

    sweep = {"id": "fake", "kind": "exposure", "values": [2000.0, 10000.0], "frames_per_point": 2, "dark": "none"}
    camera = {"backend": "aravis", "id": "Fake_1", "pixel_format": "BayerRG8", "window": [0, 0, 64, 32]}
    plan = load_plan(write_plan(tmp_path / "fake.toml", "fake", [{**sweep, "sensor": "imx250c"}], camera=camera))
    with (
        Dataset.create(tmp_path / "ds", plan.raw, plan_sha256=plan.sha256, sim=False) as data,
        HardwareRig(plan, None) as rig,
    ):
        SweepRunner(plan, data, rig).run()
    points = Dataset.open(tmp_path / "ds").points()
    assert points["bayer"].tolist() == ["BG", "BG"] and points["red_mean_dn"].notna().all()
    for argv in ([], ["--channel", "red"]):
        assert main(["emva", "characterize", str(tmp_path / "ds"), *argv]) == 2
        err = capsys.readouterr().err.strip()
        assert "\n" not in err and "no dark frames" in err
