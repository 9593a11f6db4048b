"""Aravis backend, for real, against the simulated camera served over GigE Vision on loopback."""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest

from uwlab.cli.main import main
from uwlab.drivers.camera import Policy, open_camera
from uwlab.sim.devices.camera import SensorConfig, sensor_from_rig
from uwlab.errors import ConfigError, DeviceError
from tests.support.gige_server import Server

FAST = Policy(timeout_s=3.0, reconnect_attempts=2, reconnect_delay_s=0.2)


@pytest.fixture(scope="module")
def server():
    srv = Server()
    yield srv
    srv.stop()


@pytest.fixture(scope="module")
def truth_sensor():
    return sensor_from_rig(None, seed=0)


def test_server_announces_itself_and_arv_tool_lists_it(server):
    assert server.info["address"] == server.address
    assert server.info["device_id"].startswith("uwlab-SimCam-")
    listed = subprocess.run(["arv-tool-0.8"], capture_output=True, text=True, timeout=60).stdout
    assert f"{server.info['device_id']} ({server.address})" in listed
    out = subprocess.run(
        ["arv-tool-0.8", "-a", server.address, "control", "DeviceVendorName", "PixelFormat"],
        capture_output=True,
        text=True,
        timeout=60,
    ).stdout
    assert "DeviceVendorName = uwlab" in out and "PixelFormat =" in out


def test_frames_follow_the_physics_of_the_registers(server, truth_sensor):
    with open_camera("aravis", server.address, policy=FAST) as cam:
        assert cam.info.vendor == "uwlab" and cam.info.serial and cam.transport.get("ExposureAuto") == "Off"
        cam.pixel_format = "Mono12p"
        cam.set_roi(600, 500, 256, 128)
        cam.exposure_us, cam.gain_db = 60.0, 6.0
        frames = cam.acquire(4)
    s = frames[0].settings
    assert (s.exposure_us, s.gain_db, s.width, s.height, s.offset_x, s.pixel_format) == (
        60.0,
        6.0,
        256,
        128,
        600,
        "Mono12p",
    )
    assert all(f.image.shape == (128, 256) and f.image.dtype == np.uint16 for f in frames)
    ids = [f.frame_id for f in frames]
    assert ids == sorted(ids) and len(set(ids)) == 4
    mean_dn, std_dn, _ = truth_sensor.expected_dn(SensorConfig(60.0, 6.0, 0.0, "Mono12p", 600, 500, 256, 128))
    measured = np.mean([f.image.astype(float) for f in frames], axis=0)
    assert measured.mean() == pytest.approx(float(mean_dn.mean()), rel=0.01)
    # pixel by pixel within the temporal noise of a 4-frame mean (mean |N(0, s)| = 0.8 s)
    assert np.abs(measured - mean_dn).mean() < 0.5 * float(std_dn.mean()) + 0.5


@pytest.mark.parametrize("fmt,shift", [("Mono8", -4), ("Mono10p", -2), ("Mono12Packed", 0), ("Mono16", 4)])
def test_every_pixel_format_over_the_wire(server, truth_sensor, fmt, shift):
    with open_camera("aravis", server.address, policy=FAST) as cam:
        cam.pixel_format = fmt
        cam.set_roi(1124, 974, 200, 100)
        cam.exposure_us, cam.gain_db = 200.0, 0.0
        frame = cam.acquire(1)[0]
    assert frame.pixel_format == fmt and frame.image.shape == (100, 200)
    native_bits = truth_sensor.truth.bit_depth
    mean_dn, _, _ = truth_sensor.expected_dn(SensorConfig(200.0, 0.0, 0.0, fmt, 1124, 974, 200, 100))
    expected = float(mean_dn.mean()) * 2.0 ** (shift + 12 - native_bits)
    assert frame.image.mean() == pytest.approx(expected, rel=0.03, abs=1.0)


def test_out_of_range_and_device_side_rejection(server):
    with open_camera("aravis", server.address, policy=FAST) as cam:
        with pytest.raises(ConfigError, match=r"exposure_us.*ExposureTime.*allowed"):
            cam.exposure_us = 1e12
        with pytest.raises(ConfigError, match="ExposureTime.*rejected by the device"):
            cam.transport.set("ExposureTime", 1e12)
        with pytest.raises(ConfigError, match="pixel_format.*BayerRG8"):
            cam.pixel_format = "BayerRG8"


def test_software_trigger_over_gige(server):
    with open_camera("aravis", server.address, policy=FAST) as cam:
        cam.set_roi(0, 0, 64, 64)
        cam.set_trigger("software")
        frames = cam.acquire(3)
        assert len(frames) == 3 and frames[0].settings.trigger == "software"
        cam.set_trigger("free-run")


def test_unknown_device_lists_what_was_found():
    with pytest.raises(DeviceError, match="unknown device id 'no-such-camera'"):
        open_camera("aravis", "no-such-camera")


def test_incomplete_frames_are_discarded_and_reacquired():
    srv = Server("--incomplete-every", "2")
    try:
        with open_camera("aravis", srv.address, policy=FAST) as cam:
            cam.set_roi(0, 0, 256, 128)
            cam.exposure_us = 1000.0
            frames = cam.acquire(4)
            assert len(frames) == 4 and cam.stats.discarded >= 2
    finally:
        srv.stop()


def test_a_camera_losing_a_packet_of_every_frame_fails_on_the_discard_limit_saying_why():
    srv = Server("--incomplete-every", "1")
    try:
        with open_camera("aravis", srv.address, policy=Policy(timeout_s=10.0, max_discarded_in_row=5)) as cam:
            cam.set_roi(0, 0, 256, 128)
            with pytest.raises(
                DeviceError,
                match=r"6 incomplete frames in a row \(the last: Aravis buffer status (timeout|missing-packets)\)$",
            ):
                cam.acquire(1)
            assert cam.stats.discarded == 6 and cam.stats.delivered == 0
    finally:
        srv.stop()


def test_server_stopped_mid_stream_gives_bounded_reconnect_then_error():
    srv = Server()
    try:
        with open_camera("aravis", srv.address, policy=FAST) as cam:
            cam.set_roi(0, 0, 64, 64)
            assert len(cam.acquire(2)) == 2
            cam.start()
            srv.stop()
            with pytest.raises(DeviceError, match="device lost .*not back after 2 reconnect attempts"):
                cam.acquire(50)
    finally:
        srv.stop()


def test_grab_cli_over_aravis(server, capsys):
    argv = ["grab", "--backend", "aravis", "--device", server.address, "--frames", "2", "--roi", "0,0,128,64"]
    assert main([*argv, "--pixel-format", "Mono16", "--exposure-us", "1500", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["device"]["backend"] == "aravis" and len(doc["frames"]) == 2
    assert {(f["width"], f["height"], f["pixel_format"], f["exposure_us"]) for f in doc["frames"]} == {
        (128, 64, "Mono16", 1500.0)
    }


def test_a_stray_packet_aravis_cannot_make_a_frame_of_is_not_counted_as_a_frame():
    """The twin opens a block in a stream format it never sends (H.264) before every frame: Aravis hands back an
    unfilled buffer, status ``cleared``, for each (``_find_frame_data``, src/arvgvstream.c, 0.8.26), then the frame.
    Those are no frames, incomplete or not: every frame arrives, none is discarded. (At 20 frames/s, so that Aravis
    has a buffer free for each stray block.)"""
    srv = Server("--stray-every", "1")
    try:
        with open_camera("aravis", srv.address, policy=Policy(timeout_s=5.0, max_discarded_in_row=3)) as cam:
            cam.set_roi(0, 0, 64, 48)
            cam.frame_rate_hz = 20.0
            frames = cam.acquire(8)
            assert len(frames) == 8 and cam.stats.discarded == 0
            assert all(f.image.shape == (48, 64) for f in frames)
    finally:
        srv.stop()


@pytest.mark.parametrize("flag", ["--incomplete-every", "--stray-every"])
def test_a_negative_fault_period_is_one_line_naming_it(flag, capsys):
    assert main(["sim", "camera", "--gige", flag, "-1"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and flag.lstrip("-") in err and "-1" in err
